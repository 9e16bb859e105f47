//! Stepping-stone estimate of the log evidence (Xie, Lewis, Fan, Kuo and Chen 2011, Syst. Biol.
//! 60(2)) on draws from a resample-move particle population (Del Moral, Doucet and Jasra 2006,
//! JRSS B 68(3)), with its standard error from independent replicas. This module's path starts
//! at the prior; [`super::reference`] runs it from a reference density close to the posterior
//! (the generalized stepping-stone, a run's default), which needs 1-2 rungs instead of
//! dozens. Independent of TMCMC: its
//! own ladder, its own populations and random streams; it shares only the Metropolis kernel and
//! the resampling of [`super::sampling`].
//!
//! With draws `x_i` from `p(x) L(x)^beta_{k-1}`, the ratio `Z_k / Z_{k-1}` is estimated by
//! `r_k = log mean_i exp((beta_k - beta_{k-1}) log L(x_i))`, and `log Z = sum_k r_k`. Each
//! replica runs, from `N` prior draws at `beta_0 = 0`:
//! 1. the next exponent `beta_k`, by bisection so that the effective sample size of the weights
//!    `w_i = L(x_i)^(beta_k - beta_{k-1})`, `(sum w)^2 / sum w^2`, is `target_ess N` (or
//!    `beta_k = 1` if it is already above); the rung's `r_k`;
//! 2. `N` particles resampled (systematic) in proportion to `w_i`: they are draws from
//!    `beta_k`, up to the duplicates;
//! 3. rounds of random-walk Metropolis at `beta_k` (proposal covariance `s^2 Sigma`, `Sigma` the
//!    `w`-weighted covariance, `s` adapted toward `target_accept`) until the particles' log
//!    likelihoods have decorrelated from their values after resampling (Pearson correlation below
//!    `decorrelation`, at least `min_steps` and at most `max_steps` rounds). The last rung
//!    (`beta_k = 1`) needs no moves.
//!
//! `R` replicas with independent streams give `log Z_r`; the estimate is `log mean_r Z_r` (the
//! mean of the unbiased `Z_r`, less biased than the mean of the logs) and its standard error is
//! the delta method on their spread, `sqrt(sum_r (Z_r / Zbar - 1)^2 / (R (R - 1)))`: it holds
//! everything (rung-to-rung covariance through the shared particles, the lag of the chains, the
//! adaptive ladder) but is itself uncertain with few replicas (with the default 8, the error over
//! it follows a t-distribution with 7 degrees of freedom). Each replica also reports the
//! within-run delta-method error `sqrt(sum_k Var(w) / N)` (weights normalised to mean 1), which
//! ignores the correlation between rungs and underestimates (by 1.2-1.6x on the grid test
//! below).
//!
//! Why the earlier form was biased. It used a fixed power ladder `beta_k = (k/32)^(1/0.3)`, no
//! resampling, each of 500 particles a chain of 50 Metropolis rounds per rung. On the grid test
//! of `tests/suite/inference_grid.rs` (a 2-parameter FRF posterior 550-2800 times narrower than
//! its log-uniform prior in each coordinate; `log Z` = 133.4918 by quadrature) it was 3.4-5.5
//! nats low (a re-implementation with per-rung diagnostics: 129.20, -4.29, with 800 500
//! likelihood calls in 2 minutes). On a 5-D Gaussian (prior N(0, I), likelihood sd 1e-3, `log Z`
//! in closed form; the test `stepping_stone_evidence_of_a_narrow_likelihood_under_a_wide_prior`)
//! it was 1.3-3.6 nats low over 6 seeds. Measured per rung, two causes:
//! - the ladder was too coarse near `beta = 0` for this concentration (`beta_1 = 1e-5`,
//!   `beta_2 = 1e-4`): the weights' effective sample size was 3.5-4 % of `N` on rungs 2-3 of the
//!   grid test and 1.5 % on rungs 1-2 of a 5-D Gaussian of that kind, where the log-mean-exp of
//!   so few effective draws is low (its rung 3: -3.82 for an exact -3.35);
//! - without resampling each chain had to walk from its prior draw into every narrower target:
//!   on the grid test the median log likelihood of the draws at `beta` 1e-3 to 4e-3 was 20-30 %
//!   further below the maximum than the Gaussian approximation of the tempered posterior
//!   predicts, every such rung's ratio came out low, and the proposal scale shrank from 2.0 to
//!   0.004 (the covariance it used held the laggards). With 10 rounds per rung instead of 50,
//!   on a 2-D Gaussian of that kind the draws' variance was 2-4 times the target's over the
//!   first five rungs and `log Z` came out 2.8-3.3 nats low.
//!
//! Resampling removes the laggards, the ladder adapted to the effective sample size puts 6-7
//! rungs below `beta = 1e-4` on the grid test where the power ladder had 2, and the decorrelation
//! rule gives each rung the rounds it needs: 40-370 on the grid test for `beta` 1e-5 to 1e-4,
//! where the tempered target is far from Gaussian, and 5-30 elsewhere. On the grid test (single
//! replicas of 250 particles, mean error +- its standard error), fixed 10 rounds per rung gave
//! -0.16 +- 0.07 nats (8 runs), the rule with a threshold of 0.3 -0.14 +- 0.07 and with 0.1
//! -0.01 +- 0.07 (12 runs each, rounds capped at 100).
//!
//! Now, with the defaults (8 replicas of 250 particles, about 1.6 million likelihood calls and
//! 85 s on the grid test): seeds 5-8 gave 133.487 +- 0.037, 133.397 +- 0.055, 133.417 +- 0.058
//! and 133.603 +- 0.074, i.e. -0.005, -0.095, -0.075 and +0.111 nats (the test runs seed 5); the
//! 32 replicas averaged -0.03 +- 0.03 with a spread of 0.18 each, so the 8-replica estimate is
//! good to about 0.06-0.09 nats here, not reliably to 0.1. On the 5-D Gaussian above with
//! 8 x 1000 particles (8.1 million calls, 1 s) it was within 0.05 nats over 8 seeds, with errors
//! / standard error of rms 1.1 (a t-distribution with 7 degrees of freedom has 1.18); with a
//! uniform prior U(-2, 2)^5 instead, within 0.035 (6 seeds). The error falls as
//! `1 / sqrt(calls)`; per call it is larger than TMCMC's own (delta-method, optimistic) error,
//! 0.074 with 242 000 calls on the grid test: the rounds at `beta < 1e-4` take two thirds of
//! the calls there.
//!
//! Thermodynamic integration over the same ladder (Friel and Pettitt 2008; trapezoid on
//! `E_beta[log L]` with the correction `-(db^2 / 12) (Var_k - Var_{k-1})` of Friel, Hurn and Wyse
//! 2014) was measured as a second estimator on the same draws and left out: it agreed with the
//! ratios within 0.05 nats on the Gaussians but was 20-40 nats off on the grid test, where the
//! first interval integrates `E[log L]` over the prior (mean -1.3e5, variance 2e9 and more),
//! which no trapezoid resolves.
//!
//! Determinism: replica `r` takes its seed from `unit_rng(seed ^ salt, r)`, rung `k` of it its
//! streams from `unit_rng(replica seed, k)`: one stream per particle (and one for the resampling),
//! moves in parallel reduced in particle order, so results are bit-identical whatever the thread
//! count. A run checkpoints finished replicas ([`stepping_stone_replica`], [`combine_replicas`]).

