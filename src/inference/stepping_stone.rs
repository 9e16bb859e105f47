//! Stepping-stone estimate of the log evidence (Xie, Lewis, Fan, Kuo and Chen 2011, Syst. Biol.
//! 60(2)), independent of TMCMC: a fixed ladder, no resampling.
//!
//! Ladder `beta_k = (k / K)^(1 / alpha)`, `k = 0..K` (`alpha` about 0.3 puts most rungs near the
//! prior, where the tempered densities change fastest). With draws `x_i` from
//! `p(x) L(x)^beta_{k-1}`, the ratio `Z_k / Z_{k-1}` is estimated by
//! `r_k = log mean_i exp((beta_k - beta_{k-1}) log L(x_i))`, and `log Z = sum_k r_k`.
//!
//! Draws: `N` independent prior draws at `beta_0 = 0`; each rung's draws are the previous rung's
//! moved by `steps_per_rung` rounds of random-walk Metropolis at the new exponent (proposal
//! covariance `s^2 Sigma`, `Sigma` the particles' covariance, `s` adapted toward
//! `target_accept`). Each particle is its own chain with its own RNG stream.
//!
//! Standard error: by the delta method each rung contributes
//! `Var(r_k) ~ Var(w) / (N mean(w)^2)` (`w` the rung's weights), and `se = sqrt(sum_k Var(r_k))`.
//! The particles of one rung are independent chains, so this is the right within-rung variance
//! once the chains have equilibrated; it neglects covariance between rungs (the same particles
//! carry over) and any lag of the chains behind the moving target. That lag is the main error
//! of this estimator: draws that have not caught up with `beta_{k-1}` are over-dispersed, have
//! low likelihoods and bias `log Z` low; give the chains enough rounds per rung
//! (`steps_per_rung`) for the random walk to decorrelate (a few times the dimension, divided by
//! the acceptance rate).

use rand::RngExt;
use rayon::prelude::*;

use super::sampling::{
    cholesky_jittered, eval_log_lik, in_range, log_mean_exp, move_population, nonzero,
    weighted_mean_cov, Particle, Progress, SamplerError,
};
use super::{unit_rng, Posterior};

/// Stepping-stone settings.
#[derive(Debug, Clone, PartialEq)]
pub struct SteppingStoneParams {
    /// Number of steps `K` of the ladder. Default 32 (Xie et al.: 32-64).
    pub rungs: usize,
    /// Ladder shape `alpha` in `beta_k = (k/K)^(1/alpha)`. Default 0.3.
    pub alpha: f64,
    /// Particles (independent chains) per rung. Default 500.
    pub particles: usize,
    /// Metropolis rounds per rung: the chains' burn-in toward each new exponent. Too few and the
    /// draws lag behind the tempered density (over-dispersed), which biases `log Z` low: on a
    /// 5-D Gaussian, 10 rounds gave -0.7 nats, 20 gave -0.2, 40 gave -0.02 to -0.07. Default 50.
    pub steps_per_rung: usize,
    /// Initial proposal scale. Default 0.5.
    pub scale0: f64,
    /// Target acceptance of the adaptive scaling. Default 0.23.
    pub target_accept: f64,
    /// Seed (streams are salted so that the same seed as a TMCMC run gives independent
    /// randomness). Default 0.
    pub seed: u64,
}

impl Default for SteppingStoneParams {
    fn default() -> Self {
        Self {
            rungs: 32,
            alpha: 0.3,
            particles: 500,
            steps_per_rung: 50,
            scale0: 0.5,
            target_accept: 0.23,
            seed: 0,
        }
    }
}

/// One rung of the ladder.
#[derive(Debug, Clone, PartialEq)]
pub struct SteppingStoneRung {
    /// Exponent of the draws (`beta_{k-1}`).
    pub beta_from: f64,
    /// Exponent the ratio reaches (`beta_k`).
    pub beta_to: f64,
    /// `r_k`, this rung's log ratio.
    pub log_ratio: f64,
    /// Its delta-method variance.
    pub variance: f64,
    /// Acceptance of the moves that produced the rung's draws (0 for the prior draws).
    pub acceptance: f64,
}

/// The result of [`stepping_stone`].
#[derive(Debug, Clone, PartialEq)]
pub struct SteppingStoneRun {
    /// Log evidence `sum_k r_k`.
    pub log_evidence: f64,
    /// Delta-method standard error.
    pub log_evidence_se: f64,
    /// The rungs, `k = 1..K`.
    pub rungs: Vec<SteppingStoneRung>,
    /// Likelihood evaluations.
    pub n_loglik: u64,
}

