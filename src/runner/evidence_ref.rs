//! The reference density of the generalized stepping-stone evidence
//! ([`crate::inference::reference`]) for one model at one level: a Student-t fitted to the
//! posterior draws in the samplers' unconstrained coordinates (NUTS's when it ran, else
//! TMCMC's), or to the Laplace mode and covariance when there are no draws.

use super::posterior::SamplerResult;
use crate::inference::likelihood::FrfPosterior;
use crate::inference::map::MapResult;
use crate::inference::Reference;
use crate::inference::Sampler;

/// The reference and what it was fitted to ("NUTS draws", "TMCMC draws", "Laplace
/// approximation"), or why none could be fitted.
pub fn reference_for(
    post: &FrfPosterior<'_>,
    map: &MapResult,
    samplers: &[SamplerResult],
    widen: f64,
    nu: f64,
) -> Result<(Reference, String), String> {
    let drawn = samplers
        .iter()
        .find(|s| s.sampler == Sampler::Nuts && !s.draws.lp.is_empty())
        .or(samplers.iter().find(|s| !s.draws.lp.is_empty()));
    if let Some(s) = drawn {
        let v = &s.draws.values;
        let n = v.first().map_or(0, |c| c.len());
        let x: Vec<Vec<f64>> = (0..n)
            .map(|r| post.unconstrained(&v.iter().map(|c| c[r]).collect::<Vec<f64>>()))
            .filter(|x| x.iter().all(|v| v.is_finite()))
            .collect();
        if let Ok(q) = Reference::from_draws(&x, widen, nu) {
            return Ok((
                q,
                format!("{} {} draws", s.sampler.name().to_uppercase(), x.len()),
            ));
        }
    }
    let lap = &map.laplace;
    if !lap.positive_definite {
        return Err("no posterior draws and no positive definite Laplace covariance".into());
    }
    Reference::new(&lap.x, &lap.cov_x, widen, nu)
        .map(|q| (q, "Laplace approximation".to_string()))
        .map_err(|e| e.to_string())
}

/// A 64-bit FNV-1a hash of the reference's numbers (bits), for checkpoint keys: a replica
/// saved with another reference is not reused.
pub fn reference_hash(q: &Reference) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for v in q.mean.iter().chain(&q.chol).chain(std::iter::once(&q.nu)) {
        for b in v.to_bits().to_le_bytes() {
            h ^= b as u64;
            h = h.wrapping_mul(0x0100_0000_01b3);
        }
    }
    h
}

/// TMCMC's reweighted evidence: (log Z, se, likelihood calls, seconds, note).
pub type Reweighted = (f64, f64, u64, f64, String);

/// Independent draws of TMCMC's final importance reweighting.
pub const TMCMC_IS_DRAWS: usize = 4000;

/// TMCMC's evidence by a final importance reweighting: a Student-t reference fitted to its
/// final particles (in the unconstrained coordinates, widened `widen`, `nu` degrees of
/// freedom) and [`TMCMC_IS_DRAWS`] independent draws from it
/// ([`crate::inference::importance_evidence`]). `None` when TMCMC did not run.
pub fn tmcmc_reweighted(
    post: &FrfPosterior<'_>,
    samplers: &[SamplerResult],
    widen: f64,
    nu: f64,
    seed: u64,
) -> Option<Result<Reweighted, String>> {
    let s = samplers
        .iter()
        .find(|s| s.sampler == Sampler::Tmcmc && !s.draws.lp.is_empty())?;
    let t0 = std::time::Instant::now();
    let v = &s.draws.values;
    let n = v.first().map_or(0, |c| c.len());
    let x: Vec<Vec<f64>> = (0..n)
        .map(|r| post.unconstrained(&v.iter().map(|c| c[r]).collect::<Vec<f64>>()))
        .filter(|x| x.iter().all(|v| v.is_finite()))
        .collect();
    let run = Reference::from_draws(&x, widen, nu)
        .map_err(|e| e.to_string())
        .and_then(|q| {
            crate::inference::importance_evidence(post, &q, TMCMC_IS_DRAWS, seed)
                .map_err(|e| e.to_string())
        });
    Some(run.map(|r| {
        (
            r.log_evidence,
            r.log_evidence_se,
            r.n_loglik,
            t0.elapsed().as_secs_f64(),
            format!(
                "tmcmc_is: TMCMC's {} particles fit a Student-t reference (nu {nu}, sd {widen} x theirs); {} independent draws from it, weights' effective sample size {:.0} %",
                x.len(),
                TMCMC_IS_DRAWS,
                100.0 * r.ess
            ),
        )
    }))
}
