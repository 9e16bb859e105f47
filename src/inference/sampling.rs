//! What the samplers share: their error type, the progress events they report, the
//! random-walk Metropolis kernel on a tempered posterior that TMCMC and stepping-stone move
//! their particles with, and systematic resampling.
//!
//! The tempered target at exponent `beta` is `pi_beta(x) ∝ p(x) L(x)^beta` (prior times the
//! likelihood raised to `beta`); `beta = 0` is the prior, `beta = 1` the posterior. A proposal
//! `y = x + s L z` (`z` standard normal, `L L^T = Sigma` the population covariance, `s` the
//! proposal scale) is accepted with probability `min(1, pi_beta(y) / pi_beta(x))`. After each
//! round (every particle one step) the scale is adapted toward a target acceptance rate,
//! `s <- s exp((a - a*) / sqrt(i))` for round `i` of the stage (Papaioannou, Betz, Zwirglmaier
//! and Straub 2015, Prob. Eng. Mech. 41; used for TMCMC by Betz, Papaioannou and Straub 2016).
//!
//! Determinism: each particle owns its RNG stream, rounds are run in parallel with rayon and
//! their counts reduced sequentially in particle order, so results do not depend on the number
//! of threads.

use std::path::PathBuf;

use rand::rngs::StdRng;
use rand::RngExt;
use rand_distr::StandardNormal;
use rayon::prelude::*;

use super::{DensityError, Posterior};

/// The posterior samplers a study can run. Their names (`"nuts"`, `"tmcmc"`) are the study
/// file's words and the `sampler` column of the results.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Sampler {
    /// The No-U-Turn sampler ([`super::nuts`]).
    Nuts,
    /// Transitional MCMC ([`super::tmcmc`]), which also estimates the evidence.
    Tmcmc,
}

impl Sampler {
    /// The name in study files and result tables.
    pub fn name(self) -> &'static str {
        match self {
            Sampler::Nuts => "nuts",
            Sampler::Tmcmc => "tmcmc",
        }
    }
}

