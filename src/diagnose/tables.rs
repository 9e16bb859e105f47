//! The loop's tables ([`loop_tables`]: `residuals`, `candidates`, `closed_loop`, `verdict`,
//! `signatures`; columns and units in docs/outputs.md) and the loop's results folder
//! ([`write_loop`]: the tables, the residual figures and `closed_loop.md`). The per-level
//! status tables `closed_loop` and `verdict` are in `level_tables.rs`.

use super::level_tables::{closed_loop_table, verdict_table};
use super::summary::{LevelResult, LoopOutcome};
use crate::output::{ResultsDir, Table};
use crate::stage::RunError;

/// The loop's tables: `residuals`, `candidates`, `closed_loop`, `verdict`, `signatures`.
pub fn loop_tables(o: &LoopOutcome) -> Result<Vec<Table>, RunError> {
    let mut tables = vec![
        residuals_table(&o.levels)?,
        candidates_table(&o.levels)?,
        closed_loop_table(
            &o.levels,
            &o.summary.levels,
            o.summary.term_rom.as_ref().map(|(_, r)| r),
        )?,
        verdict_table(&o.levels, &o.summary.levels)?,
        signatures_table(&o.levels)?,
    ];
    if let Some(m) = o.mesh.as_ref().filter(|m| m.failed.is_none()) {
        tables.push(super::mesh::table(m)?);
    }
    Ok(tables)
}

/// Write the loop's tables, residual figures (when `figures`) and `closed_loop.md` into `dir`.
pub fn write_loop(
    dir: &mut ResultsDir,
    o: &LoopOutcome,
    study_name: &str,
    figures: bool,
) -> Result<(), RunError> {
    for t in loop_tables(o)? {
        dir.write_table(&t).map_err(RunError::Output)?;
    }
    if figures {
        for (level, freq, ids, res, _) in &o.levels {
            let files = crate::plot::closed_loop::residual_figure(
                dir.file_path(&format!("residuals_{level}")),
                &format!(
                    "{study_name}: standardised residuals of {} at {level}, before and after",
                    o.summary.model
                ),
                freq,
                ids,
                &res.before.residuals.z,
                &res.after.residuals.z,
            )?;
            // Listed in the manifest, so that a rerun recognises the folder as rfmlab's.
            dir.record(&files.png);
            dir.record(&files.svg);
        }
    }
    dir.write_bytes("closed_loop.md", o.markdown.as_bytes())
        .map_err(RunError::Output)?;
    Ok(())
}

/// `residuals`: level, stage ("before"/"after"), freq_hz, channel, standardised residual.
fn residuals_table(results: &[LevelResult]) -> Result<Table, RunError> {
    let (mut lv, mut st, mut f, mut ch, mut re, mut im) = (
        Vec::new(),
        Vec::new(),
        Vec::new(),
        Vec::new(),
        Vec::new(),
        Vec::new(),
    );
    for (level, freq, ids, res, _) in results {
        for (stage, r) in [
            ("before", &res.before.residuals),
            ("after", &res.after.residuals),
        ] {
            let n = ids.len();
            for (o, z) in r.z.iter().enumerate() {
                lv.push(level.clone());
                st.push(stage.to_string());
                f.push(freq[o / n]);
                ch.push(ids[o % n]);
                re.push(z.re);
                im.push(z.im);
            }
        }
    }
    let mut t = Table::new("residuals");
    t.push_str("level", lv)
        .and_then(|t| t.push_str("stage", st))
        .and_then(|t| t.push_f64("freq_hz", "Hz", f))
        .and_then(|t| t.push_u32("channel", "", ch))
        .and_then(|t| t.push_f64("z_re", "1", re))
        .and_then(|t| t.push_f64("z_im", "1", im))
        .map_err(RunError::Output)?;
    Ok(t)
}

/// `signatures`: level, stage, one row per resonance of the prediction: its frequency and
/// loss factor, the data's relative frequency change and loss-factor change with sds.
fn signatures_table(results: &[LevelResult]) -> Result<Table, RunError> {
    let (mut lv, mut st) = (Vec::new(), Vec::new());
    let mut cols: [Vec<f64>; 6] = Default::default();
    for (level, _, _, res, _) in results {
        for (stage, r) in [
            ("before", &res.before.residuals),
            ("after", &res.after.residuals),
        ] {
            for x in &r.signatures.resonances {
                lv.push(level.clone());
                st.push(stage.to_string());
                for (c, v) in cols.iter_mut().zip([
                    x.freq_hz,
                    x.loss_factor,
                    x.freq_shift,
                    x.freq_shift_sd,
                    x.loss_change,
                    x.loss_change_sd,
                ]) {
                    c.push(v);
                }
            }
        }
    }
    let [f, eta, df, df_sd, de, de_sd] = cols;
    let mut t = Table::new("signatures");
    t.push_str("level", lv)
        .and_then(|t| t.push_str("stage", st))
        .and_then(|t| t.push_f64("resonance_hz", "Hz", f))
        .and_then(|t| t.push_f64("loss_factor", "1", eta))
        .and_then(|t| t.push_f64("freq_shift", "1", df))
        .and_then(|t| t.push_f64("freq_shift_sd", "1", df_sd))
        .and_then(|t| t.push_f64("loss_change", "1", de))
        .and_then(|t| t.push_f64("loss_change_sd", "1", de_sd))
        .map_err(RunError::Output)?;
    Ok(t)
}

