//! [`Results`]: everything a run computed, in memory. The typed values (identified parameters,
//! posteriors with their draws and summaries, evidence, comparisons, level changes,
//! redundancy, basins, closed-loop results) and every table that [`crate::report::write`]
//! writes as parquet, as polars `DataFrame`s named by the file stems (`parameters`, `draws`,
//! `summary`, ...).

pub use super::level_results::LevelResults;
use crate::bayes::posterior::Draws;
use crate::bayes::PosteriorResult;
use crate::diagnose::LoopOutcome;
use crate::identify::GlobalResult;
use crate::inference::diagnostics::Summary;
use crate::output::Table;
use crate::stage::{LevelData, RunError};
use crate::study::Study;
use polars_core::prelude::DataFrame;
use std::sync::Arc;

/// The models' probabilities at one level ([`Results::model_probabilities`]).
#[derive(Clone, Debug)]
pub struct ModelProbabilities {
    /// The evidence estimator used: the first of stepping-stone, TMCMC reweighted, TMCMC and
    /// Laplace that every model has.
    pub estimator: &'static str,
    pub models: Vec<ModelProbability>,
}

/// One model's Bayes factor and probability.
#[derive(Clone, Debug)]
pub struct ModelProbability {
    pub model: String,
    /// Log Bayes factor against the best model (nats; 0 for the best).
    pub log_bf_vs_best: f64,
    pub probability: f64,
}

/// The folder (inside the results folder) of the closed loop's files.
pub const LOOP_DIR: &str = "closed_loop";

/// The identified parameters of one global RFM run (SI, in the law's order).
#[derive(Clone, Debug, PartialEq)]
pub struct IdentifiedParameters {
    pub level: String,
    pub model: String,
    pub names: Vec<String>,
    /// SI unit per parameter (`Pa`, `Pa s`, `1`, ...).
    pub units: Vec<String>,
    pub initial: Vec<f64>,
    pub identified: Vec<f64>,
    pub iterations: usize,
    pub stop_reason: String,
    /// Whether the fit is a result ([`crate::rfm::status`]).
    pub status: crate::rfm::FitStatus,
    /// FRAC per response channel at the initial and the identified parameters: the data
    /// against the predicted measurement (the `correlation` table's).
    pub frac_initial: Vec<f64>,
    pub frac_updated: Vec<f64>,
}

/// One global RFM run in the summary (`rfmlab run --json` and the console): the numbers of
/// [`IdentifiedParameters`], the same as the `parameters` and `correlation` tables'.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ModelSummary {
    pub level: String,
    pub model: String,
    pub param_names: Vec<String>,
    pub initial: Vec<f64>,
    pub identified: Vec<f64>,
    pub iterations: usize,
    pub stop_reason: String,
    /// `converged` or `flagged` (the tables' `status` column).
    pub status: String,
    /// Why the fit is flagged, in plain words (empty when converged).
    pub status_reason: String,
    /// The typed reasons (empty when converged).
    pub flags: Vec<crate::rfm::FlagReason>,
    /// FRAC per response channel at the identified parameters (`frac_updated`).
    pub frac: Vec<f64>,
}

impl From<&IdentifiedParameters> for ModelSummary {
    fn from(p: &IdentifiedParameters) -> Self {
        ModelSummary {
            level: p.level.clone(),
            model: p.model.clone(),
            param_names: p.names.clone(),
            initial: p.initial.clone(),
            identified: p.identified.clone(),
            iterations: p.iterations,
            stop_reason: p.stop_reason.clone(),
            status: p.status.label().to_string(),
            status_reason: p.status.reason_text(),
            flags: p.status.reasons().to_vec(),
            frac: p.frac_updated.clone(),
        }
    }
}

/// A fit that is not a result ([`Results::flagged`]).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct FlaggedFit {
    pub level: String,
    pub model: String,
    /// `global RFM` or `MAP`.
    pub fit: String,
    pub status: crate::rfm::FitStatus,
}

impl std::fmt::Display for FlaggedFit {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} {} ({}): {}",
            self.level,
            self.model,
            self.fit,
            self.status.reason_text()
        )
    }
}

