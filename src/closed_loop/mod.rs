//! Closing the loop: the residual of the best fit, a score test per
//! candidate effect, refits of the top candidates with the effect free, and a decision by
//! evidence; repeated on the new residual until nothing passes.
//!
//! 1. **Residuals** at the MAP: `z_o = (X_o - E[H1]_o) / sqrt(v_o)` under the noise model.
//!    `q = sum |z_o|^2` is chi-square with `2 N` degrees of freedom when the model is right;
//!    the normalised chi-square is `q / (2 N - k)` (k fitted parameters). Per channel: the
//!    mean data/model ratio (a constant ratio is a gain), the slope of the phase of that ratio
//!    against frequency (a delay), and a Wald-Wolfowitz runs test on the signs of Re z along
//!    frequency (a whiteness check: systematic residuals come in long runs).
//! 2. **Score (Lagrange-multiplier) test** of each candidate effect at zero (Rao 1948; the
//!    efficient score with the law's parameters as nuisance, e.g. Boos and Stefanski 2013 ch. 3):
//!    with `J` the Jacobian of `E[H1]` at the MAP and `r = X - E[H1]`,
//!    `S_i = sum Re(conj(r_o) J_oi) / v_o`, `I_ij = sum Re(conj(J_oi) J_oj) / v_o`,
//!    `S* = S_e - I_ep I_pp^-1 S_p`, `I* = I_ee - I_ep I_pp^-1 I_pe`, `T = S*^2 / I*`
//!    (chi-square 1; for a mass, one-sided: `p = 1 - Phi(S* / sqrt(I*))`, Self and Liang 1987).
//!    `S* / I*` is the one-step estimate of the effect's size.
//! 3. **Refit** the `top` candidates by `T` with the effect free ([`crate::inference::map::find_map`],
//!    its default prior [`crate::forward::Effect::default_prior`]; a Levenberg-Marquardt search
//!    on the likelihood's Gauss-Newton curvature, [`crate::inference::map::SearchMethod`], from
//!    the profiled start of [`start`]) and compare Laplace log evidences. The best is accepted when its gain is at least `threshold_nats` (default 5 nats,
//!    "very strong" on the Kass and Raftery 1995 scale after the Bonferroni-like cost of trying
//!    several candidates) and its size is plausible: at least `min_z` posterior sds from zero and
//!    inside its prior range (not at an edge).
//!    When none passes and the residual is far from noise (normalised chi-square above
//!    `profile_rank_above`), the score at zero is not trusted to rank: an effect that acts
//!    non-linearly (a shaker's stinger resonance) can have its score point the wrong way. The
//!    candidates not yet refitted are then profiled over their priors and the `top` by profile
//!    gain (half the weighted residual sum of squares' decrease, a likelihood ratio over the
//!    prior) are refitted and judged the same way.
//!
//! 4. **Alternative laws** ([`alternative`], [`run_closed_loop_with_laws`]): a law not nested in
//!    the current one has no score test; each round the whole model is refitted with it in
//!    place of the current law and it competes with the round's effects by Laplace evidence.
//!
//! A round is a sequence of named steps run by one driver (`driver.rs`): score, rank, refit
//! (each refit judged by its gate), the alternative laws, accept; its end is a
//! [`RoundOutcome`].

pub mod alternative;
pub mod conclude;
pub mod confounding;
mod driver;
pub mod null;
pub mod signatures;
pub mod verdict;

pub use driver::RoundOutcome;

use crate::common::C64;
use crate::forward::{Effect, EffectTerm, Effects, ForwardError};
use crate::inference::likelihood::{FrfLikelihood, FrfPosterior};

pub mod start;
use crate::inference::map::{MapError, MapParams, MapResult};
use crate::inference::prior::Prior;
use crate::inference::refine::{relinearise_model_to_map, RefineError};
use crate::linalg::dense::{chol_solve, cholesky};
use crate::material::ConstitutiveModel;
use libm::erfc;

/// How far (nats) above the `-log p` it must reach a refit may stay before its search gives up
/// (after [`crate::inference::lm::GIVE_UP_RATIO`] Newton decrements): an alternative law against
/// the current fit ([`alternative::refit_law`]), the final model without an accepted effect
/// against the threshold ([`conclude`]), an effect's refit against a passing refit of the same
/// round. A margin for the two models' priors, coordinates and noise terms, which differ by
/// tens of nats, far below the hundreds of thousands a model that cannot take the data's shape
/// stays above.
pub const GIVE_UP_MARGIN_NATS: f64 = 1000.0;

/// The margin of a refit racing a passing refit of the same kind of effect (see
/// [`GIVE_UP_MARGIN_NATS`]): the same prior, so only the Occam factors differ.
pub const SAME_KIND_MARGIN_NATS: f64 = 50.0;

