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
//! Files are written atomically into a temporary sibling of the output folder, which is then
//! swapped in whole (the output contract, [`crate::output::contract`]).

use crate::material_fit::{run_loop, Candidate, MaterialFitError};
use crate::output::{Manifest, OutputError, Replace, ResultsDir};
use crate::plot::PlotError;
use crate::study::material::MaterialStudy;
use std::path::{Path, PathBuf};

mod figures;
mod markdown;
mod tables;

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

/// Run a material study and write its results (the folder is replaced as a whole when rfmlab
/// wrote it, it is empty or absent; else refused, see [`run_material_as`]).
pub fn run_material(study: &MaterialStudy) -> Result<MaterialSummary, MaterialRunError> {
    run_material_as(study, Replace::IfOurs)
}

/// [`run_material`] under the output contract's choice `replace`
/// ([`crate::output::contract`]); the folder is checked before the loop runs.
pub fn run_material_as(
    study: &MaterialStudy,
    replace: Replace,
) -> Result<MaterialSummary, MaterialRunError> {
    let t0 = std::time::Instant::now();
    crate::output::claim_folder(&study.output_dir, replace)?;
    let mut manifest = Manifest::new(&study.file, Some(study.seed));
    let r = manifest.time("material loop", || run_loop(&study.curve, &study.params))?;
    crate::output::replace_dir_as(&study.output_dir, replace, |tmp| {
        let parent = tmp.parent().map(Path::to_path_buf).unwrap_or_default();
        let name = tmp
            .file_name()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        let mut dir = ResultsDir::create(parent, &name)?;
        for t in tables::tables(study, &r)? {
            dir.write_table(&t)?;
        }
        if study.figures {
            figures::figures(&mut dir, study, &r)?;
        }
        dir.write_report(&markdown::report(study, &r, study.figures))?;
        dir.write_manifest(&mut manifest)?;
        Ok::<_, MaterialRunError>(())
    })?;
    let first = r.first_candidate();
    let last = r.final_candidate();
    Ok(MaterialSummary {
        output_dir: study.output_dir.clone(),
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
