//! `rfmlab material STUDY.toml`: the material-level loop of [`crate::material_fit`] on a measured
//! master curve, and its results in the study's output folder:
//!
//! | file | content |
//! |---|---|
//! | `steps.parquet` | one row per fitted law: step, proposal, law, n_params, accepted, on_path, log_evidence (Laplace + ln n!, nats), evidence_gain (nats), log_likelihood, rms_log10_storage, rms_log10_loss, rms_log10_sum (1), sigma_storage, sigma_loss (1, ln units), runs_z/runs_p/chi2_norm/scatter_log10 per quantity, verdict_storage, verdict_loss, positive_definite, causal_floor_ratio (weighted misfit over the best causal fit's, laws on the path) |
//! | `parameters.parquet` | candidate, law, param, value, sd (SI units in `unit`), on_path |
//! | `residuals.parquet` | per law on the path and data point: path_index, law, freq_hz, storage_pa, loss_pa, model_storage_pa, model_loss_pa, res_log10_storage, res_log10_loss |
//! | `kk.parquet` | per data point: freq_hz, storage_pa, loss_pa, loss_from_storage_pa, storage_from_loss_pa, causal_storage_pa, causal_loss_pa, res_loss_from_storage, res_storage_from_loss, res_causal_storage, res_causal_loss (log10), non_causal |
//! | `report.md` | data, steps (error and evidence), residual analysis, KK check, figures |
//! | `fit_storage`, `fit_loss`, `residuals`, `kk` (.png, .svg) | figures |
//! | `manifest.json` | study hash, seed, timings, files |
//!
//! Files are written atomically one by one into the output folder.

use crate::material_fit::{run_loop, Candidate, LoopResult, MaterialFitError};
use crate::output::{Manifest, OutputError, Report, ResultsDir, Table};
use crate::plot::{line_figure_with, Curve, CurveStyle, PlotError, PlotParams};
use crate::study::material::MaterialStudy;
use std::path::PathBuf;