/// Settings of the loop.
#[derive(Clone, Debug, PartialEq)]
pub struct ClosedLoopParams {
    /// Laplace log-evidence gain (nats) a candidate needs. Default 5.
    pub threshold_nats: f64,
    /// Candidates refitted per round. Default 3.
    pub top: usize,
    /// Rounds at most. Default 4.
    pub max_rounds: usize,
    /// An accepted size is at least this many posterior sds from zero. Default 3.
    pub min_z: f64,
    /// The MAP searches: the caller's start (refits: the current MAP with the score test's
    /// estimate) plus `n_starts` space-filling starts (default 6).
    pub map: MapParams,
    /// Refits start only from the current MAP with the score test's one-step estimate (no
    /// space-filling starts): the effect is small, so the refit's mode is next to the current
    /// one. Default true; false runs every refit as a full multistart search (the old path,
    /// kept for the bench `benches/closed_loop.rs`).
    pub warm_refits: bool,
    /// Only candidates whose score test has a p-value below this are refitted. Default 0.01
    /// (1: the top candidates whatever their p).
    pub p_threshold: f64,
    /// When no score-ranked refit passes and the current residual's normalised chi-square is
    /// above this, the score test (a linearisation at zero effect) is not trusted to rank:
    /// every candidate not yet refitted is profiled over its prior ([`start::profile_start`])
    /// and the `top` with the largest profile gain are refitted. Default 1.5 (the residual is
    /// far from noise: the acceptance limit is 1.2 and leakage-limited clean data read 0.6-0.7);
    /// null data never reach it. `f64::INFINITY` turns it off.
    pub profile_rank_above: f64,
    /// Where the score is trusted (the residual's normalised chi-square at most
    /// `profile_rank_above`), a candidate whose score-predicted evidence gain
    /// ([`predicted_gain`]) is below `threshold_nats - predicted_gain_margin` is not refitted:
    /// its refit could not pass (the compliant base's round-2 Maxwell branches, predicted
    /// below 0 nats, crept through 150 Gauss-Newton iterations each to gains of -5 nats).
    /// Default 3 nats; `f64::INFINITY` refits every candidate the p-value admits.
    pub predicted_gain_margin: f64,
    /// Where the loop reports each step (the CLI shows it on its spinner). Default: nowhere.
    pub progress: Progress,
    /// The loop's start `x0` is a fit of the starting model already (the channels'
    /// correlation estimate's MAP, or another pass's fit on another engine of the same
    /// structure): the starting MAP searches from it alone, without space-filling starts.
    /// Default false.
    pub start_is_fit: bool,
}

/// A level's fit of the starting model, from an earlier pass of the loop: physical values in
/// the order of `names` (the law's, any free declared effects', then the noise's).
#[derive(Clone, Debug, PartialEq)]
pub struct StartingFit {
    pub level: String,
    pub names: Vec<String>,
    pub values: Vec<f64>,
}

/// A sink for one-line messages on the loop's steps (a long loop is minutes of score tests
/// and refits). It does not change any result, so every two compare equal.
#[derive(Clone, Default)]
pub struct Progress(Option<std::sync::Arc<ProgressSink>>);

/// The function behind [`Progress`].
pub type ProgressSink = dyn Fn(&str) + Send + Sync;

impl Progress {
    pub fn new(f: impl Fn(&str) + Send + Sync + 'static) -> Self {
        Progress(Some(std::sync::Arc::new(f)))
    }

    /// Report `msg` (nothing when no sink was given).
    pub fn say(&self, msg: &str) {
        if let Some(f) = &self.0 {
            f(msg);
        }
    }
}

impl std::fmt::Debug for Progress {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(if self.0.is_some() {
            "Progress(sink)"
        } else {
            "Progress(none)"
        })
    }
}

