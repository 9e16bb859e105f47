//! Transitional MCMC (Ching and Chen 2007, J. Eng. Mech. 133(7)) with the improvements of
//! Betz, Papaioannou and Straub 2016 (J. Eng. Mech. 142(5)): posterior draws and the log
//! evidence.
//!
//! A population of `N` particles moves from the prior (`beta_0 = 0`) to the posterior
//! (`beta_m = 1`) through tempered densities `p(x) L(x)^beta_j`. At stage `j`:
//! 1. the plausibility weights `w_i = L(x_i)^(beta_j - beta_{j-1})` of the particles at
//!    `beta_{j-1}`; `beta_j` is found by bisection so that their coefficient of variation
//!    (population standard deviation over mean) equals `target_cov` (1), or is 1 if that is
//!    already below target;
//! 2. the evidence increment `log S_j = log mean_i w_i`; `log Z = sum_j log S_j`;
//! 3. `N` particles are resampled (systematic resampling) in proportion to `w_i`;
//! 4. each is moved by `steps_per_stage` rounds of random-walk Metropolis at `beta_j`, with
//!    proposal covariance `s^2 Sigma_j` (`Sigma_j` the `w`-weighted covariance of the particles at
//!    `beta_{j-1}`), `s` starting at `scale0` (Ching and Chen's 0.2) and adapted after each round
//!    toward `target_accept` (Betz et al.'s adaptive scaling; the several steps per particle are
//!    their burn-in).
//!
//! The particles at `beta = 1` are equal-weight posterior draws (correlated through
//! resampling). The error estimate of `log Z` is the delta-method standard error
//! `sqrt(sum_j CoV_j^2 / N)`, `CoV_j` the weights' coefficient of variation at stage `j`
//! (about `sqrt(stages / N)`), which treats the particles as independent: an underestimate
//! when resampling has left many duplicates. Betz et al. show the estimator of `Z` is unbiased
//! only asymptotically; with a few hundred particles `log Z` is biased low by a few tenths of a
//! nat: use 1000+ particles for evidence to 0.1-0.2 nats.
//!
//! Determinism: stage `j` takes its randomness from `unit_rng(seed, j)`, from which each
//! particle's stream (and the resampling stream) is derived by index, and moves run in
//! parallel with results reduced in particle order: the draws are bit-identical whatever the
//! thread count. With a checkpoint directory the whole state is saved (atomically) after every
//! stage and a rerun resumes after the last saved stage, ending bit-identical to an
//! uninterrupted run.

use std::path::{Path, PathBuf};

use rand::RngExt;
use rayon::prelude::*;

use super::checkpoint::{self, Decoder, Encoder};
use super::sampling::{
    cholesky_jittered, eval_log_lik, in_range, log_mean_exp, move_population, nonzero,
    particle_count, systematic_resample, weighted_mean_cov, Particle, Progress, SamplerError,
};
use super::{unit_rng, Posterior};

/// TMCMC settings.
#[derive(Debug, Clone, PartialEq)]
pub struct TmcmcParams {
    /// Number of particles `N`. Default 2000 (1000+ for evidence to 0.1-0.2 nats).
    pub particles: usize,
    /// Seed of the run. Default 0.
    pub seed: u64,
    /// Target coefficient of variation of the plausibility weights, which sets the
    /// tempering steps. Default 1.0 (Ching and Chen).
    pub target_cov: f64,
    /// Initial proposal scale `s` (covariance `s^2 Sigma`). Default 0.2 (Ching and Chen).
    pub scale0: f64,
    /// Target acceptance rate of the adaptive scaling. Default 0.23.
    pub target_accept: f64,
    /// Metropolis rounds per stage (each particle takes this many steps). Default 10.
    pub steps_per_stage: usize,
    /// Maximum number of tempering stages before giving up. Default 100.
    pub max_stages: usize,
    /// Stop (with [`SamplerError::Stopped`]) once this stage is complete and saved; for time
    /// budgets and for tests of resumption. Not part of the checkpoint key. Default `None`.
    pub stop_after_stages: Option<usize>,
}

