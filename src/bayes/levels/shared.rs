//! Shared or separate law parameters across two levels, by evidence: a posterior whose law
//! parameters are shared by both levels (likelihood = product of the levels' likelihoods,
//! noise coordinates per level, [`crate::inference::joint::JointPosterior`]) against separate
//! parameters per level (`log Z_low + log Z_high`). Laplace always (TMCMC when asked).
//! `log B = log Z_separate - log Z_shared > 0` favours a level-dependent
//! (amplitude-dependent) law. The shared MAP starts from the two MAPs' law coordinates
//! averaged and, with the measurement bias linearised, is re-linearised until it stops moving
//! (as the per-level search). Runs in `studies/bayes_compare.toml` (the suite's `docs` test
//! checks its tables).

use crate::bayes::posterior::build_posterior;
use crate::bayes::{InferenceParams, PosteriorResult, RunContext};
use crate::frf::FrfEngine;
use crate::inference::joint::JointPosterior;
use crate::inference::map::{find_map, MapParams, MapResult};
use crate::inference::Posterior;
use crate::inference::Sampler;
use crate::material::ConstitutiveModel;
use crate::stage::{LevelData, RunError};

/// Shared against separate law parameters.
#[derive(Clone, Debug)]
pub struct SharedEvidence {
    pub model: String,
    /// "laplace" or "tmcmc".
    pub method: &'static str,
    pub log_z_shared: f64,
    pub se_shared: f64,
    pub log_z_separate: f64,
    pub se_separate: f64,
    /// Law parameters at the shared posterior's MAP (SI).
    pub shared_map: Vec<f64>,
    pub names: Vec<String>,
    pub seconds: f64,
}

impl SharedEvidence {
    /// `log Z_separate - log Z_shared` (> 0 favours separate parameters per level).
    pub fn log_bayes_factor(&self) -> f64 {
        self.log_z_separate - self.log_z_shared
    }
}

fn fail(model: &str, e: impl std::fmt::Display) -> RunError {
    RunError::Analysis {
        analysis: format!("shared-parameter posterior of {model}"),
        message: e.to_string(),
    }
}