impl PartialEq for Progress {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

impl Default for ClosedLoopParams {
    fn default() -> Self {
        ClosedLoopParams {
            threshold_nats: 5.0,
            top: 3,
            max_rounds: 4,
            min_z: 3.0,
            map: MapParams {
                n_starts: 6,
                ..MapParams::default()
            },
            warm_refits: true,
            p_threshold: 0.01,
            profile_rank_above: 1.5,
            predicted_gain_margin: 3.0,
            progress: Progress::default(),
            start_is_fit: false,
        }
    }
}

/// Errors of the loop.
#[derive(Debug, Clone, thiserror::Error)]
pub enum ClosedLoopError {
    #[error("forward model: {0}")]
    Forward(#[from] ForwardError),
    #[error("MAP search: {0}")]
    Map(#[from] MapError),
    #[error("{0}")]
    Setup(String),
}

impl From<RefineError> for ClosedLoopError {
    fn from(e: RefineError) -> Self {
        match e {
            RefineError::Search(m) => ClosedLoopError::Map(m),
            RefineError::Measurement(f) => ClosedLoopError::Forward(f),
            other => ClosedLoopError::Setup(other.to_string()),
        }
    }
}

/// Residual statistics of one channel.
#[derive(Clone, Debug, PartialEq)]
pub struct ChannelResidual {
    /// Normalised chi-square of the channel, `sum |z|^2 / (2 n)`.
    pub chi2_normalised: f64,
    /// `||X - E[H1]|| / ||X||` over the channel.
    pub relative_norm: f64,
    /// Weighted mean of `X / E[H1]` (a constant ratio off 1 is a gain).
    pub ratio: C64,
    /// Slope (s) of the phase of `X / E[H1]` against `omega` (a delay gives `-tau`).
    pub phase_slope_s: f64,
    /// Runs test on the signs of Re z along frequency: standardised number of runs (very
    /// negative: long runs, a systematic residual).
    pub runs_z: f64,
}

/// Residual analysis at a fit.
#[derive(Clone, Debug, PartialEq)]
pub struct Residuals {
    /// Standardised complex residuals `[line * n_out + k]`.
    pub z: Vec<C64>,
    pub chi2: f64,
    pub dof: f64,
    /// `chi2 / dof`.
    pub chi2_normalised: f64,
    /// Upper-tail p-value of chi2 (Wilson-Hilferty normal approximation).
    pub p_value: f64,
    pub relative_norm: f64,
    pub channels: Vec<ChannelResidual>,
    /// FRAC per channel (data against prediction).
    pub frac: Vec<f64>,
    /// Per resonance: frequency and damping change; the ratio below the first resonance.
    pub signatures: signatures::Signatures,
}

/// One candidate in one round.
#[derive(Clone, Debug, PartialEq)]
pub struct Candidate {
    pub round: usize,
    pub effect: Effect,
    /// Score statistic `T`.
    pub score: f64,
    pub p_value: f64,
    /// One-step size estimate `S* / I*` and its sd `1 / sqrt(I*)`.
    pub one_step: f64,
    pub one_step_sd: f64,
    pub rank: usize,
    /// The evidence gain the score test predicts (nats, [`predicted_gain`]); NaN for a prior
    /// that is not uniform.
    pub predicted_gain: f64,
    /// Half the decrease of the weighted residual sum of squares at the candidate's profiled
    /// start (nats, a likelihood-ratio statistic over the prior), when the round ranked by the
    /// profile (`ClosedLoopParams::profile_rank_above`).
    pub profile_gain: Option<f64>,
    /// Filled when refitted.
    pub refit: Option<Refit>,
    /// How much the model's parameters absorb the effect ([`confounding`]).
    pub confounding: confounding::Confounding,
}

/// A refit with one candidate free.
#[derive(Clone, Debug, PartialEq)]
pub struct Refit {
    pub log_evidence: f64,
    /// Laplace log-evidence gain over the current model (nats); when either Laplace Hessian is
    /// not positive definite, the log-posterior gain less (1/2) ln(2 N) (BIC).
    pub evidence_gain: f64,
    pub size: f64,
    pub sd: f64,
    pub accepted: bool,
    /// Why not accepted (or accepted).
    pub verdict: RefitVerdict,
}

/// What a refit's tests concluded ([`Refit::verdict`]): the loop decides on it, the report and
/// the candidates table write it in words (`Display`).
#[derive(Clone, Debug, PartialEq)]
pub enum RefitVerdict {
    /// Every test passed: a candidate for the round's acceptance.
    Passes,
    /// Accepted: the round's best passing refit (or alternative law).
    Accepted,
    /// Its search gave up `short_nats` short of the round's passing refit of `name`.
    CannotBeat { name: String, short_nats: f64 },
    /// An alternative law's search gave up `short_nats` short of the current fit (its evidence
    /// gain `gain` where it stopped).
    CannotReach { short_nats: f64, gain: f64 },
    /// The Laplace Hessian is not positive definite (`law_candidate`: after the warm refit of a
    /// law candidate, which has no multistart search).
    NotPositiveDefinite { law_candidate: bool },
    /// The evidence gain (nats) is below the threshold.
    BelowThreshold { gain: f64, threshold: f64 },
    /// The size is within `min_z` sds of the effect's null value.
    NearZero { size: f64, min_z: f64 },
    /// The size is at the edge of its prior `[lo, hi]`.
    AtPriorEdge { size: f64, lo: f64, hi: f64 },
    /// A parameter of the alternative law `law` is at its prior's edge.
    LawAtPriorEdge { law: String },
    /// The alternative law `law` has no admissible start (it does not fit the current E*(w)).
    NoAdmissibleStart { law: String },
    /// The refit failed (the error in words).
    Failed(String),
    /// Not refitted, and why.
    NotRefitted(String),
    /// Accepted, then removed by the verdict (dropped, or not needed for a residual within the
    /// noise), and why.
    Removed(String),
}

impl RefitVerdict {
    /// Whether every test passed ([`RefitVerdict::Passes`]).
    pub fn passes(&self) -> bool {
        matches!(self, RefitVerdict::Passes)
    }
}

impl std::fmt::Display for RefitVerdict {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            RefitVerdict::Passes => f.write_str("passes"),
            RefitVerdict::Accepted => f.write_str("accepted"),
            RefitVerdict::CannotBeat { name, short_nats } => write!(
                f,
                "cannot beat {name}'s refit: its search gave up {short_nats:.0} nats short"
            ),
            RefitVerdict::CannotReach { short_nats, gain } => write!(
                f,
                "cannot reach the current fit: its search gave up {short_nats:.0} nats short (evidence gain {gain:.0} nats where it stopped)"
            ),
            RefitVerdict::NotPositiveDefinite { law_candidate: true } => f.write_str(
                "Laplace Hessian not positive definite after the warm refit (law candidate: no multistart search)",
            ),
            RefitVerdict::NotPositiveDefinite { law_candidate: false } => {
                f.write_str("Laplace Hessian not positive definite")
            }
            RefitVerdict::BelowThreshold { gain, threshold } => {
                write!(f, "evidence gain {gain:.2} nats < {threshold}")
            }
            RefitVerdict::NearZero { size, min_z } => {
                write!(f, "size {size:.4e} within {min_z} sd of zero")
            }
            RefitVerdict::AtPriorEdge { size, lo, hi } => {
                write!(f, "size {size:.4e} at the edge of its prior [{lo}, {hi}]")
            }
            RefitVerdict::LawAtPriorEdge { law } => {
                write!(f, "a parameter of {law} at its prior's edge")
            }
            RefitVerdict::NoAdmissibleStart { law } => write!(
                f,
                "no admissible start: {law} does not fit the current E*(w)"
            ),
            RefitVerdict::Failed(e) => write!(f, "refit failed: {e}"),
            RefitVerdict::NotRefitted(why) => write!(f, "not refitted: {why}"),
            RefitVerdict::Removed(why) => f.write_str(why),
        }
    }
}

/// A fit of the current model: physical parameters (law, free effects, noise) and names.
#[derive(Clone, Debug, PartialEq)]
pub struct Fit {
    /// Name of the constitutive law of the fit (changes when an alternative law is accepted).
    pub law: String,
    /// Number of the law's parameters (the first of `names`).
    pub n_law: usize,
    pub names: Vec<String>,
    pub values: Vec<f64>,
    pub sd: Vec<f64>,
    pub log_evidence: f64,
    /// Log likelihood plus log prior at the MAP.
    pub log_posterior: f64,
    /// Whether the Laplace Hessian was positive definite.
    pub positive_definite: bool,
    /// Laplace covariance of the physical values (row-major, the order of `names`).
    pub cov: Vec<f64>,
    pub residuals: Residuals,
}

/// An alternative-law candidate in one round ([`alternative`]): the whole model refitted with
/// the law swapped. Not nested, so no score test; decided by the Laplace evidence gain.
#[derive(Clone, Debug, PartialEq)]
pub struct LawCandidate {
    pub round: usize,
    /// The alternative law's name (e.g. "fractional_zener").
    pub law: String,
    /// Its start: the fit to the current MAP's `E*(w)`, and that fit's RMS relative error.
    pub start: Vec<f64>,
    pub start_rel_rms: f64,
    /// The refit's law parameters and their sds (empty when the refit failed).
    pub params: Vec<f64>,
    pub sd: Vec<f64>,
    /// Evidence, gain and verdict (`size`, `sd` NaN: a law has no size).
    pub refit: Refit,
    /// The refit's search in words (iterations, evaluations, why it stopped); empty when
    /// there was none.
    pub search: String,
}

impl LawCandidate {
    /// A row for `law` in `round` without a refit (yet): NaN evidence, no parameters.
    pub fn not_refitted(round: usize, law: &str, verdict: RefitVerdict) -> Self {
        LawCandidate {
            round,
            law: law.to_string(),
            start: Vec::new(),
            start_rel_rms: f64::NAN,
            params: Vec::new(),
            sd: Vec::new(),
            refit: Refit {
                log_evidence: f64::NAN,
                evidence_gain: f64::NAN,
                size: f64::NAN,
                sd: f64::NAN,
                accepted: false,
                verdict,
            },
            search: String::new(),
        }
    }
}

/// What the loop found.
#[derive(Clone, Debug, PartialEq)]
pub struct ClosedLoopResult {
    pub before: Fit,
    pub after: Fit,
    /// Accepted effects in order, with size and sd.
    pub accepted: Vec<(Effect, f64, f64)>,
    pub candidates: Vec<Candidate>,
    /// Alternative-law candidates, every round.
    pub law_candidates: Vec<LawCandidate>,
    /// "no missing effect found" or the accepted effects in words, then the confounded
    /// candidates' sentences.
    pub conclusion: String,
    /// Candidates of the last round that the model's parameters absorb (R^2 >= 0.99, law
    /// candidates aside), not accepted: a sentence each ([`confounding::Confounding::sentence`]).
    pub confounded: Vec<String>,
    /// Wall time (s) of the loop's steps in order: the starting MAP, then per round its score
    /// tests, its refits (profiles included) and its alternative laws (`round 1: refits`);
    /// the verdict's steps are appended by its caller. The run's manifest lists them.
    pub timings: Vec<(String, f64)>,
}

/// Residual analysis of `post` at physical parameters `phys` (law + free effects, then noise).
pub fn residuals(post: &FrfPosterior<'_>, phys: &[f64]) -> Result<Residuals, ForwardError> {
    let lik = &post.likelihood;
    let np = lik.forward.n_params();
    let pred = lik.forward.predict(&phys[..np], false)?;
    let v = lik.variances(&phys[np..]);
    let x = &lik.data.values;
    let n = lik.data.n_out;
    let nl = lik.data.freq_hz.len();
    let z: Vec<C64> = x
        .iter()
        .zip(&pred.values)
        .zip(&v)
        .map(|((x, h), v)| (x - h) / v.sqrt())
        .collect();
    let chi2: f64 = z.iter().map(|z| z.norm_sqr()).sum();
    let dof = (2 * x.len()) as f64 - post.names.len() as f64;
    // Wilson-Hilferty: (chi2/dof)^(1/3) ~ N(1 - 2/(9 dof), 2/(9 dof)).
    let a = 2.0 / (9.0 * dof);
    let zwh = ((chi2 / dof).cbrt() - (1.0 - a)) / a.sqrt();
    let p_value = 0.5 * erfc(zwh / std::f64::consts::SQRT_2);
    let norm = |idx: &mut dyn Iterator<Item = usize>| -> (f64, f64) {
        idx.fold((0.0, 0.0), |(a, b), o| {
            (a + (x[o] - pred.values[o]).norm_sqr(), b + x[o].norm_sqr())
        })
    };
    let (num, den) = norm(&mut (0..x.len()));
    let omega = &lik.forward.obs.omega_rad_s;
    let mut channels = Vec::with_capacity(n);
    let mut frac = Vec::with_capacity(n);
    for k in 0..n {
        let idx: Vec<usize> = (0..nl).map(|l| l * n + k).collect();
        let (cn, cd) = norm(&mut idx.iter().copied());
        let chi2_k: f64 = idx.iter().map(|&o| z[o].norm_sqr()).sum::<f64>() / (2 * nl) as f64;
        // Ratio X / H weighted by |H|^2 / v (least squares of X = c H).
        let (mut sxh, mut shh) = (C64::new(0.0, 0.0), 0.0);
        for &o in &idx {
            let h = pred.values[o];
            sxh += x[o] * h.conj() / v[o];
            shh += h.norm_sqr() / v[o];
        }
        let ratio = sxh / shh;
        // Phase slope of X/H against omega: weighted least squares of arg(X/H).
        let (mut sw, mut swx, mut swy, mut swxx, mut swxy) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for (l, &o) in idx.iter().enumerate() {
            let wgt = pred.values[o].norm_sqr() / v[o];
            let ph = (x[o] / pred.values[o]).arg();
            let w = omega[l];
            sw += wgt;
            swx += wgt * w;
            swy += wgt * ph;
            swxx += wgt * w * w;
            swxy += wgt * w * ph;
        }
        let phase_slope_s = (sw * swxy - swx * swy) / (sw * swxx - swx * swx);
        // Runs of the signs of Re z.
        let signs: Vec<bool> = idx.iter().map(|&o| z[o].re >= 0.0).collect();
        let n1 = signs.iter().filter(|s| **s).count() as f64;
        let n2 = signs.len() as f64 - n1;
        let runs = 1.0 + signs.windows(2).filter(|w| w[0] != w[1]).count() as f64;
        let nn = n1 + n2;
        let mu = 2.0 * n1 * n2 / nn + 1.0;
        let var = 2.0 * n1 * n2 * (2.0 * n1 * n2 - nn) / (nn * nn * (nn - 1.0));
        let runs_z = if var > 0.0 {
            (runs - mu) / var.sqrt()
        } else {
            0.0
        };
        channels.push(ChannelResidual {
            chi2_normalised: chi2_k,
            relative_norm: (cn / cd).sqrt(),
            ratio,
            phase_slope_s,
            runs_z,
        });
        let xs: Vec<C64> = idx.iter().map(|&o| x[o]).collect();
        let hs: Vec<C64> = idx.iter().map(|&o| pred.values[o]).collect();
        frac.push(crate::correlation::frac(&xs, &hs));
    }
    let signatures = signatures::signatures(&lik.data.freq_hz, x, &pred.values, &v, n);
    Ok(Residuals {
        signatures,
        z,
        chi2,
        dof,
        chi2_normalised: chi2 / dof,
        p_value,
        relative_norm: (num / den).sqrt(),
        channels,
        frac,
    })
}

/// The score test of `candidate` at zero, the law's parameters (and any free effects) as
/// nuisance, at physical parameters `phys` of `post` (whose forward model holds the current
/// effects). Returns (T, p, one-step size, its sd).
pub fn score_test(
    post: &FrfPosterior<'_>,
    phys: &[f64],
    candidate: &Effect,
) -> Result<(f64, f64, f64, f64), ForwardError> {
    score_test_step(post, phys, candidate).map(|(t, p, e, sd, _, _)| (t, p, e, sd))
}

/// What [`score_test_step`] returns: (T, p, one-step size, its sd, the refit's start of the
/// model parameters, the confounding).
pub type ScoreStep = (f64, f64, f64, f64, Vec<f64>, confounding::Confounding);

/// [`score_test`] and the Gauss-Newton step of the model's parameters that goes with the
/// one-step size: `dp = I_pp^-1 (S_p - I_pe de)` (halved until admissible), the refit's start
/// (the law's parameters absorbed the effect; starting them where the effect's size would put
/// them keeps the refit in the right basin). Returns (T, p, size, sd, model parameters,
/// confounding).
pub fn score_test_step(
    post: &FrfPosterior<'_>,
    phys: &[f64],
    candidate: &Effect,
) -> Result<ScoreStep, ForwardError> {
    let lik = &post.likelihood;
    let np = lik.forward.n_params();
    let fm = candidate_model(lik, candidate)?;
    let mut p: Vec<f64> = phys[..np].to_vec();
    p.push(candidate.null_value());
    let pred = fm.predict(&p, true)?;
    let v = lik.variances(&phys[np..]);
    let d = p.len();
    // Nuisance columns scaled by |p| (log parameters) for conditioning; T is invariant.
    let scale: Vec<f64> = (0..d)
        .map(|i| {
            if i < d - 1 && p[i] != 0.0 {
                p[i].abs()
            } else {
                1.0
            }
        })
        .collect();
    let cols: Vec<usize> = (0..d).collect();
    let (s, fi) = normal_equations(&lik.data.values, &pred, &v, &cols, &scale);
    let m = d - 1;
    let ipp: Vec<f64> = (0..m * m).map(|k| fi[(k / m) * d + k % m]).collect();
    let iep: Vec<f64> = (0..m).map(|j| fi[m * d + j]).collect();
    let l = cholesky(&ipp, m)
        .ok_or_else(|| ForwardError::Setup("the law's Fisher information is singular".into()))?;
    let a = chol_solve(&l, m, &iep);
    let s_eff = s[m] - a.iter().zip(&s[..m]).map(|(a, b)| a * b).sum::<f64>();
    let i_eff = fi[m * d + m] - a.iter().zip(&iep).map(|(a, b)| a * b).sum::<f64>();
    let names = fm.param_names();
    let conf = confounding::Confounding {
        r2: if fi[m * d + m] > 0.0 {
            (1.0 - i_eff / fi[m * d + m]).clamp(0.0, 1.0)
        } else {
            0.0
        },
        absorbed: names[..m].iter().cloned().zip(a.iter().copied()).collect(),
    };
    if !(i_eff > 0.0) {
        return Ok((0.0, 1.0, 0.0, f64::INFINITY, phys[..np].to_vec(), conf));
    }
    let zs = s_eff / i_eff.sqrt();
    // One-sided (a mass): the statistic is max(0, z)^2 (Self and Liang 1987), so a score
    // pointing to a negative size ranks last (not for a resonator, whose column at zero does
    // not give the sign of a finite one's action: [`Effect::score_one_sided`]).
    let one_sided = candidate.score_one_sided();
    let t = if one_sided {
        zs.max(0.0).powi(2)
    } else {
        zs * zs
    };
    let p_value = if one_sided {
        0.5 * erfc(zs / std::f64::consts::SQRT_2)
    } else {
        erfc(zs.abs() / std::f64::consts::SQRT_2)
    };
    let de = s_eff / i_eff;
    let rhs: Vec<f64> = (0..m).map(|j| s[j] - iep[j] * de).collect();
    let dp = chol_solve(&l, m, &rhs);
    let mut start = phys[..np].to_vec();
    let mut f = 1.0;
    for _ in 0..12 {
        let trial: Vec<f64> = (0..np).map(|i| p[i] + f * dp[i] * scale[i]).collect();
        let mut full = trial.clone();
        full.push(candidate.null_value());
        if fm.check(&full).is_ok() {
            start = trial;
            break;
        }
        f *= 0.5;
    }
    Ok((t, p_value, de, 1.0 / i_eff.sqrt(), start, conf))
}

/// The score `S_i = sum Re(conj(r_o) J_oi) / v_o` and the information
/// `I_ij = sum Re(conj(J_oi) J_oj) / v_o` (row-major, symmetric) of the residuals
/// `r = data - prediction` with independent observations of variance `v`, for the Jacobian
/// columns `cols`, each scaled by its `scale` (conditioning).
pub(crate) fn normal_equations(
    data: &[C64],
    pred: &crate::forward::Prediction,
    v: &[f64],
    cols: &[usize],
    scale: &[f64],
) -> (Vec<f64>, Vec<f64>) {
    let d = cols.len();
    let mut s = vec![0.0; d];
    let mut fi = vec![0.0; d * d];
    for (o, ((x, h), v)) in data.iter().zip(&pred.values).zip(v).enumerate() {
        let r = x - h;
        for i in 0..d {
            let ji = pred.jac[cols[i]][o] * scale[i];
            s[i] += (r.conj() * ji).re / v;
            for j in 0..=i {
                let jj = pred.jac[cols[j]][o] * scale[j];
                fi[i * d + j] += (ji.conj() * jj).re / v;
            }
        }
    }
    for i in 0..d {
        for j in 0..i {
            fi[j * d + i] = fi[i * d + j];
        }
    }
    (s, fi)
}

/// An accepted effect as the conclusion, the verdict and the report name it:
/// `name = size +- sd unit`.
pub(crate) fn accepted_entry(e: &Effect, size: f64, sd: f64) -> String {
    format!("{} = {size:.4e} +- {sd:.1e} {}", e.name(), e.unit())
}

/// The weighted residual sum of squares `sum |data_o - values_o|^2 / v_o`.
pub(crate) fn weighted_rss(data: &[C64], values: &[C64], v: &[f64]) -> f64 {
    data.iter()
        .zip(values)
        .zip(v)
        .map(|((x, h), v)| (x - h).norm_sqr() / v)
        .sum()
}

/// Whether the loop's searches on `forward` with `effects` run on the measurement bias
/// linearised at their start and re-linearised at their MAP
/// ([`crate::inference::refine::relinearise_model_to_map`]) instead of the measurement
/// model's fine grid: with a term of the term ROM among the effects, each evaluation is a dense
/// solve of the reduced system per evaluation line, and the fine grid has several lines per
/// measured line. The pencil's evaluations are cheap enough on the fine grid.
pub(crate) fn uses_linearised_bias(
    forward: &crate::forward::ForwardModel<'_>,
    effects: &Effects,
) -> bool {
    forward.obs.measurement.is_some() && effects.has_term_matrices()
}

/// `search` (a MAP search of `post`) on the measurement bias linearised at `p0` (physical
/// values, the forward model's parameters first) and re-linearised at the MAP it ends at, until
/// that stops moving, when [`uses_linearised_bias`] holds for `post`'s model: its result is
/// then the exact model's MAP. Otherwise `search` on the exact kernel.
pub(crate) fn search_on_linearised_bias(
    post: &mut FrfPosterior<'_>,
    p0: &[f64],
    params: &MapParams,
    search: impl FnOnce(&FrfPosterior<'_>) -> Result<MapResult, MapError>,
) -> Result<MapResult, RefineError> {
    let forward = &post.likelihood.forward;
    if !uses_linearised_bias(forward, &forward.effects) {
        return Ok(search(post)?);
    }
    let np = forward.n_params();
    post.likelihood
        .forward
        .linearise_model_measurement(&p0[..np])?;
    let mut r = search(post)?;
    relinearise_model_to_map(post, &mut r, params)?;
    Ok(r)
}

/// A forward model sharing `lik`'s observation with its effects and `candidate` free (last).
pub(crate) fn candidate_model<'a>(
    lik: &FrfLikelihood<'a>,
    candidate: &Effect,
) -> Result<crate::forward::ForwardModel<'a>, ForwardError> {
    let mut fm_effects = lik.forward.effects.clone();
    fm_effects.terms.push(EffectTerm {
        effect: candidate.clone(),
        value: candidate.null_value(),
        free: true,
    });
    let mut fm = crate::forward::ForwardModel {
        obs: crate::forward::Observation::new(
            lik.forward.obs.engine,
            &lik.forward.obs.omega_rad_s,
            lik.forward.obs.input,
            &lik.forward.obs.outputs,
            lik.forward.obs.measurement.clone(),
        )?,
        law: lik.forward.law,
        linear_bias: None,
        effects: Effects::default(),
    };
    fm.set_effects(fm_effects)?;
    Ok(fm)
}

