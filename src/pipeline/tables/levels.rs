//! The tables of the comparison across levels, parameter redundancy
//! and initial-value sensitivity. Tables (parquet):
//!
//! | table | columns (unit) |
//! |---|---|
//! | `level_change` | model, level_low, level_high, quantity (storage = E', loss = E''), point (mode 1, mode 2, chosen), freq_hz (Hz), low_median, low_q2_5, low_q97_5, high_median, high_q2_5, high_q97_5, change_median, change_q2_5, change_q25, change_q75, change_q97_5 (Pa; change = high - low), rel_change_median, rel_change_q2_5, rel_change_q97_5 (1), p_lower (1; P(high < low), for E' the probability that the adhesive is softer at the higher level), truth_low, truth_high, truth_change (Pa; NaN without a truth), truth_in_95 (1/0), n_pairs |
//! | `level_evidence` | model, level_low, level_high, method (laplace / tmcmc), log_z_shared, se_shared, log_z_separate, se_separate, log_bayes_factor (nats; separate minus shared), seconds, shared_<param> (SI, the shared posterior's MAP) |
//! | `redundancy` | level, model, kind (svd / parameter), index, parameter, singular_value (1), condition_number (1), direction (text), v_<param> (right singular vector, d ln p), posterior_sd_x, prior_sd_x, sd_ratio (1; unconstrained coordinates), corr_<param> (posterior correlation, unconstrained coordinates) |
//! | `basins` | level, model, method (map / rfm), start, kind (initial / design), basin (-1: failed), objective (map: -log posterior up to log Z, nats; rfm: relative FRF residual), iterations, stop_reason, basin_distance_sd (the basin's distance from the MAP in Laplace sd), start_<param>, end_<param> (SI) |

use crate::bayes::levels::LevelComparison;
use crate::bayes::PosteriorResult;
use crate::output::{Columns as Cols, Table};
use crate::pipeline::LevelResults;
use crate::stage::RunError;

pub(crate) fn union_names<'a>(names: impl Iterator<Item = &'a [String]>) -> Vec<String> {
    let mut all: Vec<String> = Vec::new();
    for ns in names {
        for n in ns {
            if !all.contains(n) {
                all.push(n.clone());
            }
        }
    }
    all
}

pub(crate) fn comparisons(results: &[LevelResults]) -> Vec<&LevelComparison> {
    results
        .iter()
        .filter_map(|r| r.across_levels.as_ref())
        .collect()
}

