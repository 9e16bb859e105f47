//! Initial-value sensitivity: the argmin search of the MAP and the
//! deterministic global RFM from the same space-filling starts over the prior box (a Latin
//! hypercube in prior quantiles, plus the study's initial values = the paper's Table 4), end
//! points clustered into basins ([`crate::inference::basins`]).
//!
//! Distances are measured in Laplace posterior sd of the unconstrained coordinates at the MAP:
//! end points within `tolerance_sd` of a basin's best point in every coordinate share it. The
//! search's end points are first Newton-polished to their basin's stationary point
//! ([`polish_end_point`]): L-BFGS stops on a gradient tolerance, a fraction of an sd short of
//! it, which a 0.1-sd tolerance would otherwise count as separate basins. For
//! the search, basin 0 is the global MAP's (lowest `-log p`). The RFM minimises another
//! objective (its fixed point weighs lines by the modulus sensitivity, not by the noise), so its
//! basins are ordered by its own FRF residual and reported with their distance to the MAP.
//! The RFM here runs on the measured column without the leakage-corrected second pass of the
//! deterministic analysis (one pass per start).
//!
//! Starts run in parallel (rayon); results are collected in start order, so they do not depend
//! on the thread count.

use super::bayes::PosteriorResult;
use super::{LevelData, RunError};
use crate::frf::FrfEngine;
use crate::inference::basins::{cluster, Basin};
use crate::inference::likelihood::FrfPosterior;
use crate::inference::map::{find_map, polish_end_point, MapParams};
use crate::inference::Posterior;
use crate::material::ConstitutiveModel;
use crate::study::comparison::BasinSettings;
use crate::study::Study;
use rayon::prelude::*;
use std::time::Instant;

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

/// Coordinates in Laplace sd units.
fn scaled(post: &FrfPosterior<'_>, phys: &[f64], sd: &[f64]) -> Vec<f64> {
    post.unconstrained(phys)
        .iter()
        .zip(sd)
        .map(|(x, s)| x / s)
        .collect()
}

/// The first parameter whose unconstrained coordinate sits at its prior box's bound
/// (|x| > 9: within 1e-4 of the bound in prior quantile; the logistic map's gradient vanishes
/// there, so L-BFGS reports convergence on a plateau that is no optimum).
fn at_prior_bound(post: &FrfPosterior<'_>, x: &[f64]) -> Option<String> {
    use crate::inference::prior::Prior;
    x.iter()
        .zip(&post.priors)
        .zip(&post.names)
        .find(|((x, p), _)| x.abs() > 9.0 && !matches!(p, Prior::LogNormal { .. }))
        .map(|(_, n)| n.clone())
}