/// Put `effects` into `post`: the starting model's parameters (law and declared free
/// effects, the first `base_priors.len()`) keep their priors `base_priors`, free terms added
/// by the loop get their default priors, the noise keeps `noise_priors`.
fn install(
    post: &mut FrfPosterior<'_>,
    base_priors: &[Prior],
    noise_priors: &[Prior],
    effects: Effects,
) -> Result<(), ForwardError> {
    let mut priors = base_priors.to_vec();
    let n_law = post.likelihood.forward.law.n_params();
    priors.extend(
        effects
            .terms
            .iter()
            .filter(|t| t.free)
            .skip(base_priors.len() - n_law)
            .map(|t| t.effect.default_prior()),
    );
    priors.extend(noise_priors.iter().cloned());
    post.likelihood.forward.set_effects(effects)?;
    let mut names = post.likelihood.forward.param_names();
    names.extend(post.likelihood.noise_names().iter().cloned());
    post.priors = priors;
    post.names = names;
    Ok(())
}

pub(crate) fn fit_of(post: &FrfPosterior<'_>, r: &MapResult) -> Result<Fit, ForwardError> {
    Ok(Fit {
        law: post.likelihood.forward.law.name().to_string(),
        n_law: post.likelihood.forward.law.n_params(),
        names: post.names.clone(),
        values: r.map_physical.clone(),
        sd: r.laplace.sd_physical(),
        log_evidence: r.laplace.log_evidence,
        log_posterior: r.laplace.log_posterior(),
        positive_definite: r.laplace.positive_definite,
        cov: r.laplace.cov_physical.clone(),
        residuals: residuals(post, &r.map_physical)?,
    })
}