impl Default for TmcmcParams {
    fn default() -> Self {
        Self {
            particles: 2000,
            seed: 0,
            target_cov: 1.0,
            scale0: 0.2,
            target_accept: 0.23,
            steps_per_stage: 10,
            max_stages: 100,
            stop_after_stages: None,
        }
    }
}

/// Statistics of one stage (stage 0: the prior draws).
#[derive(Debug, Clone, PartialEq)]
pub struct TmcmcStage {
    /// Stage index.
    pub stage: usize,
    /// Tempering exponent reached.
    pub beta: f64,
    /// `log mean w`, this stage's evidence increment (0 at stage 0).
    pub log_mean_weight: f64,
    /// Coefficient of variation of the weights (0 at stage 0).
    pub weight_cov: f64,
    /// Effective sample size of the weights, `(sum w)^2 / sum w^2` (`N` at stage 0).
    pub ess: f64,
    /// Acceptance rate of the stage's moves (0 at stage 0).
    pub acceptance: f64,
    /// Proposal scale after the stage's adaptation (the next stage starts from it).
    pub scale: f64,
    /// Likelihood evaluations of the stage.
    pub n_loglik: u64,
}

/// The result of [`sample_tmcmc`].
#[derive(Debug, Clone, PartialEq)]
pub struct TmcmcRun {
    /// Coordinate names.
    pub names: Vec<String>,
    /// Final particles (equal-weight posterior draws), unconstrained, one row per particle.
    pub x: Vec<Vec<f64>>,
    /// Their physical values.
    pub constrained: Vec<Vec<f64>>,
    /// Their log likelihoods.
    pub log_lik: Vec<f64>,
    /// Their log priors.
    pub log_prior: Vec<f64>,
    /// Log evidence `sum_j log S_j`.
    pub log_evidence: f64,
    /// Delta-method standard error of `log_evidence` (see the module documentation).
    pub log_evidence_se: f64,
    /// Per-stage statistics, stage 0 first.
    pub stages: Vec<TmcmcStage>,
    /// The stage the run resumed after, if it was loaded from a checkpoint.
    pub resumed_after: Option<usize>,
}

impl TmcmcRun {
    /// Likelihood evaluations over all stages.
    pub fn n_loglik(&self) -> u64 {
        self.stages.iter().map(|s| s.n_loglik).sum()
    }
}

/// The whole state after a stage: what a resumed run needs.
#[derive(Debug, Clone, PartialEq)]
struct State {
    stage: usize,
    beta: f64,
    particles: Vec<Particle>,
    log_evidence: f64,
    var_sum: f64,
    scale: f64,
    stages: Vec<TmcmcStage>,
}

impl State {
    fn encode(&self) -> Encoder {
        let mut e = Encoder::new();
        e.u64(self.stage as u64)
            .f64(self.beta)
            .f64(self.log_evidence)
            .f64(self.var_sum)
            .f64(self.scale)
            .u64(self.particles.len() as u64);
        for p in &self.particles {
            e.f64s(&p.x).f64(p.log_lik).f64(p.log_prior);
        }
        e.u64(self.stages.len() as u64);
        for s in &self.stages {
            e.u64(s.stage as u64)
                .f64(s.beta)
                .f64(s.log_mean_weight)
                .f64(s.weight_cov)
                .f64(s.ess)
                .f64(s.acceptance)
                .f64(s.scale)
                .u64(s.n_loglik);
        }
        e
    }

