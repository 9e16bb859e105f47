//! Model comparison at one level and model, computed while the posterior is alive (called
//! from [`super::infer_level`] after the samplers): the evidence per estimator (Laplace, the
//! samplers', the stepping-stone of `stepping_stone.rs`, by default from a reference fitted to
//! the posterior draws, [`mod@reference`], and the importance reweightings of TMCMC's particles
//! `tmcmc_is` and NUTS's draws `nuts_is`, with the stepping-stone only), the evidence under priors widened ten-fold ([`widening`]),
//! and the predictive criteria on thinned posterior draws (`criteria.rs`: the pointwise log
//! likelihood per line with PSIS-LOO and WAIC, FRAC per FRF, SCC(w), ACC(w), standardised
//! residuals and a chi-square test per channel at the MAP). Across models (Bayes factors,
//! model probabilities) it is done when writing the report. Checked by the suite's
//! `model_comparison` test (against ArviZ's LOO and WAIC, the widening shift `-d ln 10`).

mod criteria;
pub mod reference;
mod stepping_stone;
pub mod widening;

pub use widening::{widened, widening_shift};

use super::posterior::SamplerResult;
use super::{At, Checkpoints, SamplerParams};
use crate::common::C64;
use crate::inference::likelihood::FrfPosterior;
use crate::inference::loo::{Loo, Waic};
use crate::inference::map::MapResult;
use crate::inference::Sampler;
use crate::stage::{Event, RunError};
use widening::inside_sd;

/// Most posterior draws the pointwise log likelihood and the predictive criteria use (thinned
/// evenly within each chain).
pub const MAX_DRAWS: usize = 400;

/// One evidence estimate.
#[derive(Clone, Debug)]
pub struct EvidenceRow {
    /// "laplace", "tmcmc", "stepping_stone", "tmcmc_is" or "nuts_is".
    pub estimator: String,
    /// "declared" or "widened_10x".
    pub prior: String,
    pub log_evidence: f64,
    pub se: f64,
    pub n_loglik: u64,
    pub seconds: f64,
}

/// Median and 95 % band of a quantity over posterior draws, with its value at the MAP.
#[derive(Clone, Debug)]
pub struct Band {
    pub map: f64,
    pub median: f64,
    pub lo: f64,
    pub hi: f64,
}

/// Posterior predictive check of one channel at the MAP.
#[derive(Clone, Debug)]
pub struct ChannelCheck {
    pub response_id: u32,
    /// Standardised complex residuals `(E[H1] - X) / sqrt(v)` per line.
    pub residuals: Vec<C64>,
    /// `sum |r|^2` (each of re, im has unit variance under the noise model).
    pub chi2: f64,
    /// Degrees of freedom, `2 n_lines`.
    pub dof: usize,
    /// Upper-tail probability of `chi2` under chi-square(`dof`).
    pub p_value: f64,
}

/// Everything of the comparison for one model at one level.
#[derive(Clone, Debug, Default)]
pub struct Comparison {
    pub evidence: Vec<EvidenceRow>,
    /// Smallest distance of a law parameter's posterior mean to its declared bounds, in
    /// posterior sds (infinite for unbounded priors).
    pub inside_sd: f64,
    /// Which sampler's draws the predictive criteria use (`None`: no draws, no criteria).
    pub draws_from: Option<Sampler>,
    /// (chain, draw) of the thinned draws, numbered as in the `draws` table.
    pub draw_index: Vec<(usize, usize)>,
    /// `pointwise[draw][line]`: log likelihood per line, summed over channels.
    pub pointwise: Vec<Vec<f64>>,
    pub loo: Option<Loo>,
    pub waic: Option<Waic>,
    /// FRAC per channel (order of the level's response ids).
    pub frac: Vec<Band>,
    /// SCC and ACC per line.
    pub scc: Vec<Band>,
    pub acc: Vec<Band>,
    pub ppc: Vec<ChannelCheck>,
    /// The level's lines (Hz).
    pub freq_hz: Vec<f64>,
    /// Notes for the report (stepping-stone replicas, failures of a criterion).
    pub notes: Vec<String>,
}