/// Errors of a material run.
#[derive(Debug, thiserror::Error)]
pub enum MaterialRunError {
    #[error(transparent)]
    Fit(#[from] MaterialFitError),
    #[error(transparent)]
    Output(#[from] OutputError),
    #[error(transparent)]
    Plot(#[from] PlotError),
}

/// What a run produced.
#[derive(Clone, Debug, serde::Serialize)]
pub struct MaterialSummary {
    pub output_dir: PathBuf,
    pub seconds: f64,
    pub path: Vec<String>,
    pub final_law: String,
    pub final_n_params: usize,
    pub first_rms_log10_storage: f64,
    pub first_rms_log10_loss: f64,
    pub final_rms_log10_storage: f64,
    pub final_rms_log10_loss: f64,
    pub final_log_evidence: f64,
    pub stop_reason: String,
    pub kk_causal_rms_log10_storage: f64,
    pub kk_causal_rms_log10_loss: f64,
    pub kk_non_causal_points: usize,
}

fn fmt_params(c: &Candidate) -> String {
    c.names
        .iter()
        .zip(&c.map)
        .map(|(n, v)| format!("{n} {v:.4e}"))
        .collect::<Vec<_>>()
        .join(", ")
}

fn tables(study: &MaterialStudy, r: &LoopResult) -> Result<Vec<Table>, OutputError> {
    let cs = &r.candidates;
    let on_path: Vec<bool> = (0..cs.len()).map(|i| r.path.contains(&i)).collect();
    let f = |g: &dyn Fn(&Candidate) -> f64| cs.iter().map(g).collect::<Vec<f64>>();
    let mut steps = Table::new("steps");
    steps
        .push_i64("candidate", "", (0..cs.len() as i64).collect())?
        .push_i64("step", "", cs.iter().map(|c| c.step as i64).collect())?
        .push_str("proposal", cs.iter().map(|c| c.proposal.clone()).collect())?
        .push_str("law", cs.iter().map(|c| c.law.label()).collect())?
        .push_i64(
            "n_params",
            "",
            cs.iter().map(|c| c.n_params() as i64).collect(),
        )?
        .push_bool("accepted", cs.iter().map(|c| c.accepted).collect())?
        .push_bool("on_path", on_path.clone())?
        .push_f64("log_evidence", "nat", f(&|c| c.log_evidence))?
        .push_f64("evidence_gain", "nat", f(&|c| c.evidence_gain))?
        .push_f64("log_likelihood", "nat", f(&|c| c.log_likelihood))?
        .push_f64("rms_log10_storage", "1", f(&|c| c.rms_log10_storage))?
        .push_f64("rms_log10_loss", "1", f(&|c| c.rms_log10_loss))?
        .push_f64("rms_log10_sum", "1", f(&|c| c.rms_log10_sum()))?
        .push_f64("sigma_storage", "1", f(&|c| c.map[c.map.len() - 2]))?
        .push_f64("sigma_loss", "1", f(&|c| c.map[c.map.len() - 1]))?
        .push_f64("runs_z_storage", "1", f(&|c| c.stats_storage.runs_z))?
        .push_f64("runs_p_storage", "1", f(&|c| c.stats_storage.runs_p))?
        .push_f64("runs_z_loss", "1", f(&|c| c.stats_loss.runs_z))?
        .push_f64("runs_p_loss", "1", f(&|c| c.stats_loss.runs_p))?
        .push_f64("chi2_norm_storage", "1", f(&|c| c.stats_storage.chi2_norm))?
        .push_f64("chi2_norm_loss", "1", f(&|c| c.stats_loss.chi2_norm))?
        .push_f64(
            "scatter_log10_storage",
            "1",
            f(&|c| c.stats_storage.scatter_sd),
        )?
        .push_f64("scatter_log10_loss", "1", f(&|c| c.stats_loss.scatter_sd))?
        .push_str(
            "verdict_storage",
            cs.iter()
                .map(|c| c.stats_storage.verdict().to_string())
                .collect(),
        )?
        .push_str(
            "verdict_loss",
            cs.iter()
                .map(|c| c.stats_loss.verdict().to_string())
                .collect(),
        )?
        .push_bool(
            "positive_definite",
            cs.iter().map(|c| c.positive_definite).collect(),
        )?
        .push_f64("causal_floor_ratio", "1", f(&|c| c.causal_floor_ratio))?;
    let mut params = Table::new("parameters");
    let (mut ci, mut law, mut name, mut unit, mut val, mut sd, mut op) =
        (vec![], vec![], vec![], vec![], vec![], vec![], vec![]);
    for (i, c) in cs.iter().enumerate() {
        let mut units = c.law.param_units();
        units.extend(["1".to_string(), "1".to_string()]);
        for k in 0..c.map.len() {
            ci.push(i as i64);
            law.push(c.law.label());
            name.push(c.names[k].clone());
            unit.push(units[k].clone());
            val.push(c.map[k]);
            sd.push(c.sd[k]);
            op.push(on_path[i]);
        }
    }
    params
        .push_i64("candidate", "", ci)?
        .push_str("law", law)?
        .push_str("param", name)?
        .push_str("unit", unit)?
        .push_f64("value", "SI (see unit)", val)?
        .push_f64("sd", "SI (see unit)", sd)?
        .push_bool("on_path", op)?;
    let c = &study.curve;
    let mut res = Table::new("residuals");
    let (mut pi, mut lw, mut fr, mut s, mut l, mut ms, mut ml, mut rs, mut rl) = (
        vec![],
        vec![],
        vec![],
        vec![],
        vec![],
        vec![],
        vec![],
        vec![],
        vec![],
    );
    for (k, &i) in r.path.iter().enumerate() {
        let cand = &cs[i];
        for j in 0..c.len() {
            pi.push(k as i64);
            lw.push(cand.law.label());
            fr.push(c.freq_hz[j]);
            s.push(c.storage_pa[j]);
            l.push(c.loss_pa[j]);
            ms.push(cand.model_storage_pa[j]);
            ml.push(cand.model_loss_pa[j]);
            rs.push(cand.res_log10_storage[j]);
            rl.push(cand.res_log10_loss[j]);
        }
    }
    res.push_i64("path_index", "", pi)?
        .push_str("law", lw)?
        .push_f64("freq_hz", "Hz", fr)?
        .push_f64("storage_pa", "Pa", s)?
        .push_f64("loss_pa", "Pa", l)?
        .push_f64("model_storage_pa", "Pa", ms)?
        .push_f64("model_loss_pa", "Pa", ml)?
        .push_f64("res_log10_storage", "1", rs)?
        .push_f64("res_log10_loss", "1", rl)?;
    let k = &r.kk;
    let mut kk = Table::new("kk");
    kk.push_f64("freq_hz", "Hz", c.freq_hz.clone())?
        .push_f64("storage_pa", "Pa", c.storage_pa.clone())?
        .push_f64("loss_pa", "Pa", c.loss_pa.clone())?
        .push_f64("loss_from_storage_pa", "Pa", k.loss_from_storage_pa.clone())?
        .push_f64("storage_from_loss_pa", "Pa", k.storage_from_loss_pa.clone())?
        .push_f64("causal_storage_pa", "Pa", k.causal_storage_pa.clone())?
        .push_f64("causal_loss_pa", "Pa", k.causal_loss_pa.clone())?
        .push_f64(
            "res_loss_from_storage",
            "1",
            k.res_loss_from_storage.clone(),
        )?
        .push_f64(
            "res_storage_from_loss",
            "1",
            k.res_storage_from_loss.clone(),
        )?
        .push_f64("res_causal_storage", "1", k.res_causal_storage.clone())?
        .push_f64("res_causal_loss", "1", k.res_causal_loss.clone())?
        .push_bool("non_causal", k.non_causal.clone())?;
    Ok(vec![steps, params, res, kk])
}

fn figures(dir: &mut ResultsDir, study: &MaterialStudy, r: &LoopResult) -> Result<(), PlotError> {
    let c = &study.curve;
    let first = r.first_candidate();
    let last = r.final_candidate();
    let pp = PlotParams {
        log_x: true,
        ..PlotParams::default()
    };
    let black = (0, 0, 0);
    let mpa = |v: &[f64]| v.iter().map(|x| x * 1e-6).collect::<Vec<f64>>();
    let f = c.freq_hz.clone();
    for (stem, title, label, data, a, b) in [
        (
            "fit_storage",
            "Storage modulus: data and fits",
            "E' (MPa)",
            &c.storage_pa,
            &first.model_storage_pa,
            &last.model_storage_pa,
        ),
        (
            "fit_loss",
            "Loss modulus: data and fits",
            "E'' (MPa)",
            &c.loss_pa,
            &first.model_loss_pa,
            &last.model_loss_pa,
        ),
    ] {
        let curves = vec![
            Curve::new("data", f.clone(), mpa(data), CurveStyle::Points).with_color(black),
            Curve::line(format!("{} (first)", first.law.label()), f.clone(), mpa(a)),
            Curve::line(format!("{} (final)", last.law.label()), f.clone(), mpa(b)),
        ];
        let files = line_figure_with(
            dir.file_path(stem),
            title,
            "Frequency (Hz)",
            label,
            &curves,
            true,
            &pp,
        )?;
        dir.record(&files.png);
        dir.record(&files.svg);
    }
    let curves = vec![
        Curve::new(
            format!("E' {}", first.law.label()),
            f.clone(),
            first.res_log10_storage.clone(),
            CurveStyle::ThinLine,
        ),
        Curve::new(
            format!("E'' {}", first.law.label()),
            f.clone(),
            first.res_log10_loss.clone(),
            CurveStyle::ThinLine,
        ),
        Curve::new(
            format!("E' {}", last.law.label()),
            f.clone(),
            last.res_log10_storage.clone(),
            CurveStyle::Points,
        ),
        Curve::new(
            format!("E'' {}", last.law.label()),
            f.clone(),
            last.res_log10_loss.clone(),
            CurveStyle::Points,
        ),
    ];
    let files = line_figure_with(
        dir.file_path("residuals"),
        "Residuals log10(data / model), first and final law",
        "Frequency (Hz)",
        "log10 residual",
        &curves,
        false,
        &pp,
    )?;
    dir.record(&files.png);
    dir.record(&files.svg);
    let k = &r.kk;
    let curves = vec![
        Curve::new(
            "E'' measured / E'' implied by E'",
            f.clone(),
            k.res_loss_from_storage.clone(),
            CurveStyle::Points,
        ),
        Curve::new(
            "E' measured / E' implied by E''",
            f.clone(),
            k.res_storage_from_loss.clone(),
            CurveStyle::Points,
        ),
        Curve::new(
            "E' measured / best causal fit",
            f.clone(),
            k.res_causal_storage.clone(),
            CurveStyle::ThinLine,
        ),
        Curve::new(
            "E'' measured / best causal fit",
            f.clone(),
            k.res_causal_loss.clone(),
            CurveStyle::ThinLine,
        ),
    ];
    let files = line_figure_with(
        dir.file_path("kk"),
        "Kramers-Kronig check: log10(measured / implied)",
        "Frequency (Hz)",
        "log10 residual",
        &curves,
        false,
        &pp,
    )?;
    dir.record(&files.png);
    dir.record(&files.svg);
    Ok(())
}

fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
}

fn e(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.2}")
    } else {
        "-inf (Hessian not positive definite)".into()
    }
}