/// The ladder `beta_k = (k/K)^(1/alpha)`, `k = 0..=K`.
pub fn power_ladder(rungs: usize, alpha: f64) -> Vec<f64> {
    (0..=rungs)
        .map(|k| (k as f64 / rungs as f64).powf(1.0 / alpha))
        .collect()
}

const SALT: u64 = 0x5354_4550_5354_4f4e; // "STEPSTON"

/// Estimates the log evidence of `post` by stepping-stone sampling.
pub fn stepping_stone(
    post: &dyn Posterior,
    params: &SteppingStoneParams,
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<SteppingStoneRun, SamplerError> {
    nonzero("rungs", params.rungs)?;
    nonzero("particles", params.particles)?;
    nonzero("steps_per_rung", params.steps_per_rung)?;
    in_range(
        "alpha",
        params.alpha,
        0.0,
        f64::INFINITY,
        "a positive ladder shape, e.g. 0.3",
    )?;
    in_range(
        "scale0",
        params.scale0,
        0.0,
        f64::INFINITY,
        "a positive proposal scale",
    )?;
    in_range(
        "target_accept",
        params.target_accept,
        0.0,
        1.0,
        "an acceptance rate in (0, 1), e.g. 0.23",
    )?;
    let n = params.particles;
    let d = post.dim();
    let seed = params.seed ^ SALT;
    let ladder = power_ladder(params.rungs, params.alpha);
    let rung_seed = |k: usize| -> u64 { unit_rng(seed, k as u64).random() };

    let s0 = rung_seed(0);
    let init: Vec<Result<Particle, SamplerError>> = (0..n)
        .into_par_iter()
        .map(|i| {
            let mut rng = unit_rng(s0, i as u64);
            let x = post.sample_prior(&mut rng);
            let log_prior = post.log_prior(&x, None);
            Ok(Particle {
                log_lik: eval_log_lik(post, &x)?,
                x,
                log_prior,
            })
        })
        .collect();
    let mut particles = init.into_iter().collect::<Result<Vec<_>, _>>()?;
    // The moves draw from the first rung's streams (the prior draws used rung 0's).
    let s1 = rung_seed(1);
    let mut rngs: Vec<_> = (0..n).map(|i| unit_rng(s1, i as u64)).collect();

    let mut scale = params.scale0;
    let mut n_loglik = n as u64;
    let mut rungs = Vec::with_capacity(params.rungs);
    let mut acceptance = 0.0;
    for k in 1..=params.rungs {
        let (b0, b1) = (ladder[k - 1], ladder[k]);
        if k > 1 {
            // Move the draws from beta_{k-2} to beta_{k-1}.
            let ones = vec![1.0; n];
            let (_, cov) = weighted_mean_cov(&particles, &ones, d);
            let chol = cholesky_jittered(&cov, d);
            let m = move_population(
                post,
                &mut particles,
                &mut rngs,
                b0,
                &chol,
                &mut scale,
                params.target_accept,
                params.steps_per_rung,
            )?;
            acceptance = m.acceptance;
            n_loglik += m.n_loglik;
        }
        let lw: Vec<f64> = particles.iter().map(|p| (b1 - b0) * p.log_lik).collect();
        let log_ratio = log_mean_exp(&lw);
        if log_ratio == f64::NEG_INFINITY {
            return Err(SamplerError::AllWeightsZero {
                particles: n,
                stage: k,
                beta: b0,
            });
        }
        let w: Vec<f64> = lw.iter().map(|l| (l - log_ratio).exp()).collect();
        // w has mean 1: Var(r_k) ~ Var(w) / N.
        let var_w =
            w.iter().map(|v| (v - 1.0) * (v - 1.0)).sum::<f64>() / (n as f64 - 1.0).max(1.0);
        rungs.push(SteppingStoneRung {
            beta_from: b0,
            beta_to: b1,
            log_ratio,
            variance: var_w / n as f64,
            acceptance,
        });
        progress(Progress::SteppingStoneRung {
            rung: k,
            rungs: params.rungs,
            beta: b1,
        });
    }
    Ok(SteppingStoneRun {
        log_evidence: rungs.iter().map(|r| r.log_ratio).sum(),
        log_evidence_se: rungs.iter().map(|r| r.variance).sum::<f64>().sqrt(),
        rungs,
        n_loglik,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ladder_runs_from_prior_to_posterior_and_crowds_near_zero() {
        let l = power_ladder(32, 0.3);
        assert_eq!(l.len(), 33);
        assert_eq!((l[0], l[32]), (0.0, 1.0));
        assert!(l.windows(2).all(|w| w[1] > w[0]));
        assert!(l[16] < 0.11, "half the rungs below beta = 0.1: {}", l[16]);
    }
}