/// A run's results in memory (see the module doc).
#[derive(Clone, Debug)]
pub struct Results {
    pub(crate) study: Arc<Study>,
    pub(crate) levels: Vec<LevelData>,
    pub(crate) level_results: Vec<LevelResults>,
    pub(crate) engine_note: String,
    pub(crate) timings: Vec<(String, f64)>,
    pub(crate) counters: Vec<(String, u64)>,
    pub(crate) seconds: f64,
    pub(crate) figures: bool,
    pub(crate) output_dir: std::path::PathBuf,
    pub(crate) closed_loop: Option<LoopOutcome>,
    pub(crate) mesh: Option<crate::discretisation::Discretisation>,
    /// The pre-flight's warnings that bear on the results (channels flipped, a level's file
    /// whose force level differs from the level's, bands beyond the data).
    pub(crate) preflight_warnings: Vec<String>,
    /// (name = path of the parquet file without `.parquet`, table, its DataFrame).
    tables: Vec<(String, Table, DataFrame)>,
}

impl Results {
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn new(
        study: Arc<Study>,
        levels: Vec<LevelData>,
        level_results: Vec<LevelResults>,
        engine_note: String,
        timings: Vec<(String, f64)>,
        counters: Vec<(String, u64)>,
        seconds: f64,
        figures: bool,
        output_dir: std::path::PathBuf,
        closed_loop: Option<LoopOutcome>,
        mesh: Option<crate::discretisation::Discretisation>,
    ) -> Result<Results, RunError> {
        let mut tables = Vec::new();
        for t in crate::pipeline::tables::all(&levels, &level_results)? {
            let df = t.to_dataframe()?;
            tables.push((t.name().to_string(), t, df));
        }
        if let Some(d) = &mesh {
            let t = discretisation_table(d)?;
            let df = t.to_dataframe()?;
            tables.push((t.name().to_string(), t, df));
        }
        if let Some(o) = &closed_loop {
            for t in crate::diagnose::loop_tables(o)? {
                let df = t.to_dataframe()?;
                tables.push((format!("{}/{}", LOOP_DIR, t.name()), t, df));
            }
        }
        Ok(Results {
            study,
            levels,
            level_results,
            engine_note,
            timings,
            counters,
            seconds,
            figures,
            output_dir,
            closed_loop,
            mesh,
            preflight_warnings: Vec::new(),
            tables,
        })
    }

    /// The pre-flight's warnings that bear on the results, one sentence each (the console
    /// and the report's first lines show them).
    pub fn preflight_warnings(&self) -> &[String] {
        &self.preflight_warnings
    }

    /// The mesh's estimated discretisation error per low mode (empty for imported models, lap
    /// joints, and a fixed mesh whose data were made on it without `[analyses] mesh_error`).
    pub fn mesh_error(&self) -> &[crate::stage::preflight::ModeDiscretisation] {
        self.mesh.as_ref().map_or(&[], |d| d.modes.as_slice())
    }

    /// How the mesh was chosen and the error it leaves ([`crate::discretisation`]).
    pub fn discretisation(&self) -> Option<&crate::discretisation::Discretisation> {
        self.mesh.as_ref()
    }