use rand::RngExt;
use rayon::prelude::*;

use super::sampling::{
    cholesky_jittered, eval_log_lik, in_range, log_mean_exp, move_round, nonzero, particle_count,
    systematic_resample, weighted_mean_cov, Particle, Progress, SamplerError,
};
use super::{unit_rng, Posterior};

/// Stepping-stone settings.
#[derive(Debug, Clone, PartialEq)]
pub struct SteppingStoneParams {
    /// Particles per replica `N`. Default 250.
    pub particles: usize,
    /// Independent replicas `R` (the standard error comes from their spread; with 1 it is the
    /// within-run delta method, an underestimate). Default 8.
    pub replicas: usize,
    /// Effective sample size of each rung's weights as a fraction of `N`, which sets the
    /// ladder. Default 0.8 (TMCMC's coefficient of variation 1 is 0.5).
    pub target_ess: f64,
    /// The moves of a rung stop once the Pearson correlation between the particles' log
    /// likelihoods after resampling and now is below this. Default 0.1 (0.3 left the grid test
    /// -0.14 +- 0.07 nats off, see the module documentation).
    pub decorrelation: f64,
    /// Fewest Metropolis rounds per rung. Default 2.
    pub min_steps: usize,
    /// Most Metropolis rounds per rung, a safety cap: where it stops the moves before the
    /// decorrelation rule, the draws may lag the target (the grid test reached 100 on several
    /// rungs and up to 370 once). Default 500.
    pub max_steps: usize,
    /// Most rungs per replica before giving up. Default 500.
    pub max_rungs: usize,
    /// Initial proposal scale `s` (covariance `s^2 Sigma`). Default 0.5.
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
            particles: 250,
            replicas: 8,
            target_ess: 0.8,
            decorrelation: 0.1,
            min_steps: 2,
            max_steps: 500,
            max_rungs: 500,
            scale0: 0.5,
            target_accept: 0.23,
            seed: 0,
        }
    }
}

