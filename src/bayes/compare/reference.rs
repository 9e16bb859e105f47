//! The reference density of the generalized stepping-stone evidence
//! ([`crate::inference::reference`]) for one model at one level: a Student-t fitted to the
//! posterior draws in the samplers' unconstrained coordinates (NUTS's when it ran, else
//! TMCMC's), or to the Laplace mode and covariance when there are no draws; and the evidence
//! by importance sampling from a Student-t fitted to a sampler's draws (TMCMC's final
//! particles, `tmcmc_is`; NUTS's draws, `nuts_is`; `Z = E_q[L p / q]`,
//! [`crate::inference::importance_evidence`]). Checked by the suite's
//! `evidence_quadrature` (both estimators against quadrature) and `model_comparison` tests.

use crate::bayes::posterior::SamplerResult;
use crate::inference::likelihood::FrfPosterior;
use crate::inference::map::MapResult;
use crate::inference::Sampler;
use crate::inference::{Reference, ReferenceError, SamplerError};

/// Why no reference or no reweighted evidence.
#[derive(Debug, thiserror::Error)]
pub enum EvidenceRefError {
    #[error("no posterior draws and no positive definite Laplace covariance")]
    NoDrawsNoLaplace,
    #[error(transparent)]
    Reference(#[from] ReferenceError),
    #[error(transparent)]
    Importance(#[from] SamplerError),
}

/// The reference and what it was fitted to ("NUTS draws", "TMCMC draws", "Laplace
/// approximation"), or why none could be fitted.
pub fn reference_for(
    post: &FrfPosterior<'_>,
    map: &MapResult,
    samplers: &[SamplerResult],
    widen: f64,
    nu: f64,
) -> Result<(Reference, String), EvidenceRefError> {
    let drawn = samplers
        .iter()
        .find(|s| s.sampler == Sampler::Nuts && !s.draws.lp.is_empty())
        .or(samplers.iter().find(|s| !s.draws.lp.is_empty()));
    if let Some(s) = drawn {
        let x = unconstrained_draws(post, s);
        if let Ok(q) = Reference::from_draws(&x, widen, nu) {
            return Ok((
                q,
                format!("{} {} draws", s.sampler.name().to_uppercase(), x.len()),
            ));
        }
    }
    let lap = &map.laplace;
    if !lap.positive_definite {
        return Err(EvidenceRefError::NoDrawsNoLaplace);
    }
    Ok((
        Reference::new(&lap.x, &lap.cov_x, widen, nu)?,
        "Laplace approximation".to_string(),
    ))
}

/// The draws of `s` in the unconstrained coordinates, non-finite ones left out.
fn unconstrained_draws(post: &FrfPosterior<'_>, s: &SamplerResult) -> Vec<Vec<f64>> {
    let v = &s.draws.values;
    let n = v.first().map_or(0, |c| c.len());
    (0..n)
        .map(|r| post.unconstrained(&v.iter().map(|c| c[r]).collect::<Vec<f64>>()))
        .filter(|x| x.iter().all(|v| v.is_finite()))
        .collect()
}

/// TMCMC's reweighted evidence.
#[derive(Clone, Debug)]
pub struct Reweighted {
    pub log_evidence: f64,
    pub se: f64,
    pub n_loglik: u64,
    pub seconds: f64,
    /// The report's sentence on it.
    pub note: String,
}

/// Independent draws of a sampler's importance reweighting.
pub const IS_DRAWS: usize = 4000;

/// The evidence by importance sampling from `sampler`'s draws (TMCMC's final particles, or
/// NUTS's draws): a Student-t reference fitted to them (in the unconstrained coordinates,
/// widened `widen`, `nu` degrees of freedom) and [`IS_DRAWS`] independent draws from it
/// ([`crate::inference::importance_evidence`], `Z = E_q[L p / q]`). Its error differs from
/// the stepping-stone's (one importance step from the reference instead of a tempered path
/// through it), which makes the pair a check of each other at the cost of [`IS_DRAWS`]
/// likelihood evaluations. `None` when the sampler did not run.
pub fn reweighted(
    sampler: Sampler,
    post: &FrfPosterior<'_>,
    samplers: &[SamplerResult],
    widen: f64,
    nu: f64,
    seed: u64,
) -> Option<Result<Reweighted, EvidenceRefError>> {
    let s = samplers
        .iter()
        .find(|s| s.sampler == sampler && !s.draws.lp.is_empty())?;
    let t0 = std::time::Instant::now();
    let x = unconstrained_draws(post, s);
    let run = Reference::from_draws(&x, widen, nu)
        .map_err(EvidenceRefError::from)
        .and_then(|q| {
            Ok(crate::inference::importance_evidence(
                post, &q, IS_DRAWS, seed,
            )?)
        });
    Some(run.map(|r| Reweighted {
        log_evidence: r.log_evidence,
        se: r.log_evidence_se,
        n_loglik: r.n_loglik,
        seconds: t0.elapsed().as_secs_f64(),
        note: format!(
            "{}_is: {}'s {} draws fit a Student-t reference (nu {nu}, sd {widen} x theirs); {} independent draws from it, weights' effective sample size {:.0} %",
            sampler.name(),
            sampler.name().to_uppercase(),
            x.len(),
            IS_DRAWS,
            100.0 * r.ess
        ),
    }))
}