/// Run the basin study of `result` (the level's posterior of `law`) with `post` rebuilt in the
/// state the MAP search saw (measurement bias linearised at the MAP when the study does so).
#[allow(clippy::too_many_arguments)]
pub fn run(
    study: &Study,
    settings: &BasinSettings,
    post: &FrfPosterior<'_>,
    square_engine: &dyn FrfEngine,
    level: &LevelData,
    law: &dyn ConstitutiveModel,
    result: &PosteriorResult,
    max_iters: u64,
    seed: u64,
) -> Result<BasinStudy, RunError> {
    let d = post.dim();
    let nl = post.n_law();
    let lap = &result.map.laplace;
    let sd: Vec<f64> = (0..d)
        .map(|i| {
            let v = lap.cov_x[i * d + i];
            if v.is_finite() && v > 0.0 {
                v.sqrt()
            } else {
                1e-3
            }
        })
        .collect();
    let map_scaled = scaled(post, &result.map.map_physical, &sd);
    let dist = |p: &[f64]| -> f64 {
        scaled(post, p, &sd)
            .iter()
            .zip(&map_scaled)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max)
    };
    // 1. The search from the initial values and the design.
    let t0 = Instant::now();
    let params = MapParams {
        n_starts: settings.starts,
        max_iters,
        seed,
        ..MapParams::default()
    };
    let map = find_map(post, Some(&result.initial_x), &params, &|| ()).map_err(|e| {
        RunError::Analysis {
            analysis: format!("basin study of {} at {}", result.model, result.level),
            message: e.to_string(),
        }
    })?;
    // Polish each end point (in parallel, collected in start order); a failed polish keeps
    // the search's end point.
    let polished: Vec<(Vec<f64>, f64)> = map
        .starts
        .par_iter()
        .map(|s| {
            if !s.objective.is_finite() {
                return (s.end_x.clone(), s.objective);
            }
            match polish_end_point(post, &s.end_x, params.polish_tol) {
                Ok((x, f)) if f.is_finite() && f <= s.objective => (x, f),
                _ => (s.end_x.clone(), s.objective),
            }
        })
        .collect();
    let ends: Vec<Option<Vec<f64>>> = polished
        .iter()
        .map(|(x, f)| f.is_finite().then(|| post.physical(x)))
        .collect();
    let obj: Vec<f64> = polished.iter().map(|(_, f)| *f).collect();
    let pts: Vec<Option<Vec<f64>>> = ends
        .iter()
        .map(|e| e.as_ref().map(|p| scaled(post, p, &sd)))
        .collect();
    let (of, basins) = cluster(&pts, &obj, settings.tolerance_sd);
    let starts: Vec<BasinStart> = map
        .starts
        .iter()
        .zip(ends)
        .zip(&of)
        .map(|((s, end), b)| BasinStart {
            index: s.index,
            kind: s.kind,
            start: post.physical(&s.start_x),
            end,
            objective: polished[s.index].1,
            iterations: s.iterations,
            stop_reason: match at_prior_bound(post, &polished[s.index].0) {
                Some(name) => format!("{} (stalled at the prior bound of {name})", s.stop_reason),
                None => s.stop_reason.clone(),
            },
            basin: *b,
        })
        .collect();
    let distance_to_map_sd = basins.iter().map(|b| {
        let phys: Vec<f64> = b
            .point
            .iter()
            .zip(&sd)
            .zip(&post.priors)
            .map(|((z, s), p)| p.to_physical(z * s))
            .collect();
        dist(&phys)
    });
    let mut methods = vec![MethodBasins {
        method: "map",
        distance_to_map_sd: distance_to_map_sd.collect(),
        basins,
        starts,
        seconds: t0.elapsed().as_secs_f64(),
    }];
    // 2. The deterministic RFM from the same starts (law parameters only).
    if settings.rfm && nl == d {
        let t0 = Instant::now();
        let rp = super::compute::rfm_params(study);
        let starts_phys: Vec<(&'static str, Vec<f64>)> = methods[0]
            .starts
            .iter()
            .map(|s| (s.kind, s.start.clone()))
            .collect();
        let runs: Vec<BasinStart> = starts_phys
            .par_iter()
            .enumerate()
            .map(|(i, (kind, p0))| {
                match crate::rfm::rfm_global(square_engine, &level.column, law, p0, &rp) {
                    Ok(r) => {
                        let res = r
                            .history
                            .last()
                            .map_or(f64::INFINITY, |h| h.frf_relative_residual);
                        let ok = res.is_finite() && r.params.iter().all(|v| v.is_finite());
                        let inside = r
                            .params
                            .iter()
                            .zip(&post.priors)
                            .all(|(v, p)| p.contains(*v));
                        BasinStart {
                            index: i,
                            kind,
                            start: p0.clone(),
                            end: (ok && inside).then(|| r.params.clone()),
                            objective: if ok && inside { res } else { f64::INFINITY },
                            iterations: r.iterations as u64,
                            stop_reason: if ok && !inside {
                                format!("{} (outside the prior box)", r.stop_reason)
                            } else {
                                r.stop_reason.to_string()
                            },
                            basin: None,
                        }
                    }
                    Err(e) => BasinStart {
                        index: i,
                        kind,
                        start: p0.clone(),
                        end: None,
                        objective: f64::INFINITY,
                        iterations: 0,
                        stop_reason: format!("failed: {e}"),
                        basin: None,
                    },
                }
            })
            .collect();
        let pts: Vec<Option<Vec<f64>>> = runs
            .iter()
            .map(|s| s.end.as_ref().map(|p| scaled(post, p, &sd)))
            .collect();
        let obj: Vec<f64> = runs.iter().map(|s| s.objective).collect();
        let (of, basins) = cluster(&pts, &obj, settings.tolerance_sd);
        let runs: Vec<BasinStart> = runs
            .into_iter()
            .zip(of)
            .map(|(mut s, b)| {
                s.basin = b;
                s
            })
            .collect();
        let distance_to_map_sd = basins
            .iter()
            .map(|b| {
                let phys: Vec<f64> = b
                    .point
                    .iter()
                    .zip(&sd)
                    .zip(&post.priors)
                    .map(|((z, s), p)| p.to_physical(z * s))
                    .collect();
                dist(&phys)
            })
            .collect();
        methods.push(MethodBasins {
            method: "rfm",
            starts: runs,
            basins,
            distance_to_map_sd,
            seconds: t0.elapsed().as_secs_f64(),
        });
    }
    Ok(BasinStudy {
        names: post.names.clone(),
        tolerance_sd: settings.tolerance_sd,
        methods,
    })
}

/// The basin study of every posterior of a level (hook of the runner after the level's
/// inference): rebuilds each posterior, linearises its measurement bias at the MAP as the
/// search did, and runs [`run`].
pub fn run_level(
    study: &Study,
    inf: &crate::study::inference::Inference,
    lik_engine: &dyn FrfEngine,
    square_engine: &dyn FrfEngine,
    level: &LevelData,
    laws: &[Box<dyn ConstitutiveModel>],
    posts: &mut [PosteriorResult],
) -> Result<(), RunError> {
    let Some(settings) = &inf.basins else {
        return Ok(());
    };
    for (mi, p) in posts.iter_mut().enumerate() {
        let Some((_, law)) = study
            .models
            .iter()
            .zip(laws)
            .find(|(m, _)| m.name.eq_ignore_ascii_case(&p.model))
        else {
            continue;
        };
        let mut post =
            super::bayes::build_posterior(study, inf, lik_engine, level, law.as_ref(), &p.model)?;
        let nl = law.n_params();
        if inf.linearised_measurement && post.likelihood.forward.obs.measurement.is_some() {
            post.likelihood
                .forward
                .linearise_measurement(&p.map.map_physical[..nl])
                .map_err(|e| RunError::Analysis {
                    analysis: format!("basin study of {} at {}", p.model, p.level),
                    message: e.to_string(),
                })?;
        }
        let seed = study.seed
            ^ 0xBA51_0000_0000
            ^ ((mi as u64 + 1) << 40)
            ^ super::bayes::level_hash(&level.name);
        p.basins = Some(run(
            study,
            settings,
            &post,
            square_engine,
            level,
            law.as_ref(),
            p,
            inf.map_max_iterations,
            seed,
        )?);
    }
    Ok(())
}