/// Run the loop on `post` (its forward model may hold declared effects, fixed or free) from
/// the unconstrained start `x0`, trying `candidates` (those already in the model are
/// skipped). On return `post` holds the final model.
pub fn run_closed_loop(
    post: &mut FrfPosterior<'_>,
    x0: &[f64],
    candidates: &[Effect],
    params: &ClosedLoopParams,
) -> Result<ClosedLoopResult, ClosedLoopError> {
    run_closed_loop_with_laws(post, x0, candidates, &[], params)
}

/// [`run_closed_loop`] with alternative laws as candidates too ([`alternative`]): in each
/// round, besides the effects, the whole model refitted with each law in `laws` (other than
/// the current one) in place of the current law, accepted by the same evidence threshold when
/// its Laplace Hessian is positive definite and no law parameter is at its prior's edge. The
/// best passing candidate of a round (effect or law) by Laplace log evidence is accepted.
pub fn run_closed_loop_with_laws<'a>(
    post: &mut FrfPosterior<'a>,
    x0: &[f64],
    candidates: &[Effect],
    laws: &[&'a dyn ConstitutiveModel],
    params: &ClosedLoopParams,
) -> Result<ClosedLoopResult, ClosedLoopError> {
    let mut lp = driver::ClosedLoop::init(post, x0, candidates, laws, params)?;
    for round in 0..params.max_rounds {
        if lp.round(round)? == RoundOutcome::NothingPasses {
            break;
        }
    }
    lp.terminate()
}