    /// The study that ran (with the plan's parameters written in).
    pub fn study(&self) -> &Study {
        &self.study
    }
    /// Names of the tables: the paths of the parquet files [`crate::report::write`] writes,
    /// without `.parquet` (`parameters`, `draws`, ..., `closed_loop/candidates`).
    pub fn table_names(&self) -> Vec<&str> {
        self.tables.iter().map(|(n, _, _)| n.as_str()).collect()
    }
    /// The table `name` (e.g. `"parameters"`, `"summary"`, `"draws"`).
    pub fn table(&self, name: &str) -> Option<&DataFrame> {
        self.tables
            .iter()
            .find(|(n, _, _)| n == name)
            .map(|(_, _, d)| d)
    }
    /// The table `name` with the unit of each column ([`Table::unit`]).
    pub fn table_with_units(&self, name: &str) -> Option<&Table> {
        self.tables
            .iter()
            .find(|(n, _, _)| n == name)
            .map(|(_, t, _)| t)
    }
    /// The tables of the results folder itself (not the closed loop's).
    pub(crate) fn top_tables(&self) -> impl Iterator<Item = &Table> {
        self.tables
            .iter()
            .filter(|(n, _, _)| !n.contains('/'))
            .map(|(_, t, _)| t)
    }
    /// The closed loop's outcome, when the plan ran it: per level its rounds, candidates,
    /// accepted effects and the fit before and after.
    pub fn closed_loop(&self) -> Option<&LoopOutcome> {
        self.closed_loop.as_ref()
    }
    /// The measured data of every level as the identification used it.
    pub fn levels(&self) -> &[LevelData] {
        &self.levels
    }
    /// Everything computed for `level` (deterministic analyses and posteriors).
    pub fn level(&self, level: &str) -> Option<&LevelResults> {
        self.level_results.iter().find(|r| r.level == level)
    }
    /// Everything computed, per level in data order.
    pub fn level_results(&self) -> &[LevelResults] {
        &self.level_results
    }
    /// The global RFM of `model` at `level` with its FRFs and correlation.
    pub fn rfm(&self, level: &str, model: &str) -> Option<&GlobalResult> {
        self.level(level)?
            .global
            .iter()
            .find(|g| g.result.model_name.eq_ignore_ascii_case(model))
    }
    /// The identified parameters of every global RFM run, per level and model.
    pub fn identified(&self) -> Vec<IdentifiedParameters> {
        self.level_results
            .iter()
            .flat_map(|r| {
                r.global.iter().map(move |g| {
                    let res = &g.result;
                    let units = crate::material::model_from_name(&res.model_name, None)
                        .map(|l| l.param_units())
                        .unwrap_or_else(|_| vec![String::new(); res.params.len()]);
                    IdentifiedParameters {
                        level: r.level.clone(),
                        model: res.model_name.clone(),
                        names: res.param_names.clone(),
                        units,
                        initial: res.initial.clone(),
                        identified: res.params.clone(),
                        iterations: res.iterations,
                        stop_reason: res.stop_reason.to_string(),
                        status: g.status.clone(),
                        frac_initial: g.frac_initial.clone(),
                        frac_updated: g.frac_updated.clone(),
                    }
                })
            })
            .collect()
    }
    /// The identified parameters of `model` at `level`.
    pub fn identified_at(&self, level: &str, model: &str) -> Option<IdentifiedParameters> {
        self.identified()
            .into_iter()
            .find(|p| p.level == level && p.model.eq_ignore_ascii_case(model))
    }
    /// Every posterior (MAP, samplers' draws, evidence, comparison, redundancy, basins).
    pub fn posteriors(&self) -> impl Iterator<Item = &PosteriorResult> {
        self.level_results.iter().flat_map(|r| r.posteriors.iter())
    }
    /// The posterior of `model` at `level`.
    pub fn posterior(&self, level: &str, model: &str) -> Option<&PosteriorResult> {
        self.posteriors()
            .find(|p| p.level == level && p.model.eq_ignore_ascii_case(model))
    }
    /// The models' probabilities at `level` under `prior` (`"declared"` or `"widened_10x"`),
    /// with equal prior model probabilities, as the `model_comparison` table gives them.
    /// `None` without evidence for every model.
    pub fn model_probabilities(&self, level: &str, prior: &str) -> Option<ModelProbabilities> {
        let posts: Vec<&PosteriorResult> = self.posteriors().filter(|p| p.level == level).collect();
        let (estimator, p) =
            crate::pipeline::tables::comparison::model_probabilities(&posts, prior)?;
        let models = posts
            .iter()
            .zip(p)
            .map(|(post, (log_bf_vs_best, probability))| ModelProbability {
                model: post.model.clone(),
                log_bf_vs_best,
                probability,
            })
            .collect();
        Some(ModelProbabilities { estimator, models })
    }
    /// The draws of `sampler` (`"nuts"`, `"tmcmc"`; `None`: the one the figures show) for
    /// `model` at `level`, with the parameter names (law, then noise) of `values`.
    pub fn draws(
        &self,
        level: &str,
        model: &str,
        sampler: Option<&str>,
    ) -> Option<(&[String], &Draws)> {
        let p = self.posterior(level, model)?;
        let s = match sampler {
            Some(name) => p.samplers.iter().find(|s| s.sampler.name() == name)?,
            None => p.figure_sampler()?,
        };
        Some((&p.names, &s.draws))
    }
    /// Diagnostics (mean, sd, quantiles, HDI, R-hat, ESS) per sampler and parameter of
    /// `model` at `level`, parameters in the order of [`PosteriorResult::names`].
    pub fn summaries(&self, level: &str, model: &str) -> Vec<(String, Vec<Summary>)> {
        self.posterior(level, model)
            .map(crate::pipeline::tables::summaries)
            .unwrap_or_default()
    }
    /// The plan's results folder (where `rfmlab run` writes these results).
    pub fn output_dir(&self) -> &std::path::Path {
        &self.output_dir
    }
    /// Description of the FRF engine (kind, ROM certificate).
    pub fn engine_note(&self) -> &str {
        &self.engine_note
    }
    /// Seconds per step of the run.
    pub fn timings(&self) -> &[(String, f64)] {
        &self.timings
    }
    /// Counters of the run: `rom builds` (ROMs built and certified) and `rom cache loads` (ROMs
    /// read from the cache instead).
    pub fn counters(&self) -> &[(String, u64)] {
        &self.counters
    }
    /// Wall-clock seconds of the run.
    pub fn seconds(&self) -> f64 {
        self.seconds
    }
    /// Per level and model: identified parameters, stop reason, status and FRAC per FRF, made
    /// from [`Results::identified`] (the numbers of the tables and the report).
    pub fn model_summaries(&self) -> Vec<ModelSummary> {
        self.identified().iter().map(ModelSummary::from).collect()
    }
    /// The fits that are not results ([`crate::rfm::FitStatus::Flagged`]): the global RFM per
    /// level and model, then each posterior's MAP.
    pub fn flagged(&self) -> Vec<FlaggedFit> {
        let mut out: Vec<FlaggedFit> = self
            .identified()
            .into_iter()
            .filter(|p| p.status.is_flagged())
            .map(|p| FlaggedFit {
                level: p.level,
                model: p.model,
                fit: "global RFM".into(),
                status: p.status,
            })
            .collect();
        for p in self.posteriors() {
            let status = crate::bayes::map_status(p);
            if status.is_flagged() {
                out.push(FlaggedFit {
                    level: p.level.clone(),
                    model: p.model.clone(),
                    fit: "MAP".into(),
                    status,
                });
            }
        }
        out
    }
}