impl std::fmt::Display for Sampler {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Why a sampler stopped without a result.
#[derive(Debug, thiserror::Error)]
pub enum SamplerError {
    /// A count setting (chains, draws, particles, rungs) is zero.
    #[error("{what} must be at least 1 (got 0)")]
    Zero {
        /// The setting's name.
        what: &'static str,
    },
    /// A setting outside its admissible range.
    #[error("invalid setting {name} = {value}: {hint}")]
    Setting {
        /// The setting's name.
        name: &'static str,
        /// Its value, as given.
        value: String,
        /// What it must be.
        hint: &'static str,
    },
    /// Not one start per chain.
    #[error("{got} starts given for {chains} chains: give one start per chain")]
    StartCount {
        /// Starts given.
        got: usize,
        /// Chains asked for.
        chains: usize,
    },
    /// A start of the wrong dimension.
    #[error("start {index} has {got} coordinates but the posterior has {dim}")]
    StartDim {
        /// Index of the start.
        index: usize,
        /// Its length.
        got: usize,
        /// The posterior's dimension.
        dim: usize,
    },
    /// A start where NUTS cannot begin: the log posterior or its gradient is not finite there,
    /// or a gradient component stays exactly zero (nuts-rs initialises the mass matrix from it).
    #[error("start {index} is not usable ({detail}): choose starts inside the support, e.g. prior draws or jittered MAP points")]
    BadStart {
        /// Index of the start.
        index: usize,
        /// The value or the density's message.
        detail: String,
    },
    /// The density reported an unrecoverable error.
    #[error("fatal density error: {0}")]
    Fatal(String),
    /// nuts-rs stopped a chain for a reason other than a fatal density error.
    #[error("NUTS chain {chain} failed: {message}")]
    Nuts {
        /// The chain.
        chain: usize,
        /// nuts-rs's message (whole error chain).
        message: String,
    },
    /// No particle has a positive likelihood: the tempering cannot proceed.
    #[error("all {particles} particles have zero likelihood at stage {stage} (beta = {beta}): the likelihood fails or underflows everywhere the prior puts its mass")]
    AllWeightsZero {
        /// Number of particles.
        particles: usize,
        /// The stage.
        stage: usize,
        /// The current tempering exponent.
        beta: f64,
    },
    /// TMCMC ran out of stages before reaching the posterior.
    #[error("TMCMC did not reach beta = 1 within {max_stages} stages (beta = {beta}): raise max_stages or the number of particles")]
    TooManyStages {
        /// The stage limit.
        max_stages: usize,
        /// The exponent reached.
        beta: f64,
    },
    /// Stepping-stone ran out of rungs before reaching the posterior.
    #[error("stepping-stone did not reach beta = 1 within {max_rungs} rungs (beta = {beta}): raise max_rungs or lower target_ess")]
    TooManyRungs {
        /// The rung limit.
        max_rungs: usize,
        /// The exponent reached.
        beta: f64,
    },
    /// The run stopped on request (`stop_after_stages`) after saving its checkpoint.
    #[error("stopped after stage {stage} as requested; rerun with the same checkpoint to resume")]
    Stopped {
        /// The last completed stage.
        stage: usize,
    },
    /// A checkpoint could not be read or written.
    #[error("checkpoint {op} failed for {}: {source}", path.display())]
    Checkpoint {
        /// The file or directory.
        path: PathBuf,
        /// What was attempted.
        op: &'static str,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
}

/// A progress event, passed to the caller's callback (which may be called from several
/// threads at once).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Progress {
    /// A NUTS chain has done `done` of its `total` iterations (warm-up included).
    NutsDraws {
        /// The chain.
        chain: usize,
        /// Iterations done.
        done: u64,
        /// Warm-up plus kept draws.
        total: u64,
    },
    /// A NUTS chain was loaded from its checkpoint instead of being run.
    NutsChainLoaded {
        /// The chain.
        chain: usize,
    },
    /// A TMCMC stage is complete (stage 0 is the prior draws).
    TmcmcStage {
        /// The stage.
        stage: usize,
        /// Its tempering exponent.
        beta: f64,
        /// The acceptance rate of its moves (0 for stage 0).
        acceptance: f64,
    },
    /// TMCMC resumed from a checkpoint after `stage`.
    TmcmcResumed {
        /// The last saved stage.
        stage: usize,
        /// Its exponent.
        beta: f64,
    },
    /// A stepping-stone rung is done (its ladder is adaptive: the number of rungs is known only
    /// when `beta` reaches 1).
    SteppingStoneRung {
        /// The replica (independent population, 0-based).
        replica: usize,
        /// The number of replicas.
        replicas: usize,
        /// The rung (1-based).
        rung: usize,
        /// Its exponent.
        beta: f64,
    },
}

/// A progress callback that ignores every event.
pub fn no_progress(_: Progress) {}

/// Log likelihood for a population move: a recoverable failure (or NaN) is `-inf` (the point is
/// rejected), a fatal one stops the run.
pub(crate) fn eval_log_lik(post: &dyn Posterior, x: &[f64]) -> Result<f64, SamplerError> {
    match post.log_likelihood(x, None) {
        Ok(v) if v.is_nan() => Ok(f64::NEG_INFINITY),
        Ok(v) => Ok(v),
        Err(DensityError::Recoverable(_)) => Ok(f64::NEG_INFINITY),
        Err(DensityError::Fatal(m)) => Err(SamplerError::Fatal(m)),
    }
}

/// `log p(x) + beta log L(x)`, with `beta = 0` the prior even where `log L = -inf`.
pub(crate) fn tempered(log_prior: f64, log_lik: f64, beta: f64) -> f64 {
    if beta == 0.0 {
        log_prior
    } else {
        log_prior + beta * log_lik
    }
}

/// `log(mean(exp(v)))`, stable; `-inf` when every term is `-inf`.
pub(crate) fn log_mean_exp(v: &[f64]) -> f64 {
    let m = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if m == f64::NEG_INFINITY {
        return m;
    }
    let s: f64 = v.iter().map(|a| (a - m).exp()).sum();
    m + (s / v.len() as f64).ln()
}

/// One particle of a population: its position and cached densities.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Particle {
    pub x: Vec<f64>,
    pub log_lik: f64,
    pub log_prior: f64,
}

/// Mean and covariance (row-major `d x d`, divisor = sum of weights) of the particles with
/// weights `w` (any positive scale; all ones for an unweighted population).
pub(crate) fn weighted_mean_cov(ps: &[Particle], w: &[f64], d: usize) -> (Vec<f64>, Vec<f64>) {
    let sw: f64 = w.iter().sum();
    let mut mean = vec![0.0; d];
    for (p, &wi) in ps.iter().zip(w) {
        for k in 0..d {
            mean[k] += wi * p.x[k];
        }
    }
    mean.iter_mut().for_each(|m| *m /= sw);
    let mut cov = vec![0.0; d * d];
    for (p, &wi) in ps.iter().zip(w) {
        if wi == 0.0 {
            continue;
        }
        for a in 0..d {
            let da = p.x[a] - mean[a];
            for b in 0..=a {
                cov[a * d + b] += wi * da * (p.x[b] - mean[b]);
            }
        }
    }
    for a in 0..d {
        for b in 0..=a {
            let v = cov[a * d + b] / sw;
            cov[a * d + b] = v;
            cov[b * d + a] = v;
        }
    }
    (mean, cov)
}