fn report(study: &MaterialStudy, r: &LoopResult, with_figures: bool) -> Report {
    let c = &study.curve;
    let mut rep = Report::new();
    rep.heading(1, &format!("Material study {}", study.name));
    if !study.description.is_empty() {
        rep.paragraph(&study.description);
    }
    rep.paragraph(&format!(
        "Data: `{}`, {} points, {:.3e} to {:.3e} Hz; E' {:.4} to {:.4} MPa, E'' {:.4} to {:.4} MPa. \
         Likelihood on ln E' and ln E'' with one inferred relative scatter each; priors log-uniform: \
         moduli [{:.3e}, {:.3e}] Pa, relaxation times [{:.3e}, {:.3e}] s, scatters [1e-4, 1]; fractional order uniform (0, 1). \
         Evidence: Laplace + ln n! for n exchangeable branches; it depends on these priors.",
        study.data_file.display(),
        c.len(),
        c.freq_hz[0],
        c.freq_hz[c.len() - 1],
        c.storage_pa.iter().cloned().fold(f64::INFINITY, f64::min) * 1e-6,
        c.storage_pa.iter().cloned().fold(0.0, f64::max) * 1e-6,
        c.loss_pa.iter().cloned().fold(f64::INFINITY, f64::min) * 1e-6,
        c.loss_pa.iter().cloned().fold(0.0, f64::max) * 1e-6,
        r.prior_box.modulus_pa.0,
        r.prior_box.modulus_pa.1,
        r.prior_box.tau_s.0,
        r.prior_box.tau_s.1,
    ));
    rep.heading(2, "Steps: error and evidence");
    let rows: Vec<Vec<String>> = r
        .candidates
        .iter()
        .enumerate()
        .map(|(i, k)| {
            vec![
                i.to_string(),
                k.step.to_string(),
                k.proposal.clone(),
                k.law.label(),
                k.n_params().to_string(),
                e(k.log_evidence),
                e(k.evidence_gain),
                format!("{:.4}", k.rms_log10_storage),
                format!("{:.4}", k.rms_log10_loss),
                format!("{} / {}", k.stats_storage.verdict(), k.stats_loss.verdict()),
                if k.causal_floor_ratio.is_finite() {
                    format!("{:.2}", k.causal_floor_ratio)
                } else {
                    String::new()
                },
                if r.path.contains(&i) {
                    "yes".into()
                } else {
                    "".into()
                },
            ]
        })
        .collect();
    rep.table(
        &[
            "#",
            "step",
            "proposal",
            "law",
            "params",
            "log Z (nat)",
            "gain (nat)",
            "RMS log10 E'",
            "RMS log10 E''",
            "residual E' / E''",
            "misfit / causal floor",
            "accepted",
        ],
        &rows,
    );
    let first = r.first_candidate();
    let last = r.final_candidate();
    rep.paragraph(&format!(
        "Stop: {}. Before (first law, {}): RMS log10 error E' {:.4}, E'' {:.4}. After (final law, {}, {} parameters): E' {:.4}, E'' {:.4}; \
         evidence gain {:.1} nats over the first law.",
        r.stop.as_str(),
        first.law.label(),
        first.rms_log10_storage,
        first.rms_log10_loss,
        last.law.label(),
        last.n_params(),
        last.rms_log10_storage,
        last.rms_log10_loss,
        last.log_evidence - first.log_evidence
    ));
    rep.paragraph(&format!(
        "Final parameters (MAP, SI): {}.",
        fmt_params(last)
    ));
    rep.heading(2, "Residual analysis");
    let mut rows = Vec::new();
    for (name, k) in [("first", first), ("final", last)] {
        for (q, s) in [("E'", &k.stats_storage), ("E''", &k.stats_loss)] {
            rows.push(vec![
                format!("{name} ({})", k.law.label()),
                q.to_string(),
                format!("{:.4}", s.rms),
                format!("{} / {:.1}", s.runs, s.runs_expected),
                format!("{:.2}", s.runs_z),
                format!("{:.2e}", s.runs_p),
                format!("{:.4}", s.scatter_sd),
                format!("{:.2}", s.chi2_norm),
                s.verdict().to_string(),
            ]);
        }
    }
    rep.table(
        &[
            "law",
            "quantity",
            "RMS log10",
            "runs / expected",
            "runs z",
            "runs p",
            "scatter (log10, successive differences)",
            "chi2 / scatter^2",
            "verdict",
        ],
        &rows,
    );
    let k = &r.kk;
    let n_bad = k.non_causal.iter().filter(|b| **b).count();
    let regions: Vec<String> = k
        .regions_hz
        .iter()
        .map(|(a, b)| format!("{a:.3e}-{b:.3e} Hz"))
        .collect();
    rep.heading(2, "Kramers-Kronig check of the data");
    rep.paragraph(&format!(
        "Non-negative relaxation spectrum on {} relaxation times ({} per decade, one decade beyond the data at each end; \
         the first and last decade of the data are the least certain). Best causal fit: RMS log10 error E' {:.4}, E'' {:.4} \
         (sum {:.4}; the final law's sum is {:.4}). Point-to-point scatter about it: E' {:.4}, E'' {:.4} (log10). \
         RMS log10 of E'' implied by E' against the measured E'': {:.4}; of E' implied by E'': {:.4} (one-sided transforms, ill-posed where the other quantity is flat). \
         {} of {} points are non-causal (the best causal fit's 5-point averaged residual beyond {} white-noise sds){}.",
        k.tau_s.len(),
        study.params.kk_per_decade,
        k.causal_rms_log10_storage,
        k.causal_rms_log10_loss,
        k.causal_rms_log10_storage + k.causal_rms_log10_loss,
        last.rms_log10_sum(),
        k.scatter_log10_storage,
        k.scatter_log10_loss,
        rms(&k.res_loss_from_storage),
        rms(&k.res_storage_from_loss),
        n_bad,
        c.len(),
        k.threshold,
        if regions.is_empty() { String::new() } else { format!(": {}", regions.join(", ")) }
    ));
    let systematic = last.stats_storage.is_systematic() || last.stats_loss.is_systematic();
    let near_floor = last.causal_floor_ratio <= 1.25;
    let verdict = match (systematic, near_floor) {
        (false, _) => "The final law's residual is consistent with scatter (runs test at 1 %).".to_string(),
        (true, true) => format!(
            "The final law's residual is systematic, but its weighted misfit is {:.2} times that of the best causal fit \
             with the same weights (any non-negative relaxation spectrum): the remaining residual is the data's causal \
             (Kramers-Kronig) inconsistency, not missing relaxation content{}.",
            last.causal_floor_ratio,
            if regions.is_empty() { String::new() } else { format!("; the data are non-causal at {}", regions.join(", ")) }
        ),
        (true, false) => format!(
            "The final law's residual is systematic and its weighted misfit is {:.2} times the best causal fit's with the \
             same weights: part of the residual is relaxation content the law lacks (the loop stopped because {}); \
             the rest is the data's causal inconsistency{}.",
            last.causal_floor_ratio,
            r.stop.as_str(),
            if regions.is_empty() { String::new() } else { format!(" at {}", regions.join(", ")) }
        ),
    };
    rep.paragraph(&verdict);
    if with_figures {
        rep.heading(2, "Figures");
        rep.image("fit_storage.png", "E' data and fits");
        rep.image("fit_loss.png", "E'' data and fits");
        rep.image("residuals.png", "residuals");
        rep.image("kk.png", "Kramers-Kronig check");
    }
    rep
}

