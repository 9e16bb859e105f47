//! Initial-value sensitivity: the argmin search of the MAP and the
//! deterministic global RFM from the same space-filling starts over the prior box (a Latin
//! hypercube in prior quantiles, plus the study's initial values = the paper's Table 4), end
//! points clustered into basins ([`crate::inference::basins`]).
//!
//! Distances are measured in Laplace posterior sd of the unconstrained coordinates at the MAP:
//! end points within `tolerance_sd` of a basin's best point in every coordinate share it. The
//! search's end points are first Newton-polished to their basin's stationary point
//! ([`crate::inference::map::polish_end_point`]): L-BFGS stops on a gradient tolerance, a
//! fraction of an sd short of it, which a 0.1-sd tolerance would otherwise count as separate
//! basins. For the search, basin 0 is the global MAP's (lowest `-log p`). The RFM minimises
//! another objective (its fixed point weighs lines by the modulus sensitivity, not by the
//! noise), so its basins are ordered by its own FRF residual and reported with their distance
//! to the MAP.
//! The RFM here runs on the measured column without the leakage-corrected second pass of the
//! deterministic analysis (one pass per start).
//!
//! Starts run in parallel (rayon); results are collected in start order, so they do not depend
//! on the thread count.
//!
//! Types and the per-level driver here; the two methods' starts and clustering in `search.rs`.
//! The clustering is checked by the unit tests of [`crate::inference::basins`]; the study
//! itself runs with `[inference.basins]` (`studies/bayes_compare.toml`; the suite's `docs`
//! test checks its tables).

mod search;

pub use search::run;

use super::posterior::{build_posterior, level_hash};
use super::{InferenceParams, PosteriorResult, RunContext};
use crate::frf::FrfEngine;
use crate::inference::basins::Basin;
use crate::rfm::RfmParams;
use crate::stage::{LevelData, RunError};
use crate::study::comparison::BasinSettings;

/// One start of one method.
#[derive(Clone, Debug)]
pub struct BasinStart {
    pub index: usize,
    /// "initial" (the study's initial values) or "design".
    pub kind: &'static str,
    /// Physical values (SI) at the start and the end (`None` when the method failed).
    pub start: Vec<f64>,
    pub end: Option<Vec<f64>>,
    /// `-log p` (search) or the relative FRF residual (RFM) at the end.
    pub objective: f64,
    pub iterations: u64,
    pub stop_reason: String,
    pub basin: Option<usize>,
}

/// The starts of one method and their basins.
#[derive(Clone, Debug)]
pub struct MethodBasins {
    /// "map" (argmin L-BFGS on -log posterior) or "rfm" (global RFM fixed point).
    pub method: &'static str,
    pub starts: Vec<BasinStart>,
    pub basins: Vec<Basin>,
    /// Largest distance (Laplace sd, max over coordinates) of each basin's point from the MAP.
    pub distance_to_map_sd: Vec<f64>,
    pub seconds: f64,
}

impl MethodBasins {
    /// Fraction of starts in basin 0.
    pub fn fraction_best(&self) -> f64 {
        let n = self.starts.len().max(1) as f64;
        self.starts.iter().filter(|s| s.basin == Some(0)).count() as f64 / n
    }
    /// Fraction of starts ending within the tolerance of the MAP.
    pub fn fraction_at_map(&self, tol: f64) -> f64 {
        let n = self.starts.len().max(1) as f64;
        self.starts
            .iter()
            .filter(|s| s.basin.is_some_and(|b| self.distance_to_map_sd[b] <= tol))
            .count() as f64
            / n
    }
    /// The initial values' basin.
    pub fn initial_basin(&self) -> Option<usize> {
        self.starts
            .iter()
            .find(|s| s.kind == "initial")
            .and_then(|s| s.basin)
    }
    /// Stop reasons with their counts, most frequent first.
    pub fn stop_reasons(&self) -> Vec<(String, usize)> {
        let mut out: Vec<(String, usize)> = Vec::new();
        for s in &self.starts {
            match out.iter_mut().find(|(r, _)| *r == s.stop_reason) {
                Some(e) => e.1 += 1,
                None => out.push((s.stop_reason.clone(), 1)),
            }
        }
        out.sort_by_key(|b| std::cmp::Reverse(b.1));
        out
    }
}

/// The basin study of one model at one level.
#[derive(Clone, Debug)]
pub struct BasinStudy {
    pub names: Vec<String>,
    pub tolerance_sd: f64,
    pub methods: Vec<MethodBasins>,
}

/// The basin study of every posterior `posts` of a level (after the level's inference, whose
/// stages are `stages`): rebuilds each posterior on `lik_engine`, linearises its measurement
/// bias at the MAP as the search did, and runs [`run`] (the RFM with `rfm` on
/// `square_engine`).
#[allow(clippy::too_many_arguments)]
pub fn basins_of_level(
    run_ctx: &RunContext<'_>,
    stages: &[&InferenceParams],
    settings: &BasinSettings,
    rfm: &RfmParams,
    lik_engine: &dyn FrfEngine,
    square_engine: &dyn FrfEngine,
    level: &LevelData,
    posts: &mut [PosteriorResult],
) -> Result<(), RunError> {
    for (mi, p) in posts.iter_mut().enumerate() {
        let Some((_, law)) = run_ctx.model(&p.model) else {
            continue;
        };
        let Some(stage) = stages.iter().find(|s| s.model == p.model) else {
            continue;
        };
        let mut post = build_posterior(&run_ctx.posterior, stage, lik_engine, level, law)?;
        let nl = law.n_params();
        if stage.samplers.linearised_measurement
            && post.likelihood.forward.obs.measurement.is_some()
        {
            post.likelihood
                .forward
                .linearise_measurement(&p.map.map_physical[..nl])
                .map_err(|e| RunError::Analysis {
                    analysis: format!("basin study of {} at {}", p.model, p.level),
                    message: e.to_string(),
                })?;
        }
        let seed =
            run_ctx.seed ^ 0xBA51_0000_0000 ^ ((mi as u64 + 1) << 40) ^ level_hash(&level.name);
        p.basins = Some(run(
            settings,
            rfm,
            &post,
            square_engine,
            level,
            law,
            &p.map,
            &p.initial_x,
            &format!("{} at {}", p.model, p.level),
            stage.samplers.map_max_iterations,
            seed,
        )?);
    }
    Ok(())
}