/// The refit's inputs for candidate `c`: its prior's range (infinite when not uniform), the
/// score test's one-step size kept 1 % of the range inside it, and the model parameters' start
/// (the score test's Gauss-Newton step from `starts`, else the current MAP's `phys_model`).
fn refit_inputs(
    c: &Candidate,
    starts: &[(String, Vec<f64>)],
    phys_model: &[f64],
) -> (f64, f64, f64, Vec<f64>) {
    let (lo, hi) = match c.effect.default_prior() {
        Prior::Uniform { lo, hi } => (lo, hi),
        _ => (f64::NEG_INFINITY, f64::INFINITY),
    };
    let span = hi - lo;
    let one_step = c.one_step.clamp(lo + 0.01 * span, hi - 0.01 * span);
    let gn = starts
        .iter()
        .find(|(n, _)| *n == c.effect.name())
        .map_or_else(|| phys_model.to_vec(), |(_, v)| v.clone());
    (lo, hi, one_step, gn)
}

/// The evidence gain (nats) the score test predicts for candidate `effect` with statistic `t`
/// and one-step sd `sd` (`1 / sqrt(I*)`): the quadratic model's log-likelihood gain `t / 2` plus
/// the Occam factor of one parameter with that posterior sd under its uniform prior on
/// `[lo, hi]`, `ln(sqrt(2 pi) sd / (hi - lo))` (the Laplace evidence ratio of a linear-Gaussian
/// model). NaN for a prior that is not uniform.
pub fn predicted_gain(effect: &Effect, t: f64, sd: f64) -> f64 {
    match effect.default_prior() {
        Prior::Uniform { lo, hi } if hi > lo && sd > 0.0 => {
            0.5 * t + ((2.0 * std::f64::consts::PI).sqrt() * sd / (hi - lo)).ln()
        }
        _ => f64::NAN,
    }
}