/// Comparison of one model at one level: see the module documentation. `samplers` carry the
/// evidence already corrected to the exact measurement model by `lin_shift` (nats, with its
/// standard error), which is added to the stepping-stone and Laplace estimates here too. The
/// stepping-stone replicas are checkpointed in `checkpoints`; `at` names the stage and gives
/// its seed.
#[allow(clippy::too_many_arguments)]
pub fn compare(
    checkpoints: &Checkpoints<'_>,
    inf: &SamplerParams,
    post: &FrfPosterior<'_>,
    map: &MapResult,
    samplers: &[SamplerResult],
    lin_shift: (f64, f64),
    at: &At<'_>,
    progress: &(dyn Fn(Event) + Sync),
) -> Result<Comparison, RunError> {
    let mut c = Comparison {
        freq_hz: at.level.freq_hz.clone(),
        ..Comparison::default()
    };
    let nl = post.n_law();
    // Evidence per estimator, declared priors.
    c.evidence.push(EvidenceRow {
        estimator: "laplace".into(),
        prior: "declared".into(),
        log_evidence: map.laplace.log_evidence + lin_shift.0,
        se: f64::NAN,
        n_loglik: map.evaluations as u64,
        seconds: f64::NAN,
    });
    for s in samplers {
        if let Some((lz, se)) = s.log_evidence {
            c.evidence.push(EvidenceRow {
                estimator: s.sampler.to_string(),
                prior: "declared".into(),
                log_evidence: lz,
                se,
                n_loglik: s.evaluations as u64,
                seconds: s.seconds,
            });
        }
    }
    if let Some(ss) = &inf.stepping_stone {
        let (mut row, notes) =
            stepping_stone::run(checkpoints, ss, post, map, samplers, at, progress)?;
        row.log_evidence += lin_shift.0;
        row.se = row.se.hypot(lin_shift.1);
        c.evidence.push(row);
        c.notes.extend(notes);
    }
    // Importance reweightings of TMCMC's particles and NUTS's draws, with the comparison part
    // (stepping-stone) only: each a second estimator beside the stepping-stone.
    if let Some(ss) = &inf.stepping_stone {
        for sampler in [Sampler::Tmcmc, Sampler::Nuts] {
            let est = format!("{}_is", sampler.name());
            match reference::reweighted(sampler, post, samplers, ss.widen, ss.nu, at.seed) {
                Some(Ok(r)) => {
                    c.evidence.push(EvidenceRow {
                        estimator: est,
                        prior: "declared".into(),
                        log_evidence: r.log_evidence + lin_shift.0,
                        se: r.se.hypot(lin_shift.1),
                        n_loglik: r.n_loglik,
                        seconds: r.seconds,
                    });
                    c.notes.push(r.note);
                }
                Some(Err(e)) => c.notes.push(format!("{est} not computed: {e}")),
                None => {}
            }
        }
    }
    // The posterior draws of the criteria: NUTS's when it ran, else TMCMC's.
    let Some(s) = samplers
        .iter()
        .find(|s| s.sampler == Sampler::Nuts)
        .or(samplers.iter().find(|s| !s.draws.lp.is_empty()))
    else {
        return Ok(c);
    };
    c.draws_from = Some(s.sampler);
    // Widened priors by importance reweighting of the draws.
    let (shift, shift_se) = widening_shift(&post.priors, &s.draws.values, nl);
    c.inside_sd = inside_sd(&post.priors, &s.draws.values, nl);
    let declared: Vec<EvidenceRow> = c.evidence.clone();
    for e in declared {
        c.evidence.push(EvidenceRow {
            prior: "widened_10x".into(),
            log_evidence: e.log_evidence + shift,
            se: e.se.hypot(shift_se),
            ..e
        });
    }
    criteria::predictive(&mut c, post, map, s, at, progress)?;
    Ok(c)
}