/// One rung of a replica's ladder.
#[derive(Debug, Clone, PartialEq)]
pub struct SteppingStoneRung {
    /// Exponent of the draws (`beta_{k-1}`).
    pub beta_from: f64,
    /// Exponent the ratio reaches (`beta_k`).
    pub beta_to: f64,
    /// `r_k`, this rung's log ratio.
    pub log_ratio: f64,
    /// Its delta-method variance, `Var(w) / N` with `w` normalised to mean 1.
    pub variance: f64,
    /// Effective sample size of the weights as a fraction of `N`.
    pub ess: f64,
    /// Metropolis rounds at `beta_to` after resampling (0 on the last rung).
    pub steps: usize,
    /// Their acceptance rate (0 on the last rung).
    pub acceptance: f64,
    /// Correlation of the log likelihoods before and after the moves (1 on the last rung).
    pub correlation: f64,
    /// Likelihood evaluations of the rung's moves.
    pub n_loglik: u64,
}

/// One independent replica: its own prior draws, ladder and moves.
#[derive(Debug, Clone, PartialEq)]
pub struct SteppingStoneReplica {
    /// Its log evidence `sum_k r_k`.
    pub log_evidence: f64,
    /// Within-run delta-method standard error `sqrt(sum_k variance_k)`.
    pub log_evidence_se: f64,
    /// The rungs, `k = 1..K`.
    pub rungs: Vec<SteppingStoneRung>,
    /// Likelihood evaluations (prior draws included).
    pub n_loglik: u64,
}

/// The result of [`stepping_stone`].
#[derive(Debug, Clone, PartialEq)]
pub struct SteppingStoneRun {
    /// Log evidence `log mean_r Z_r` over the replicas.
    pub log_evidence: f64,
    /// Its standard error from the replicas' spread (see the module documentation).
    pub log_evidence_se: f64,
    /// The replicas.
    pub replicas: Vec<SteppingStoneReplica>,
    /// Likelihood evaluations over all replicas.
    pub n_loglik: u64,
}

const SALT: u64 = 0x5354_4550_5354_4f4e; // "STEPSTON"

fn validate(p: &SteppingStoneParams) -> Result<(), SamplerError> {
    particle_count(p.particles, "at least 2 (hundreds for evidence)")?;
    nonzero("replicas", p.replicas)?;
    nonzero("max_steps", p.max_steps)?;
    nonzero("max_rungs", p.max_rungs)?;
    if p.min_steps > p.max_steps {
        return Err(SamplerError::Setting {
            name: "min_steps",
            value: p.min_steps.to_string(),
            hint: "at most max_steps",
        });
    }
    in_range(
        "target_ess",
        p.target_ess,
        0.0,
        1.0,
        "a fraction of the particles in (0, 1), e.g. 0.8",
    )?;
    in_range(
        "decorrelation",
        p.decorrelation,
        0.0,
        1.0,
        "a correlation in (0, 1), e.g. 0.1",
    )?;
    in_range(
        "scale0",
        p.scale0,
        0.0,
        f64::INFINITY,
        "a positive proposal scale",
    )?;
    in_range(
        "target_accept",
        p.target_accept,
        0.0,
        1.0,
        "an acceptance rate in (0, 1), e.g. 0.23",
    )
}

/// Effective sample size of `exp(db * ll)` as a fraction of the number of particles.
fn ess_fraction(ll: &[f64], db: f64) -> f64 {
    let m = ll.iter().map(|l| db * l).fold(f64::NEG_INFINITY, f64::max);
    let (s, s2) = ll.iter().fold((0.0, 0.0), |(s, s2), l| {
        let w = (db * l - m).exp();
        (s + w, s2 + w * w)
    });
    s * s / s2 / ll.len() as f64
}

/// The next exponent: the `beta' in (beta, 1]` where the weights' effective sample size is the
/// fraction `target` (bisection on the step), or 1 if it is at least that at 1.
fn next_beta(ll: &[f64], beta: f64, target: f64) -> f64 {
    let span = 1.0 - beta;
    if ess_fraction(ll, span) >= target {
        return 1.0;
    }
    let (mut lo, mut hi) = (0.0, span);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if ess_fraction(ll, mid) < target {
            hi = mid;
        } else {
            lo = mid;
        }
        if hi - lo <= 1e-12 * hi {
            break;
        }
    }
    (beta + 0.5 * (lo + hi)).min(1.0)
}

