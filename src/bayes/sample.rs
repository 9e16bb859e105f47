//! Samplers of the `[inference]` part of a run: NUTS (from dispersed starts around the Laplace
//! approximation) and TMCMC (from the prior), with checkpoints per level, model and sampler so
//! that an interrupted run resumes where it stopped and ends with the same draws.
//!
//! NUTS samples in coordinates whitened by the Laplace approximation, `x = m + L z` with
//! `L L^T` the Laplace covariance, from starts `z ~ N(0, 4 I)` (twice the Laplace spread).
//! Checked by the suite's `bayes_run` (draws against ArviZ's diagnostics; a run killed while
//! sampling and run again ends with the same draws; one thread gives the same draws) and
//! `inference_samplers` tests.

use super::posterior::{Draws, SamplerResult};
use super::{fail, At, Checkpoints, SamplerParams};
use crate::inference::likelihood::FrfPosterior;
use crate::inference::map::MapResult;
use crate::inference::whiten::Whitened;
use crate::inference::Sampler;
use crate::inference::{
    sample_nuts, sample_tmcmc, unit_rng, NutsParams, Posterior, Progress, TmcmcParams,
};
use crate::linalg::dense::cholesky;
use crate::stage::{Event, RunError};
use rand_distr::{Distribution, StandardNormal};
use std::time::Instant;

/// Stream offset of the NUTS starts (chain c uses unit `START_STREAM + c`).
const START_STREAM: u64 = 0x5354_4152_5400;

/// Dispersed NUTS starts: the Laplace mode plus twice its spread, one stream per chain.
pub fn dispersed_starts(map: &MapResult, chains: usize, seed: u64) -> Vec<Vec<f64>> {
    let lp = &map.laplace;
    let d = lp.dim();
    let l = if lp.positive_definite {
        cholesky(&lp.cov_x, d)
    } else {
        None
    };
    (0..chains)
        .map(|c| {
            let mut rng = unit_rng(seed, START_STREAM + c as u64);
            let z: Vec<f64> = (0..d).map(|_| StandardNormal.sample(&mut rng)).collect();
            match &l {
                Some(l) => (0..d)
                    .map(|i| lp.x[i] + 2.0 * (0..=i).map(|k| l[i * d + k] * z[k]).sum::<f64>())
                    .collect(),
                None => (0..d).map(|i| lp.x[i] + 0.05 * z[i]).collect(),
            }
        })
        .collect()
}