/// The `discretisation` table: per mode on the mesh used, its estimated error and adhesive
/// share, with the mesh and the allowance on every row.
fn discretisation_table(d: &crate::discretisation::Discretisation) -> Result<Table, RunError> {
    let n = d.modes.len();
    let chosen = d.levels.get(d.chosen);
    let rep = |v: f64| vec![v; n];
    let mut t = Table::new("discretisation");
    t.push_u32("mode", "", d.modes.iter().map(|m| m.mode as u32).collect())
        .and_then(|t| t.push_f64("freq_hz", "Hz", d.modes.iter().map(|m| m.freq_hz).collect()))
        .and_then(|t| {
            t.push_f64(
                "error_hz",
                "Hz",
                d.modes.iter().map(|m| m.error_hz).collect(),
            )
        })
        .and_then(|t| {
            t.push_f64(
                "rel_error",
                "1",
                d.modes.iter().map(|m| m.rel_error).collect(),
            )
        })
        .and_then(|t| t.push_f64("order", "1", d.modes.iter().map(|m| m.order).collect()))
        .and_then(|t| {
            t.push_f64(
                "adhesive_share",
                "1",
                d.modes.iter().map(|m| m.adhesive_share).collect(),
            )
        })
        .and_then(|t| {
            t.push_f64(
                "measured_share",
                "1",
                d.modes.iter().map(|m| m.measured_share).collect(),
            )
        })
        .and_then(|t| t.push_str("rule", vec![d.rule.clone(); n]))
        .and_then(|t| t.push_opt_f64("edge_m", "m", vec![chosen.map(|l| l.edge_m); n]))
        .and_then(|t| t.push_opt_f64("n_dof", "1", vec![chosen.map(|l| l.n_dof as f64); n]))
        .and_then(|t| t.push_f64("tolerance", "1", rep(d.tolerance)))
        .and_then(|t| t.push_bool("reached", vec![d.reached; n]))
        .and_then(|t| t.push_f64("stiffness_excess", "1", rep(d.stiffness_excess)))
        .and_then(|t| t.push_f64("stiffness_excess_sd", "1", rep(d.stiffness_excess_sd)))
        .and_then(|t| t.push_f64("adherend_excess", "1", rep(d.adherend_excess)))
        .and_then(|t| t.push_f64("adherend_excess_sd", "1", rep(d.adherend_excess_sd)))
        .and_then(|t| t.push_bool("allowance", vec![d.allowance; n]))
        .map_err(RunError::Output)?;
    Ok(t)
}