    fn decode(b: &[u8], n: usize, d: usize) -> Option<Self> {
        let mut r = Decoder::new(b);
        let stage = r.u64()? as usize;
        let beta = r.f64()?;
        let log_evidence = r.f64()?;
        let var_sum = r.f64()?;
        let scale = r.f64()?;
        if r.u64()? as usize != n {
            return None;
        }
        let mut particles = Vec::with_capacity(n);
        for _ in 0..n {
            let x = r.f64s()?;
            if x.len() != d {
                return None;
            }
            particles.push(Particle {
                x,
                log_lik: r.f64()?,
                log_prior: r.f64()?,
            });
        }
        let ns = r.u64()? as usize;
        let mut stages = Vec::new();
        for _ in 0..ns {
            stages.push(TmcmcStage {
                stage: r.u64()? as usize,
                beta: r.f64()?,
                log_mean_weight: r.f64()?,
                weight_cov: r.f64()?,
                ess: r.f64()?,
                acceptance: r.f64()?,
                scale: r.f64()?,
                n_loglik: r.u64()?,
            });
        }
        r.at_end().then_some(State {
            stage,
            beta,
            particles,
            log_evidence,
            var_sum,
            scale,
            stages,
        })
    }
}

fn validate(p: &TmcmcParams) -> Result<(), SamplerError> {
    particle_count(p.particles, "at least 2 (1000+ for evidence)")?;
    nonzero("steps_per_stage", p.steps_per_stage)?;
    nonzero("max_stages", p.max_stages)?;
    in_range(
        "target_cov",
        p.target_cov,
        0.0,
        f64::INFINITY,
        "a positive coefficient of variation, e.g. 1.0",
    )?;
    in_range(
        "scale0",
        p.scale0,
        0.0,
        f64::INFINITY,
        "a positive proposal scale, e.g. 0.2",
    )?;
    in_range(
        "target_accept",
        p.target_accept,
        0.0,
        1.0,
        "an acceptance rate in (0, 1), e.g. 0.23",
    )
}

fn run_key(post: &dyn Posterior, p: &TmcmcParams) -> [u8; 32] {
    let mut e = Encoder::new();
    e.str("rfmlab tmcmc v1")
        .u64(p.particles as u64)
        .u64(p.seed)
        .f64(p.target_cov)
        .f64(p.scale0)
        .f64(p.target_accept)
        .u64(p.steps_per_stage as u64)
        .u64(post.dim() as u64);
    for n in post.names() {
        e.str(&n);
    }
    e.key()
}

fn state_path(dir: &Path, key: &[u8; 32]) -> PathBuf {
    dir.join(format!("tmcmc-{}.ckpt", checkpoint::key_hex(key)))
}

/// Coefficient of variation of `exp(db * ll)` (population standard deviation over mean).
fn weights_cov(ll: &[f64], db: f64) -> f64 {
    let lw: Vec<f64> = ll.iter().map(|l| db * l).collect();
    let m = lw.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let w: Vec<f64> = lw.iter().map(|l| (l - m).exp()).collect();
    let n = w.len() as f64;
    let mean = w.iter().sum::<f64>() / n;
    let var = w.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / n;
    var.sqrt() / mean
}