/// The samplers of `inf` (NUTS, then TMCMC) on `post` for the stage `at` (its seed), with
/// their checkpoints in `checkpoints`.
pub fn run_samplers(
    checkpoints: &Checkpoints<'_>,
    inf: &SamplerParams,
    post: &FrfPosterior<'_>,
    map: &MapResult,
    at: &At<'_>,
    progress: &(dyn Fn(Event) + Sync),
) -> Result<Vec<SamplerResult>, RunError> {
    let (seed, level, model) = (at.seed, at.level, at.model);
    let mut out = Vec::new();
    let d = post.dim();
    if let Some(n) = &inf.nuts {
        let params = NutsParams {
            chains: n.chains,
            tune: n.tune as u64,
            draws: n.draws as u64,
            seed,
            max_tree_depth: n.max_tree_depth,
            target_accept: n.target_accept,
            ..NutsParams::default()
        };
        let every = params.progress_every.max(1);
        let per_chain = (n.tune + n.draws) as u64 / every;
        progress(Event::Start {
            step: format!(
                "{}: NUTS on {model} ({} chains x {} + {} draws)",
                level.name, n.chains, n.tune, n.draws
            ),
            total: per_chain * n.chains as u64,
        });
        // Sample in coordinates whitened by the Laplace approximation (x = m + L z): the
        // posteriors are narrow and correlated in x, nearly isotropic in z.
        let lp = &map.laplace;
        let whitened = if lp.positive_definite {
            cholesky(&lp.cov_x, d).and_then(|l| Whitened::new(post, lp.x.clone(), l))
        } else {
            None
        };
        let target: &dyn Posterior = match &whitened {
            Some(w) => w,
            None => post,
        };
        let starts = match &whitened {
            // Twice the Laplace spread around its mode: z ~ N(0, 4 I).
            Some(_) => (0..n.chains)
                .map(|c| {
                    let mut rng = unit_rng(seed, START_STREAM + c as u64);
                    (0..d)
                        .map(|_| {
                            let v: f64 = StandardNormal.sample(&mut rng);
                            2.0 * v
                        })
                        .collect()
                })
                .collect(),
            None => dispersed_starts(map, n.chains, seed),
        };
        let dir = checkpoints.dir(level, model, Sampler::Nuts.name());
        let t0 = Instant::now();
        let run = sample_nuts(target, &starts, &params, Some(&dir), &|p| match p {
            Progress::NutsDraws { .. } => progress(Event::Advance),
            Progress::NutsChainLoaded { .. } => {
                for _ in 0..per_chain {
                    progress(Event::Advance);
                }
            }
            _ => {}
        })
        .map_err(|e| fail(format!("NUTS of {model} at level {}", level.name), e))?;
        progress(Event::Finish);
        let mut draws = Draws {
            values: vec![Vec::new(); d],
            ..Draws::default()
        };
        let stat_names = ["step_size", "tree_depth", "n_steps", "diverging", "energy"];
        let mut stats: Vec<Vec<f64>> = vec![Vec::new(); stat_names.len()];
        let mut evaluations = 0usize;
        for c in &run.chains {
            for i in 0..c.len() {
                draws.chain.push(c.chain);
                draws.draw.push(i);
                for (k, v) in c.constrained[i].iter().enumerate() {
                    draws.values[k].push(*v);
                }
                draws.lp.push(c.lp[i]);
                draws.log_lik.push(c.log_lik[i]);
                draws.log_prior.push(c.log_prior[i]);
                stats[0].push(c.step_size[i]);
                stats[1].push(c.tree_depth[i] as f64);
                stats[2].push(c.n_steps[i] as f64);
                stats[3].push(if c.divergent[i] { 1.0 } else { 0.0 });
                stats[4].push(c.energy[i]);
                evaluations += c.n_steps[i] as usize;
            }
        }
        draws.stats = stat_names
            .iter()
            .map(|s| s.to_string())
            .zip(stats)
            .collect();
        let divergent = run.n_divergent();
        let tune_div: u64 = run.chains.iter().map(|c| c.tune_divergences).sum();
        out.push(SamplerResult {
            sampler: Sampler::Nuts,
            draws,
            log_evidence: None,
            evaluations,
            seconds: t0.elapsed().as_secs_f64(),
            notes: vec![
                format!(
                    "{divergent} divergent transitions after warm-up ({tune_div} during warm-up)"
                ),
                format!("chains loaded from checkpoints: {:?}", run.loaded_chains),
            ],
        });
    }
    if let Some(particles) = inf.tmcmc_particles {
        let params = TmcmcParams {
            particles,
            seed: seed ^ 0x746d_636d_6300,
            ..TmcmcParams::default()
        };
        progress(Event::Start {
            step: format!("{}: TMCMC on {model} ({particles} particles)", level.name),
            total: 0,
        });
        let dir = checkpoints.dir(level, model, Sampler::Tmcmc.name());
        let t0 = Instant::now();
        let run = sample_tmcmc(post, &params, Some(&dir), &|p| {
            if let Progress::TmcmcStage { .. } = p {
                progress(Event::Advance)
            }
        })
        .map_err(|e| fail(format!("TMCMC of {model} at level {}", level.name), e))?;
        progress(Event::Finish);
        let n = run.x.len();
        let mut draws = Draws {
            values: vec![Vec::new(); d],
            ..Draws::default()
        };
        for i in 0..n {
            // TMCMC's final particles are one population: chain 0 (diagnostics that need
            // chains do not apply to them).
            draws.chain.push(0);
            draws.draw.push(i);
            for (k, v) in run.constrained[i].iter().enumerate() {
                draws.values[k].push(*v);
            }
            draws.lp.push(run.log_lik[i] + run.log_prior[i]);
            draws.log_lik.push(run.log_lik[i]);
            draws.log_prior.push(run.log_prior[i]);
        }
        let notes = run
            .stages
            .iter()
            .map(|s| {
                format!(
                    "stage {}: beta {:.3e}, acceptance {:.2}, weights ESS {:.0}, scale {:.3}",
                    s.stage, s.beta, s.acceptance, s.ess, s.scale
                )
            })
            .collect();
        out.push(SamplerResult {
            sampler: Sampler::Tmcmc,
            draws,
            log_evidence: Some((run.log_evidence, run.log_evidence_se)),
            evaluations: run.n_loglik() as usize,
            seconds: t0.elapsed().as_secs_f64(),
            notes,
        });
    }
    Ok(out)
}