/// Pearson correlation over the pairs where both values are finite (0 when either side has no
/// spread: nothing left to decorrelate).
fn correlation(a: &[f64], b: &[f64]) -> f64 {
    let pairs: Vec<(f64, f64)> = a
        .iter()
        .zip(b)
        .filter(|(x, y)| x.is_finite() && y.is_finite())
        .map(|(x, y)| (*x, *y))
        .collect();
    let n = pairs.len() as f64;
    if n < 2.0 {
        return 0.0;
    }
    let ma = pairs.iter().map(|p| p.0).sum::<f64>() / n;
    let mb = pairs.iter().map(|p| p.1).sum::<f64>() / n;
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in &pairs {
        sab += (x - ma) * (y - mb);
        saa += (x - ma) * (x - ma);
        sbb += (y - mb) * (y - mb);
    }
    if saa > 0.0 && sbb > 0.0 {
        sab / (saa * sbb).sqrt()
    } else {
        0.0
    }
}

/// One replica from the prior to the posterior.
fn run_replica(
    post: &dyn Posterior,
    p: &SteppingStoneParams,
    replica: usize,
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<SteppingStoneReplica, SamplerError> {
    let n = p.particles;
    let d = post.dim();
    let seed: u64 = unit_rng(p.seed ^ SALT, replica as u64).random();
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

    let mut scale = p.scale0;
    let mut n_loglik = n as u64;
    let mut rungs: Vec<SteppingStoneRung> = Vec::new();
    let mut beta = 0.0;
    while beta < 1.0 {
        let k = rungs.len() + 1;
        if k > p.max_rungs {
            return Err(SamplerError::TooManyRungs {
                max_rungs: p.max_rungs,
                beta,
            });
        }
        let ll: Vec<f64> = particles.iter().map(|q| q.log_lik).collect();
        if !ll.iter().any(|l| l.is_finite()) {
            return Err(SamplerError::AllWeightsZero {
                particles: n,
                stage: k,
                beta,
            });
        }
        let next = next_beta(&ll, beta, p.target_ess);
        let lw: Vec<f64> = ll.iter().map(|l| (next - beta) * l).collect();
        let log_ratio = log_mean_exp(&lw);
        // Weights with mean 1: Var(r_k) ~ Var(w) / N.
        let w: Vec<f64> = lw.iter().map(|l| (l - log_ratio).exp()).collect();
        let var_w = w.iter().map(|v| (v - 1.0) * (v - 1.0)).sum::<f64>() / (n as f64 - 1.0);
        let sw2: f64 = w.iter().map(|v| v * v).sum();
        let ess = n as f64 / sw2;

        let (mut steps, mut acceptance, mut corr, mut rung_evals) = (0, 0.0, 1.0, 0u64);
        if next < 1.0 {
            let (_, cov) = weighted_mean_cov(&particles, &w, d);
            let chol = cholesky_jittered(&cov, d);
            let seed_k = rung_seed(k);
            let wn: Vec<f64> = w.iter().map(|v| v / n as f64).collect();
            let u0: f64 = unit_rng(seed_k, n as u64).random();
            let idx = systematic_resample(&wn, u0);
            particles = idx.iter().map(|&i| particles[i].clone()).collect();
            let mut rngs: Vec<_> = (0..n).map(|i| unit_rng(seed_k, i as u64)).collect();
            let ll0: Vec<f64> = particles.iter().map(|q| q.log_lik).collect();
            let mut accepted = 0u64;
            while steps < p.max_steps {
                let (a, e) = move_round(
                    post,
                    &mut particles,
                    &mut rngs,
                    next,
                    &chol,
                    &mut scale,
                    p.target_accept,
                    steps,
                )?;
                steps += 1;
                accepted += a;
                rung_evals += e;
                let ll1: Vec<f64> = particles.iter().map(|q| q.log_lik).collect();
                corr = correlation(&ll0, &ll1);
                if steps >= p.min_steps && corr < p.decorrelation {
                    break;
                }
            }
            acceptance = accepted as f64 / (n * steps) as f64;
        }
        n_loglik += rung_evals;
        rungs.push(SteppingStoneRung {
            beta_from: beta,
            beta_to: next,
            log_ratio,
            variance: var_w / n as f64,
            ess,
            steps,
            acceptance,
            correlation: corr,
            n_loglik: rung_evals,
        });
        progress(Progress::SteppingStoneRung {
            replica,
            replicas: p.replicas,
            rung: k,
            beta: next,
        });
        beta = next;
    }
    Ok(SteppingStoneReplica {
        log_evidence: rungs.iter().map(|r| r.log_ratio).sum(),
        log_evidence_se: rungs.iter().map(|r| r.variance).sum::<f64>().sqrt(),
        rungs,
        n_loglik,
    })
}

/// Estimates the log evidence of `post` by stepping-stone sampling over `replicas` independent
/// resample-move populations (see the module documentation). A recoverable likelihood failure
/// counts as zero likelihood; a fatal one stops the run with its message.
pub fn stepping_stone(
    post: &dyn Posterior,
    params: &SteppingStoneParams,
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<SteppingStoneRun, SamplerError> {
    validate(params)?;
    let replicas = (0..params.replicas)
        .map(|r| run_replica(post, params, r, progress))
        .collect::<Result<Vec<_>, _>>()?;
    Ok(combine_replicas(replicas))
}

/// Replica `replica` of [`stepping_stone`] alone (the same numbers as inside a full run), for
/// callers that keep finished replicas, e.g. in checkpoints.
pub fn stepping_stone_replica(
    post: &dyn Posterior,
    params: &SteppingStoneParams,
    replica: usize,
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<SteppingStoneReplica, SamplerError> {
    validate(params)?;
    run_replica(post, params, replica, progress)
}

/// The estimate over replicas: `log mean_r Z_r` and the replicas' standard error (the
/// within-run one for a single replica). `replicas` must not be empty.
pub fn combine_replicas(replicas: Vec<SteppingStoneReplica>) -> SteppingStoneRun {
    let logs: Vec<f64> = replicas.iter().map(|r| r.log_evidence).collect();
    let log_evidence = log_mean_exp(&logs);
    let nr = logs.len();
    let log_evidence_se = if nr >= 2 {
        let ss: f64 = logs
            .iter()
            .map(|l| ((l - log_evidence).exp() - 1.0).powi(2))
            .sum();
        (ss / (nr * (nr - 1)) as f64).sqrt()
    } else {
        replicas.first().map_or(f64::NAN, |r| r.log_evidence_se)
    };
    SteppingStoneRun {
        log_evidence,
        log_evidence_se,
        n_loglik: replicas.iter().map(|r| r.n_loglik).sum(),
        replicas,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn next_beta_hits_the_target_effective_sample_size() {
        let ll: Vec<f64> = (0..500)
            .map(|i| -0.5 * (i as f64 * 0.01).powi(2) * 50.0)
            .collect();
        let b = next_beta(&ll, 0.0, 0.8);
        assert!(b > 0.0 && b < 1.0);
        assert!((ess_fraction(&ll, b) - 0.8).abs() < 1e-9);
        // A flat likelihood goes straight to the posterior.
        assert_eq!(next_beta(&[-3.0; 10], 0.4, 0.8), 1.0);
        // Dead particles (-inf) have zero weight and do not break the search.
        let mut ll2 = ll.clone();
        ll2[0] = f64::NEG_INFINITY;
        let b2 = next_beta(&ll2, 0.0, 0.8);
        assert!(b2 > 0.0 && (ess_fraction(&ll2, b2) - 0.8).abs() < 1e-6);
    }

    #[test]
    fn correlation_ignores_dead_particles_and_flat_sides() {
        let a = [1.0, 2.0, 3.0, f64::NEG_INFINITY];
        let b = [2.0, 4.0, 6.0, 1.0];
        assert!((correlation(&a, &b) - 1.0).abs() < 1e-12);
        let c = [3.0, 2.0, 1.0, 0.0];
        assert!((correlation(&a, &c) + 1.0).abs() < 1e-12);
        assert_eq!(correlation(&a, &[5.0; 4]), 0.0);
    }

    #[test]
    fn settings_out_of_range_are_rejected_with_their_name() {
        let bad = |p: SteppingStoneParams| validate(&p).unwrap_err().to_string();
        let d = SteppingStoneParams::default();
        assert_eq!(
            bad(SteppingStoneParams {
                replicas: 0,
                ..d.clone()
            }),
            "replicas must be at least 1 (got 0)"
        );
        assert!(bad(SteppingStoneParams {
            target_ess: 1.0,
            ..d.clone()
        })
        .contains("target_ess = 1"));
        assert!(bad(SteppingStoneParams {
            min_steps: 5,
            max_steps: 4,
            ..d
        })
        .contains("min_steps = 5"));
    }
}