/// The next exponent: the `beta' in (beta, 1]` where the weights' CoV equals `target`
/// (bisection), or 1 if the CoV at 1 is already below it.
fn next_beta(ll: &[f64], beta: f64, target: f64) -> f64 {
    let span = 1.0 - beta;
    if weights_cov(ll, span) <= target {
        return 1.0;
    }
    let (mut lo, mut hi) = (0.0, span);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if weights_cov(ll, mid) > target {
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

/// The seed of stage `stage`'s streams.
fn stage_seed(seed: u64, stage: usize) -> u64 {
    unit_rng(seed, stage as u64).random()
}

fn initial_state(post: &dyn Posterior, p: &TmcmcParams) -> Result<State, SamplerError> {
    let s0 = stage_seed(p.seed, 0);
    let out: Vec<Result<Particle, SamplerError>> = (0..p.particles)
        .into_par_iter()
        .map(|i| {
            let mut rng = unit_rng(s0, i as u64);
            let x = post.sample_prior(&mut rng);
            let log_prior = post.log_prior(&x, None);
            let log_lik = eval_log_lik(post, &x)?;
            Ok(Particle {
                x,
                log_lik,
                log_prior,
            })
        })
        .collect();
    let particles = out.into_iter().collect::<Result<Vec<_>, _>>()?;
    Ok(State {
        stage: 0,
        beta: 0.0,
        particles,
        log_evidence: 0.0,
        var_sum: 0.0,
        scale: p.scale0,
        stages: vec![TmcmcStage {
            stage: 0,
            beta: 0.0,
            log_mean_weight: 0.0,
            weight_cov: 0.0,
            ess: p.particles as f64,
            acceptance: 0.0,
            scale: p.scale0,
            n_loglik: p.particles as u64,
        }],
    })
}

/// One tempering stage from `st` (see the module documentation).
fn advance(post: &dyn Posterior, p: &TmcmcParams, st: &mut State) -> Result<(), SamplerError> {
    let n = p.particles;
    let d = post.dim();
    let stage = st.stage + 1;
    let ll: Vec<f64> = st.particles.iter().map(|q| q.log_lik).collect();
    if !ll.iter().any(|l| l.is_finite()) {
        return Err(SamplerError::AllWeightsZero {
            particles: n,
            stage,
            beta: st.beta,
        });
    }
    let beta = next_beta(&ll, st.beta, p.target_cov);
    let db = beta - st.beta;
    let lw: Vec<f64> = ll.iter().map(|l| db * l).collect();
    let log_mean_weight = log_mean_exp(&lw);
    let m = lw.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let w: Vec<f64> = lw.iter().map(|l| (l - m).exp()).collect();
    let sw: f64 = w.iter().sum();
    let sw2: f64 = w.iter().map(|v| v * v).sum();
    let ess = sw * sw / sw2;
    let weight_cov = weights_cov(&ll, db);

    let (_, cov) = weighted_mean_cov(&st.particles, &w, d);
    let chol = cholesky_jittered(&cov, d);

    let seed = stage_seed(p.seed, stage);
    let wn: Vec<f64> = w.iter().map(|v| v / sw).collect();
    let u0: f64 = unit_rng(seed, n as u64).random();
    let idx = systematic_resample(&wn, u0);
    let mut particles: Vec<Particle> = idx.iter().map(|&i| st.particles[i].clone()).collect();
    let mut rngs: Vec<_> = (0..n).map(|i| unit_rng(seed, i as u64)).collect();
    let mut scale = st.scale;
    let moves = move_population(
        post,
        &mut particles,
        &mut rngs,
        beta,
        &chol,
        &mut scale,
        p.target_accept,
        p.steps_per_stage,
    )?;

    st.stage = stage;
    st.beta = beta;
    st.particles = particles;
    st.log_evidence += log_mean_weight;
    st.var_sum += weight_cov * weight_cov / n as f64;
    st.scale = scale;
    st.stages.push(TmcmcStage {
        stage,
        beta,
        log_mean_weight,
        weight_cov,
        ess,
        acceptance: moves.acceptance,
        scale,
        n_loglik: moves.n_loglik,
    });
    Ok(())
}

/// Samples `post` by transitional MCMC and estimates its log evidence.
///
/// With `checkpoint = Some(dir)` the state is saved after every stage and a rerun with the same
/// settings resumes after the last saved stage (see the module documentation). A recoverable
/// likelihood failure counts as zero likelihood (the point is rejected); a fatal one stops the
/// run with its message.
pub fn sample_tmcmc(
    post: &dyn Posterior,
    params: &TmcmcParams,
    checkpoint: Option<&Path>,
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<TmcmcRun, SamplerError> {
    validate(params)?;
    let key = run_key(post, params);
    let path = match checkpoint {
        Some(dir) => {
            checkpoint::ensure_dir(dir)?;
            Some(state_path(dir, &key))
        }
        None => None,
    };
    let save = |st: &State| -> Result<(), SamplerError> {
        match &path {
            Some(path) => checkpoint::write_atomic(path, &key, st.encode().bytes()),
            None => Ok(()),
        }
    };

    let loaded = match &path {
        Some(path) => checkpoint::read_matching(path, &key)?
            .and_then(|b| State::decode(&b, params.particles, post.dim())),
        None => None,
    };
    let resumed_after = loaded.as_ref().map(|s| s.stage);
    let mut st = match loaded {
        Some(st) => {
            progress(Progress::TmcmcResumed {
                stage: st.stage,
                beta: st.beta,
            });
            st
        }
        None => {
            let st = initial_state(post, params)?;
            save(&st)?;
            progress(Progress::TmcmcStage {
                stage: 0,
                beta: 0.0,
                acceptance: 0.0,
            });
            if params.stop_after_stages == Some(0) {
                return Err(SamplerError::Stopped { stage: 0 });
            }
            st
        }
    };

    while st.beta < 1.0 {
        if st.stage >= params.max_stages {
            return Err(SamplerError::TooManyStages {
                max_stages: params.max_stages,
                beta: st.beta,
            });
        }
        advance(post, params, &mut st)?;
        save(&st)?;
        let last = st.stages.last().expect("a stage was just added");
        progress(Progress::TmcmcStage {
            stage: st.stage,
            beta: st.beta,
            acceptance: last.acceptance,
        });
        if params.stop_after_stages.is_some_and(|k| st.stage >= k) && st.beta < 1.0 {
            return Err(SamplerError::Stopped { stage: st.stage });
        }
    }

    let names = post.names();
    let constrained = st
        .particles
        .iter()
        .map(|q| post.constrained(&q.x))
        .collect();
    Ok(TmcmcRun {
        names,
        constrained,
        log_lik: st.particles.iter().map(|q| q.log_lik).collect(),
        log_prior: st.particles.iter().map(|q| q.log_prior).collect(),
        x: st.particles.into_iter().map(|q| q.x).collect(),
        log_evidence: st.log_evidence,
        log_evidence_se: st.var_sum.sqrt(),
        stages: st.stages,
        resumed_after,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn next_beta_hits_the_target_coefficient_of_variation() {
        let ll: Vec<f64> = (0..500)
            .map(|i| -0.5 * (i as f64 * 0.01).powi(2) * 50.0)
            .collect();
        let b = next_beta(&ll, 0.0, 1.0);
        assert!(b > 0.0 && b < 1.0);
        assert!(
            (weights_cov(&ll, b) - 1.0).abs() < 1e-9,
            "{}",
            weights_cov(&ll, b)
        );
        // A flat likelihood goes straight to the posterior.
        assert_eq!(next_beta(&[-3.0; 10], 0.4, 1.0), 1.0);
        // Dead particles (-inf) have zero weight and do not break the search.
        let mut ll2 = ll.clone();
        ll2[0] = f64::NEG_INFINITY;
        let b2 = next_beta(&ll2, 0.0, 1.0);
        assert!(b2 > 0.0 && (weights_cov(&ll2, b2) - 1.0).abs() < 1e-6);
    }

    #[test]
    fn state_round_trips_through_its_encoding() {
        let st = State {
            stage: 3,
            beta: 0.25,
            particles: vec![
                Particle {
                    x: vec![0.1, -2.0],
                    log_lik: -1.5,
                    log_prior: f64::NEG_INFINITY,
                };
                3
            ],
            log_evidence: -4.2,
            var_sum: 1e-3,
            scale: 0.7,
            stages: vec![TmcmcStage {
                stage: 1,
                beta: 0.25,
                log_mean_weight: -4.2,
                weight_cov: 1.0,
                ess: 1000.5,
                acceptance: 0.3,
                scale: 0.7,
                n_loglik: 42,
            }],
        };
        let e = st.encode();
        assert_eq!(State::decode(e.bytes(), 3, 2), Some(st.clone()));
        assert_eq!(State::decode(e.bytes(), 4, 2), None);
        assert_eq!(State::decode(&e.bytes()[..20], 3, 2), None);
    }

    #[test]
    fn settings_out_of_range_are_rejected_with_their_name() {
        let p = TmcmcParams {
            particles: 0,
            ..TmcmcParams::default()
        };
        assert_eq!(
            validate(&p).unwrap_err().to_string(),
            "particles must be at least 1 (got 0)"
        );
        let p = TmcmcParams {
            target_accept: 1.5,
            ..TmcmcParams::default()
        };
        assert!(validate(&p)
            .unwrap_err()
            .to_string()
            .contains("target_accept = 1.5"));
    }
}