/// Laplace (and TMCMC when `tmcmc`) evidence of the law's parameters shared by `low` and
/// `high`, against the separate posteriors `pl` and `ph` of stage `stage` (the `mi`-th model
/// of the lower level).
#[allow(clippy::too_many_arguments)]
pub(super) fn shared_evidence(
    run: &RunContext<'_>,
    stage: &InferenceParams,
    tmcmc: bool,
    engine: &dyn FrfEngine,
    law: &dyn ConstitutiveModel,
    (low, pl): (&LevelData, &PosteriorResult),
    (high, ph): (&LevelData, &PosteriorResult),
    mi: usize,
) -> Result<Vec<SharedEvidence>, RunError> {
    let t0 = std::time::Instant::now();
    let model = pl.model.as_str();
    let nl = law.n_params();
    let inf = &stage.samplers;
    // The two levels' posteriors, built alike; the high level's extra parameters follow the
    // shared ones below.
    let [post_a, post_b] =
        [low, high].map(|level| build_posterior(&run.posterior, stage, engine, level, law));
    let (mut post_a, mut post_b) = (post_a?, post_b?);
    let linearised = inf.linearised_measurement
        && post_a.likelihood.forward.obs.measurement.is_some()
        && post_b.likelihood.forward.obs.measurement.is_some();
    let (da, db) = (post_a.dim(), post_b.dim());
    let map_a: Vec<usize> = (0..da).collect();
    let map_b: Vec<usize> = (0..nl)
        .chain((da..da + db - nl).collect::<Vec<_>>())
        .collect();
    let mut priors = post_a.priors.clone();
    priors.extend(post_b.priors[nl..].iter().cloned());
    let mut names: Vec<String> = post_a.names[..nl].to_vec();
    names.extend(
        post_a.names[nl..]
            .iter()
            .map(|n| format!("{n}_{}", low.name)),
    );
    names.extend(
        post_b.names[nl..]
            .iter()
            .map(|n| format!("{n}_{}", high.name)),
    );
    // Start: the two MAPs' law coordinates averaged, each level's noise coordinates.
    let mut x0: Vec<f64> = (0..nl)
        .map(|k| 0.5 * (pl.map.map_x[k] + ph.map.map_x[k]))
        .collect();
    x0.extend(pl.map.map_x[nl..].iter().copied());
    x0.extend(ph.map.map_x[nl..].iter().copied());
    let seed = run.seed ^ 0x5A4E_D000 ^ ((mi as u64 + 1) << 36);
    let params = MapParams {
        n_starts: inf.map_starts,
        max_iters: inf.map_max_iterations,
        seed,
        ..MapParams::default()
    };
    if linearised {
        let p0 = post_a.physical(&x0)[..nl].to_vec();
        post_a
            .likelihood
            .forward
            .linearise_measurement(&p0)
            .map_err(|e| fail(model, e))?;
        post_b
            .likelihood
            .forward
            .linearise_measurement(&p0)
            .map_err(|e| fail(model, e))?;
    }
    let search = |a: &crate::inference::likelihood::FrfPosterior<'_>,
                  b: &crate::inference::likelihood::FrfPosterior<'_>,
                  x: &[f64],
                  params: &MapParams|
     -> Result<MapResult, RunError> {
        let joint = JointPosterior::new(
            vec![a as &dyn Posterior, b as &dyn Posterior],
            vec![map_a.clone(), map_b.clone()],
            priors.clone(),
            names.clone(),
        )
        .map_err(|e| fail(model, e))?;
        find_map(&joint, Some(x), params, &|| ()).map_err(|e| fail(model, e))
    };
    let mut map = search(&post_a, &post_b, &x0, &params)?;
    if linearised {
        // Re-linearise at the shared MAP until it stops moving (as the per-level search does).
        for _ in 0..6 {
            let p_lin = map.map_physical[..nl].to_vec();
            post_a
                .likelihood
                .forward
                .linearise_measurement(&p_lin)
                .map_err(|e| fail(model, e))?;
            post_b
                .likelihood
                .forward
                .linearise_measurement(&p_lin)
                .map_err(|e| fail(model, e))?;
            let again = search(
                &post_a,
                &post_b,
                &map.map_x,
                &MapParams {
                    n_starts: 0,
                    ..params.clone()
                },
            )?;
            let moved = again.map_physical[..nl]
                .iter()
                .zip(&p_lin)
                .map(|(a, b)| ((a - b) / b).abs())
                .fold(0.0, f64::max);
            map = again;
            if moved < 1e-7 {
                break;
            }
        }
    }
    let mut out = vec![SharedEvidence {
        model: model.to_string(),
        method: "laplace",
        log_z_shared: map.laplace.log_evidence,
        se_shared: 0.0,
        log_z_separate: pl.map.laplace.log_evidence + ph.map.laplace.log_evidence,
        se_separate: 0.0,
        shared_map: map.map_physical[..nl].to_vec(),
        names: names[..nl].to_vec(),
        seconds: t0.elapsed().as_secs_f64(),
    }];
    if tmcmc {
        let sep = |p: &PosteriorResult| {
            p.samplers
                .iter()
                .find(|s| s.sampler == Sampler::Tmcmc)
                .and_then(|s| s.log_evidence)
        };
        if let (Some((za, sa)), Some((zb, sb)), Some(particles)) =
            (sep(pl), sep(ph), inf.tmcmc_particles)
        {
            let t1 = std::time::Instant::now();
            let joint = JointPosterior::new(
                vec![&post_a as &dyn Posterior, &post_b as &dyn Posterior],
                vec![map_a.clone(), map_b.clone()],
                priors.clone(),
                names.clone(),
            )
            .map_err(|e| fail(model, e))?;
            let run = crate::inference::sample_tmcmc(
                &joint,
                &crate::inference::TmcmcParams {
                    particles,
                    seed: seed ^ 0x746d_636d_6300,
                    ..Default::default()
                },
                None,
                &crate::inference::no_progress,
            )
            .map_err(|e| fail(model, e))?;
            out.push(SharedEvidence {
                model: model.to_string(),
                method: "tmcmc",
                log_z_shared: run.log_evidence,
                se_shared: run.log_evidence_se,
                log_z_separate: za + zb,
                se_separate: (sa * sa + sb * sb).sqrt(),
                shared_map: map.map_physical[..nl].to_vec(),
                names: names[..nl].to_vec(),
                seconds: t1.elapsed().as_secs_f64(),
            });
        }
    }
    Ok(out)
}