/// The tables (only those with rows).
pub(super) fn tables(results: &[LevelResults]) -> Result<Vec<Table>, RunError> {
    let mut out = Vec::new();
    let cmps = comparisons(results);
    let (mut ch, mut ev) = (Cols::default(), Cols::default());
    let (mut n_ch, mut n_ev) = (0, 0);
    let ev_names = union_names(
        cmps.iter()
            .flat_map(|c| c.evidence.iter().map(|e| e.names.as_slice())),
    );
    for c in &cmps {
        for r in &c.rows {
            n_ch += 1;
            ch.s("model", r.model.clone());
            ch.s("level_low", c.low.clone());
            ch.s("level_high", c.high.clone());
            ch.s("quantity", r.quantity.to_string());
            ch.s("point", r.point.clone());
            ch.f("freq_hz", "Hz", r.freq_hz);
            let s = &r.stats;
            for (n, v) in [
                ("low_median", s.low.median),
                ("low_q2_5", s.low.q2_5),
                ("low_q97_5", s.low.q97_5),
                ("high_median", s.high.median),
                ("high_q2_5", s.high.q2_5),
                ("high_q97_5", s.high.q97_5),
                ("change_median", s.change.median),
                ("change_q2_5", s.change.q2_5),
                ("change_q25", s.change.q25),
                ("change_q75", s.change.q75),
                ("change_q97_5", s.change.q97_5),
            ] {
                ch.f(n, "Pa", v);
            }
            ch.f("rel_change_median", "1", s.rel_change.median);
            ch.f("rel_change_q2_5", "1", s.rel_change.q2_5);
            ch.f("rel_change_q97_5", "1", s.rel_change.q97_5);
            ch.f("p_lower", "1", s.p_lower);
            ch.f("truth_low", "Pa", r.truth_low);
            ch.f("truth_high", "Pa", r.truth_high);
            let tc = r.truth_high - r.truth_low;
            ch.f("truth_change", "Pa", tc);
            ch.i(
                "truth_in_95",
                (tc.is_finite() && s.change.contains95(tc)) as i64,
            );
            ch.i("n_pairs", s.n_pairs as i64);
        }
        for e in &c.evidence {
            n_ev += 1;
            ev.s("model", e.model.clone());
            ev.s("level_low", c.low.clone());
            ev.s("level_high", c.high.clone());
            ev.s("method", e.method.to_string());
            ev.f("log_z_shared", "nats", e.log_z_shared);
            ev.f("se_shared", "nats", e.se_shared);
            ev.f("log_z_separate", "nats", e.log_z_separate);
            ev.f("se_separate", "nats", e.se_separate);
            ev.f("log_bayes_factor", "nats", e.log_bayes_factor());
            ev.f("seconds", "s", e.seconds);
            for n in &ev_names {
                let v = e
                    .names
                    .iter()
                    .position(|m| m == n)
                    .map_or(f64::NAN, |k| e.shared_map[k]);
                ev.f(&format!("shared_{}", n.to_ascii_lowercase()), "", v);
            }
        }
    }
    if n_ch > 0 {
        out.push(ch.table("level_change")?);
    }
    if n_ev > 0 {
        out.push(ev.table("level_evidence")?);
    }
    let posts: Vec<&PosteriorResult> = results.iter().flat_map(|r| r.posteriors.iter()).collect();
    let names = union_names(posts.iter().map(|p| p.names.as_slice()));
    let mut rd = Cols::default();
    let mut n_rd = 0;
    for p in &posts {
        let Ok(r) = &p.redundancy else { continue };
        let mut row = |rd: &mut Cols, kind: &str, idx: usize| {
            n_rd += 1;
            rd.s("level", p.level.clone());
            rd.s("model", p.model.clone());
            rd.s("kind", kind.to_string());
            rd.i("index", idx as i64);
        };
        for (i, sv) in r.svd.singular_values.iter().enumerate() {
            row(&mut rd, "svd", i);
            rd.s("parameter", String::new());
            rd.f("singular_value", "1", *sv);
            rd.f("condition_number", "1", r.svd.condition_number);
            rd.s(
                "direction",
                crate::inference::identifiability::combination_text(
                    &r.law_names,
                    &r.svd.right_vectors[i],
                ),
            );
            for n in &names {
                let v = r
                    .law_names
                    .iter()
                    .position(|m| m == n)
                    .map_or(f64::NAN, |k| r.svd.right_vectors[i][k]);
                rd.f(&format!("v_{}", n.to_ascii_lowercase()), "1", v);
            }
            for (c, v) in [
                ("posterior_sd_x", f64::NAN),
                ("prior_sd_x", f64::NAN),
                ("sd_ratio", f64::NAN),
            ] {
                rd.f(c, "1", v);
            }
            for n in &names {
                rd.f(&format!("corr_{}", n.to_ascii_lowercase()), "1", f64::NAN);
            }
        }
        let d = r.names.len();
        let ratio = r.ratio();
        for (k, name) in r.names.iter().enumerate() {
            row(&mut rd, "parameter", k);
            rd.s("parameter", name.clone());
            rd.f("singular_value", "1", f64::NAN);
            rd.f("condition_number", "1", f64::NAN);
            rd.s("direction", String::new());
            for n in &names {
                rd.f(&format!("v_{}", n.to_ascii_lowercase()), "1", f64::NAN);
            }
            rd.f("posterior_sd_x", "1", r.posterior_sd_x[k]);
            rd.f("prior_sd_x", "1", r.prior_sd_x[k]);
            rd.f("sd_ratio", "1", ratio[k]);
            for n in &names {
                let v = r
                    .names
                    .iter()
                    .position(|m| m == n)
                    .map_or(f64::NAN, |j| r.correlation[k * d + j]);
                rd.f(&format!("corr_{}", n.to_ascii_lowercase()), "1", v);
            }
        }
    }
    if n_rd > 0 {
        out.push(rd.table("redundancy")?);
    }
    let mut ba = Cols::default();
    let mut n_ba = 0;
    for p in &posts {
        let Some(b) = &p.basins else { continue };
        for m in &b.methods {
            for s in &m.starts {
                n_ba += 1;
                ba.s("level", p.level.clone());
                ba.s("model", p.model.clone());
                ba.s("method", m.method.to_string());
                ba.i("start", s.index as i64);
                ba.s("kind", s.kind.to_string());
                ba.i("basin", s.basin.map_or(-1, |b| b as i64));
                ba.f("objective", "", s.objective);
                ba.i("iterations", s.iterations as i64);
                ba.s("stop_reason", s.stop_reason.clone());
                ba.f(
                    "basin_distance_sd",
                    "1",
                    s.basin.map_or(f64::NAN, |k| m.distance_to_map_sd[k]),
                );
                for n in &names {
                    let k = b.names.iter().position(|m| m == n);
                    // The parameter's unit from any posterior that has it (a column's unit
                    // is set by its first row, which may be a model without the parameter).
                    let unit = posts
                        .iter()
                        .find_map(|q| {
                            let bq = q.basins.as_ref()?;
                            bq.names
                                .iter()
                                .position(|m| m == n)
                                .map(|k| q.units[k].clone())
                        })
                        .unwrap_or_default();
                    ba.f(
                        &format!("start_{}", n.to_ascii_lowercase()),
                        &unit,
                        k.map_or(f64::NAN, |k| s.start.get(k).copied().unwrap_or(f64::NAN)),
                    );
                    ba.f(
                        &format!("end_{}", n.to_ascii_lowercase()),
                        &unit,
                        k.and_then(|k| s.end.as_ref().and_then(|e| e.get(k).copied()))
                            .unwrap_or(f64::NAN),
                    );
                }
            }
        }
    }
    if n_ba > 0 {
        out.push(ba.table("basins")?);
    }
    Ok(out)
}
