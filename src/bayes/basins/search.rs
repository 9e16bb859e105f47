//! The basin study's two methods from the same starts: the argmin search of the MAP (end
//! points Newton-polished to their basin's stationary point) and the deterministic global RFM
//! (law parameters only, one pass per start on the measured column), each clustered into
//! basins in Laplace sd units ([`crate::inference::basins::cluster`]). Starts run in parallel;
//! results are collected in start order.

use super::{BasinStart, BasinStudy, MethodBasins};
use crate::frf::FrfEngine;
use crate::inference::basins::cluster;
use crate::inference::likelihood::FrfPosterior;
use crate::inference::map::{find_map, polish_end_point, MapParams, MapResult};
use crate::inference::Posterior;
use crate::material::ConstitutiveModel;
use crate::rfm::RfmParams;
use crate::stage::{LevelData, RunError};
use crate::study::comparison::BasinSettings;
use rayon::prelude::*;
use std::time::Instant;

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

/// Run the basin study around `map` (the MAP of the level's posterior of `law`, found from
/// `initial_x`; `label` names model and level in errors) with `post` rebuilt in the
/// state the MAP search saw (measurement bias linearised at the MAP when the study does so);
/// the RFM runs with `rfm`.
#[allow(clippy::too_many_arguments)]
pub fn run(
    settings: &BasinSettings,
    rfm: &RfmParams,
    post: &FrfPosterior<'_>,
    square_engine: &dyn FrfEngine,
    level: &LevelData,
    law: &dyn ConstitutiveModel,
    map: &MapResult,
    initial_x: &[f64],
    label: &str,
    max_iters: u64,
    seed: u64,
) -> Result<BasinStudy, RunError> {
    let d = post.dim();
    let nl = post.n_law();
    let lap = &map.laplace;
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
    let map_scaled = scaled(post, &map.map_physical, &sd);
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
    let map = find_map(post, Some(initial_x), &params, &|| ()).map_err(|e| RunError::Analysis {
        analysis: format!("basin study of {label}"),
        message: e.to_string(),
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
        let starts_phys: Vec<(&'static str, Vec<f64>)> = methods[0]
            .starts
            .iter()
            .map(|s| (s.kind, s.start.clone()))
            .collect();
        let runs: Vec<BasinStart> = starts_phys
            .par_iter()
            .enumerate()
            .map(|(i, (kind, p0))| {
                match crate::rfm::rfm_global(square_engine, &level.column, law, p0, rfm) {
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