/// The log-evidence gain (nats) of refit `r` over `current`, which has `extra` fewer
/// parameters, on `n_data` complex values: the Laplace evidences' difference when both Hessians
/// are positive definite; otherwise (a fit at a prior bound) the log-posterior gain at the MAPs
/// less the BIC cost of the extra parameters, `(extra / 2) ln(2 N)`.
pub(crate) fn evidence_gain(r: &MapResult, current: &MapResult, extra: i64, n_data: usize) -> f64 {
    if r.laplace.positive_definite && current.laplace.positive_definite {
        r.laplace.log_evidence - current.laplace.log_evidence
    } else {
        r.laplace.log_posterior()
            - current.laplace.log_posterior()
            - 0.5 * extra as f64 * (2.0 * n_data as f64).ln()
    }
}

/// Whether `a` and `b` are attachments at the same point (a point mass, a sensor mass or a
/// resonator): once one is accepted the others are not tried. Below its own frequency a
/// resonator loads its point as a mass does, so the two would stand in for each other.
fn same_attachment_point(a: &Effect, b: &Effect) -> bool {
    let id = |e: &Effect| match e {
        Effect::PointMass { id, .. }
        | Effect::SensorMass { id, .. }
        | Effect::SensorMassTerm { id }
        | Effect::Resonator { id, .. } => Some(*id),
        _ => None,
    };
    id(a).is_some() && id(a) == id(b)
}