/// Lower Cholesky factor (row-major) of a symmetric covariance; when it is not positive
/// definite (a collapsed population), a growing multiple of its mean diagonal is added, and as
/// a last resort the identity is used.
pub(crate) fn cholesky_jittered(cov: &[f64], d: usize) -> Vec<f64> {
    let scale = (0..d).map(|i| cov[i * d + i].abs()).sum::<f64>() / d as f64;
    let scale = if scale > 0.0 && scale.is_finite() {
        scale
    } else {
        1.0
    };
    for jitter in [0.0, 1e-10, 1e-8, 1e-6, 1e-4, 1e-2] {
        let mut a = cov.to_vec();
        for i in 0..d {
            a[i * d + i] += jitter * scale;
        }
        if let Some(l) = cholesky(&a, d) {
            return l;
        }
    }
    let mut l = vec![0.0; d * d];
    for i in 0..d {
        l[i * d + i] = scale.sqrt();
    }
    l
}

use crate::linalg::dense::cholesky;

/// Outcome of one round of population moves.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct MoveStats {
    /// Accepted proposals / proposals, over all rounds.
    pub acceptance: f64,
    /// Likelihood evaluations (proposals outside the prior's support need none).
    pub n_loglik: u64,
}

/// One random-walk Metropolis step of one particle at exponent `beta`. Returns
/// `(accepted, likelihood evaluated)`.
fn rw_step(
    post: &dyn Posterior,
    p: &mut Particle,
    beta: f64,
    chol: &[f64],
    scale: f64,
    rng: &mut StdRng,
) -> Result<(bool, bool), SamplerError> {
    let d = p.x.len();
    let z: Vec<f64> = (0..d).map(|_| rng.sample(StandardNormal)).collect();
    let u: f64 = rng.random();
    let mut y = p.x.clone();
    for i in 0..d {
        let mut s = 0.0;
        for k in 0..=i {
            s += chol[i * d + k] * z[k];
        }
        y[i] += scale * s;
    }
    let lp = post.log_prior(&y, None);
    if !(lp > f64::NEG_INFINITY) {
        return Ok((false, false));
    }
    // Evaluated even at beta = 0: the cached value weighs the particle at the next exponent.
    let ll = eval_log_lik(post, &y)?;
    let log_ratio = tempered(lp, ll, beta) - tempered(p.log_prior, p.log_lik, beta);
    if u.ln() < log_ratio {
        p.x = y;
        p.log_lik = ll;
        p.log_prior = lp;
        Ok((true, true))
    } else {
        Ok((false, true))
    }
}

/// One round of random-walk Metropolis moves (every particle one step, each with its own RNG
/// stream, in parallel) at exponent `beta` with proposal scale `scale`, then the adaptation of
/// `scale` toward `target_accept` for round `round` (0-based) of the stage. Returns the numbers
/// of accepted proposals and of likelihood evaluations, reduced in particle order.
#[allow(clippy::too_many_arguments)]
pub(crate) fn move_round(
    post: &dyn Posterior,
    particles: &mut [Particle],
    rngs: &mut [StdRng],
    beta: f64,
    chol: &[f64],
    scale: &mut f64,
    target_accept: f64,
    round: usize,
) -> Result<(u64, u64), SamplerError> {
    let n = particles.len();
    let s = *scale;
    let out: Vec<Result<(bool, bool), SamplerError>> = particles
        .par_iter_mut()
        .zip(rngs.par_iter_mut())
        .map(|(p, rng)| rw_step(post, p, beta, chol, s, rng))
        .collect();
    let (mut accepted, mut n_loglik) = (0u64, 0u64);
    for r in out {
        let (a, e) = r?;
        accepted += a as u64;
        n_loglik += e as u64;
    }
    let rate = accepted as f64 / n as f64;
    *scale = (s * ((rate - target_accept) / ((round + 1) as f64).sqrt()).exp()).clamp(1e-4, 1e2);
    Ok((accepted, n_loglik))
}

/// `steps` rounds of random-walk Metropolis moves of every particle at exponent `beta` (see
/// [`move_round`]).
#[allow(clippy::too_many_arguments)]
pub(crate) fn move_population(
    post: &dyn Posterior,
    particles: &mut [Particle],
    rngs: &mut [StdRng],
    beta: f64,
    chol: &[f64],
    scale: &mut f64,
    target_accept: f64,
    steps: usize,
) -> Result<MoveStats, SamplerError> {
    let n = particles.len();
    let mut accepted_total = 0u64;
    let mut n_loglik = 0u64;
    for round in 0..steps {
        let (accepted, evals) = move_round(
            post,
            particles,
            rngs,
            beta,
            chol,
            scale,
            target_accept,
            round,
        )?;
        accepted_total += accepted;
        n_loglik += evals;
    }
    Ok(MoveStats {
        acceptance: accepted_total as f64 / (n * steps.max(1)) as f64,
        n_loglik,
    })
}