/// `candidates`: one row per candidate and round.
fn candidates_table(results: &[LevelResult]) -> Result<Table, RunError> {
    let mut t = Table::new("candidates");
    let (mut c_level, mut c_round, mut c_rank, mut c_effect, mut c_kind) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut num: [Vec<f64>; 4] = Default::default();
    let mut refit: [Vec<Option<f64>>; 4] = Default::default();
    let (mut acc, mut verdict, mut unit) = (Vec::new(), Vec::new(), Vec::new());
    let (mut r2, mut absorbed, mut profile) = (Vec::new(), Vec::new(), Vec::new());
    let mut predicted = Vec::new();
    for (level, _, _, res, _) in results {
        for c in &res.candidates {
            c_level.push(level.clone());
            c_round.push(c.round as i64);
            c_rank.push(c.rank as i64);
            c_effect.push(c.effect.name());
            c_kind.push(c.effect.kind().into());
            unit.push(c.effect.unit().to_string());
            num[0].push(c.score);
            num[1].push(c.p_value);
            num[2].push(c.one_step);
            num[3].push(c.one_step_sd);
            let r = c.refit.as_ref();
            refit[0].push(r.map(|r| r.evidence_gain));
            refit[1].push(r.map(|r| r.log_evidence));
            refit[2].push(r.map(|r| r.size));
            refit[3].push(r.map(|r| r.sd));
            acc.push(r.is_some_and(|r| r.accepted));
            verdict.push(r.map_or("not refitted".to_string(), |r| r.verdict.to_string()));
            predicted.push(c.predicted_gain);
            profile.push(c.profile_gain);
            r2.push(c.confounding.r2);
            absorbed.push(
                c.confounding
                    .absorbed
                    .iter()
                    .map(|(n, a)| format!("{n} {a:+.4e}"))
                    .collect::<Vec<_>>()
                    .join(", "),
            );
        }
        // Alternative laws: no score test (not nested), no size.
        for c in &res.law_candidates {
            c_level.push(level.clone());
            c_round.push(c.round as i64);
            c_rank.push(0);
            c_effect.push(c.law.clone());
            c_kind.push(crate::closed_loop::alternative::ALTERNATIVE_LAW.into());
            unit.push(String::new());
            for x in num.iter_mut() {
                x.push(f64::NAN);
            }
            let r = &c.refit;
            refit[0].push(Some(r.evidence_gain).filter(|x| x.is_finite()));
            refit[1].push(Some(r.log_evidence).filter(|x| x.is_finite()));
            refit[2].push(None);
            refit[3].push(None);
            acc.push(r.accepted);
            verdict.push(r.verdict.to_string());
            predicted.push(f64::NAN);
            profile.push(None);
            // A whole law is not a column beside the law's own: no confounding measure.
            r2.push(f64::NAN);
            absorbed.push(String::new());
        }
    }
    let [score, p, est, est_sd] = num;
    let [gain, logz, size, sd] = refit;
    t.push_str("level", c_level)
        .and_then(|t| t.push_i64("round", "", c_round))
        .and_then(|t| t.push_i64("rank", "", c_rank))
        .and_then(|t| t.push_str("effect", c_effect))
        .and_then(|t| t.push_str("kind", c_kind))
        .and_then(|t| t.push_str("unit", unit))
        .and_then(|t| t.push_f64("score", "1", score))
        .and_then(|t| t.push_f64("p_value", "1", p))
        .and_then(|t| t.push_f64("one_step_size", "SI (see unit)", est))
        .and_then(|t| t.push_f64("one_step_sd", "SI (see unit)", est_sd))
        .and_then(|t| t.push_f64("predicted_gain", "nat", predicted))
        .and_then(|t| t.push_opt_f64("evidence_gain", "nat", gain))
        .and_then(|t| t.push_opt_f64("log_evidence", "nat", logz))
        .and_then(|t| t.push_opt_f64("size", "SI (see unit)", size))
        .and_then(|t| t.push_opt_f64("size_sd", "SI (see unit)", sd))
        .and_then(|t| t.push_bool("accepted", acc))
        .and_then(|t| t.push_str("verdict", verdict))
        .and_then(|t| t.push_opt_f64("profile_gain", "nat", profile))
        .and_then(|t| t.push_f64("law_r2", "1", r2))
        .and_then(|t| t.push_str("absorbed_per_unit", absorbed))
        .map_err(RunError::Output)?;
    Ok(t)
}