/// Run a material study and write its results.
pub fn run_material(study: &MaterialStudy) -> Result<MaterialSummary, MaterialRunError> {
    let t0 = std::time::Instant::now();
    let mut manifest = Manifest::new(&study.file, Some(study.seed));
    let r = manifest.time("material loop", || run_loop(&study.curve, &study.params))?;
    let parent = study
        .output_dir
        .parent()
        .map(|p| p.to_path_buf())
        .unwrap_or_default();
    let name = study
        .output_dir
        .file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| study.name.clone());
    let mut dir = ResultsDir::create(
        if parent.as_os_str().is_empty() {
            PathBuf::from(".")
        } else {
            parent
        },
        &name,
    )?;
    for t in tables(study, &r)? {
        dir.write_table(&t)?;
    }
    if study.figures {
        figures(&mut dir, study, &r)?;
    }
    dir.write_report(&report(study, &r, study.figures))?;
    dir.write_manifest(&mut manifest)?;
    let first = r.first_candidate();
    let last = r.final_candidate();
    Ok(MaterialSummary {
        output_dir: dir.path().to_path_buf(),
        seconds: t0.elapsed().as_secs_f64(),
        path: r
            .path
            .iter()
            .map(|&i| r.candidates[i].law.label())
            .collect(),
        final_law: last.law.label(),
        final_n_params: last.n_params(),
        first_rms_log10_storage: first.rms_log10_storage,
        first_rms_log10_loss: first.rms_log10_loss,
        final_rms_log10_storage: last.rms_log10_storage,
        final_rms_log10_loss: last.rms_log10_loss,
        final_log_evidence: last.log_evidence,
        stop_reason: r.stop.as_str().to_string(),
        kk_causal_rms_log10_storage: r.kk.causal_rms_log10_storage,
        kk_causal_rms_log10_loss: r.kk.causal_rms_log10_loss,
        kk_non_causal_points: r.kk.non_causal.iter().filter(|b| **b).count(),
    })
}