/// An alternative law is not refitted while its last refit's shortfall against the loop's fit
/// exceeds this many times the evidence gained since (at least the threshold's worth).
pub const LAW_SKIP_FACTOR: f64 = 10.0;

/// Whether one of `a` and `b` is base springs and the other the beam modulus factor: once one
/// is in the model the other is not tried. Both soften the structure; after a beam factor
/// accepted as a stand-in (for a sensor's x and z inertia, or a mesh that is too stiff) the
/// springs' refit with the beam factor free took 574 s for nothing on rfmlab's three-direction
/// mass at point 3 (320 evaluations at 1.8 s, ten times the springs' cost without it).
fn springs_and_beam(a: &Effect, b: &Effect) -> bool {
    let springs = |e: &Effect| matches!(e, Effect::BaseSprings { .. });
    let beam = |e: &Effect| matches!(e, Effect::BeamModulus);
    (springs(a) && beam(b)) || (beam(a) && springs(b))
}

/// Whether `a` and `b` are base springs of two shapes: one base has one set of springs.
fn other_springs_shape(a: &Effect, b: &Effect) -> bool {
    matches!(a, Effect::BaseSprings { .. }) && matches!(b, Effect::BaseSprings { .. })
}

/// Whether `e` changes the constitutive law (a Maxwell branch) rather than the structure or
/// the measurement chain.
pub fn is_law_effect(e: &Effect) -> bool {
    matches!(e, Effect::MaxwellBranch { .. })
}

/// The default candidate list for an observation: a point mass and a resonator (a mass on
/// the default spring, [`crate::forward::effects::DEFAULT_RESONATOR_STIFFNESS_N_M`]) per
/// measured point that is an engine input (with its id), a gain and a delay per channel, the
/// beam modulus and a shaker's moving mass on the default stinger (acting at the drive point).
///
/// At zero size a resonator's column is the point mass's (`dm_eff/dm = 1`), so the two tie in
/// the score test; each resonator follows its point's mass, and the ranking's stable sort
/// sends both to the refits, where the evidence tells them apart.
pub fn default_candidates(channel_ids: &[u32], mass_points: &[(usize, u32)]) -> Vec<Effect> {
    default_candidates_with(
        channel_ids,
        mass_points,
        crate::forward::effects::DEFAULT_RESONATOR_STIFFNESS_N_M,
    )
}

/// [`default_candidates`] with the resonators on a spring of `resonator_stiffness_n_m` (N/m).
pub fn default_candidates_with(
    channel_ids: &[u32],
    mass_points: &[(usize, u32)],
    resonator_stiffness_n_m: f64,
) -> Vec<Effect> {
    let mut c = Vec::new();
    for &(point, id) in mass_points {
        c.push(Effect::PointMass { point, id });
        c.push(Effect::Resonator {
            point,
            id,
            stiffness_n_m: resonator_stiffness_n_m,
        });
    }
    for (channel, &id) in channel_ids.iter().enumerate() {
        c.push(Effect::Gain { channel, id });
        c.push(Effect::Delay { channel, id });
    }
    c.push(Effect::BeamModulus);
    c.push(Effect::Shaker {
        stiffness_n_m: crate::forward::effects::DEFAULT_STINGER_STIFFNESS_N_M,
    });
    c
}

/// Law candidates: one more Maxwell branch with its corner frequency `1 / (2 pi tau)` on the
/// 1-2-5 series inside the band `band_hz` (the branch's modulus the parameter; a relaxation
/// time is not identified at zero modulus, so the score test runs on a grid of them).
pub fn maxwell_candidates(band_hz: (f64, f64)) -> Vec<Effect> {
    let mut c = Vec::new();
    for decade in -2..6 {
        for m in [1.0, 2.0, 5.0] {
            let f = m * 10f64.powi(decade);
            if f >= band_hz.0 && f <= band_hz.1 {
                c.push(Effect::MaxwellBranch {
                    tau_s: 1.0 / (std::f64::consts::TAU * f),
                });
            }
        }
    }
    c
}