/// Systematic resampling: `w.len()` indices in proportion to the normalised weights `w`, from
/// one uniform `u0` in `[0, 1)`.
pub(crate) fn systematic_resample(w: &[f64], u0: f64) -> Vec<usize> {
    let n = w.len();
    let mut idx = Vec::with_capacity(n);
    let mut cum = w[0];
    let mut j = 0;
    for i in 0..n {
        let u = (u0 + i as f64) / n as f64;
        while u > cum && j + 1 < n {
            j += 1;
            cum += w[j];
        }
        idx.push(j);
    }
    idx
}

/// Checks a count setting.
pub(crate) fn nonzero(what: &'static str, n: usize) -> Result<(), SamplerError> {
    if n == 0 {
        Err(SamplerError::Zero { what })
    } else {
        Ok(())
    }
}

/// Checks a population size: non-zero, and at least 2 (a covariance needs two particles);
/// `hint` says how many the estimate wants.
pub(crate) fn particle_count(n: usize, hint: &'static str) -> Result<(), SamplerError> {
    nonzero("particles", n)?;
    if n < 2 {
        return Err(SamplerError::Setting {
            name: "particles",
            value: n.to_string(),
            hint,
        });
    }
    Ok(())
}

/// Checks a real setting against an open interval `(lo, hi)`.
pub(crate) fn in_range(
    name: &'static str,
    v: f64,
    lo: f64,
    hi: f64,
    hint: &'static str,
) -> Result<(), SamplerError> {
    if v > lo && v < hi {
        Ok(())
    } else {
        Err(SamplerError::Setting {
            name,
            value: v.to_string(),
            hint,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn log_mean_exp_matches_direct_form_and_handles_all_minus_inf() {
        let v = [-1.0, 0.5, 2.0];
        let direct = ((-1.0f64).exp() + 0.5f64.exp() + 2.0f64.exp()) / 3.0;
        assert!((log_mean_exp(&v) - direct.ln()).abs() < 1e-14);
        let big = [1000.0, 1000.0];
        assert!((log_mean_exp(&big) - 1000.0).abs() < 1e-12);
        assert_eq!(log_mean_exp(&[f64::NEG_INFINITY; 3]), f64::NEG_INFINITY);
    }

    #[test]
    fn jittered_cholesky_reproduces_the_matrix_and_survives_a_singular_one() {
        let a = [4.0, 2.0, 0.4, 2.0, 3.0, 0.5, 0.4, 0.5, 1.0];
        let l = cholesky_jittered(&a, 3);
        for i in 0..3 {
            for j in 0..3 {
                let s: f64 = (0..3).map(|k| l[i * 3 + k] * l[j * 3 + k]).sum();
                assert!((s - a[i * 3 + j]).abs() < 1e-12, "({i},{j})");
            }
        }
        let singular = [1.0, 1.0, 1.0, 1.0];
        let l = cholesky_jittered(&singular, 2);
        assert!(l.iter().all(|v| v.is_finite()) && l[3] > 0.0);
    }

    #[test]
    fn systematic_resampling_keeps_expected_counts() {
        let w = [0.5, 0.25, 0.0, 0.25];
        let idx = systematic_resample(&w, 0.5);
        let count = |k| idx.iter().filter(|&&i| i == k).count();
        assert_eq!((count(0), count(1), count(2), count(3)), (2, 1, 0, 1));
    }

    #[test]
    fn weighted_covariance_of_two_points() {
        let ps = [
            Particle {
                x: vec![0.0, 0.0],
                log_lik: 0.0,
                log_prior: 0.0,
            },
            Particle {
                x: vec![2.0, 4.0],
                log_lik: 0.0,
                log_prior: 0.0,
            },
        ];
        let (m, c) = weighted_mean_cov(&ps, &[3.0, 1.0], 2);
        assert_eq!(m, vec![0.5, 1.0]);
        // Var of x0: 0.75 * 0.25 + 0.25 * 2.25 = 0.75.
        assert!((c[0] - 0.75).abs() < 1e-15 && (c[1] - 1.5).abs() < 1e-15);
        assert!((c[3] - 3.0).abs() < 1e-15 && c[1] == c[2]);
    }
}
