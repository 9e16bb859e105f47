//! Bayesian inference on the forward model: priors, likelihood, the MAP by multistart search,
//! samplers (NUTS, TMCMC) and their diagnostics.
//!
//! Everything here sees a posterior only through [`Posterior`]: a log prior and a log likelihood
//! (each with its gradient) over unconstrained coordinates `x in R^d`, and draws from the prior.
//! The physical parameters are a fixed transform of `x` (log, or a logit of the log for bounded
//! priors); the prior density in `x` includes the transform's log-Jacobian, so samplers never see
//! a boundary.

use rand::rngs::StdRng;

pub mod basins;
pub mod checkpoint;
pub mod diagnostics;
pub mod identifiability;
pub mod joint;
pub mod likelihood;
pub mod lm;
pub mod loo;
pub mod map;
pub mod nuts;
pub mod reference;
pub mod refine;
pub mod sampling;
pub mod stepping_stone;
pub mod tmcmc;
pub mod whiten;

/// The priors and special functions live in [`crate::stats`], below the forward model.
pub use crate::stats::{prior, special};

pub use nuts::{sample_nuts, ChainDraws, NutsParams, NutsRun};
pub use reference::{
    importance_evidence, reference_stepping_stone, reference_stepping_stone_replica, ImportanceRun,
    Reference, ReferenceError, ReferencePosterior,
};
pub use sampling::{no_progress, Progress, Sampler, SamplerError};
pub use stepping_stone::{
    combine_replicas, stepping_stone, stepping_stone_replica, SteppingStoneParams,
    SteppingStoneReplica, SteppingStoneRun, SteppingStoneRung,
};
pub use tmcmc::{sample_tmcmc, TmcmcParams, TmcmcRun, TmcmcStage};

/// Why a density evaluation failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DensityError {
    /// The point cannot be evaluated (outside a law's admissible range, a singular forward
    /// model): a sampler rejects the proposal (NUTS counts it as a divergence) and continues.
    #[error("density not evaluable here: {0}")]
    Recoverable(String),
    /// Sampling cannot continue (missing data, an engine failure that will repeat).
    #[error("{0}")]
    Fatal(String),
}

/// A posterior over unconstrained coordinates `x in R^d`:
/// `log p(x | data) = log_prior(x) + log_likelihood(x) - log Z`.
///
/// Both densities write their gradient with respect to `x` into `grad` when it is given
/// (overwriting it, length [`Posterior::dim`]). Implementations are `Sync`: samplers call them
/// from several threads at once.
pub trait Posterior: Sync {
    /// Number of unconstrained coordinates.
    fn dim(&self) -> usize;
    /// One name per coordinate (the physical parameter it maps to), for outputs.
    fn names(&self) -> Vec<String>;
    /// Log prior density of `x` in the unconstrained coordinates (transform's log-Jacobian
    /// included), normalised: it integrates to one over `R^d`.
    fn log_prior(&self, x: &[f64], grad: Option<&mut [f64]>) -> f64;
    /// Log likelihood of the data at `x`, normalised over the data (so that evidences of
    /// different models compare).
    fn log_likelihood(&self, x: &[f64], grad: Option<&mut [f64]>) -> Result<f64, DensityError>;
    /// One draw from the prior, in unconstrained coordinates.
    fn sample_prior(&self, rng: &mut StdRng) -> Vec<f64>;
    /// Physical values (SI) of the coordinates `x`, in the order of [`Posterior::names`].
    fn constrained(&self, x: &[f64]) -> Vec<f64>;

    /// `ln |det dp/dx|`, the transform's log-Jacobian inside [`Posterior::log_prior`], with its
    /// gradient. The MAP in the physical parameters maximises `log_posterior - log_jacobian`
    /// (the mode does not depend on the coordinates chosen for sampling). Default 0 (the
    /// coordinates are the physical values).
    fn log_jacobian(&self, _x: &[f64], grad: Option<&mut [f64]>) -> f64 {
        if let Some(g) = grad {
            g.iter_mut().for_each(|v| *v = 0.0);
        }
        0.0
    }

    /// Prior quantiles `u in (0, 1)^d` mapped to unconstrained coordinates (for space-filling
    /// designs). Default: the standard logistic quantile `ln(u / (1 - u))` per coordinate;
    /// posteriors with their own priors override it.
    fn prior_quantile(&self, u: &[f64]) -> Vec<f64> {
        u.iter()
            .map(|u| {
                let u = u.clamp(1e-12, 1.0 - 1e-12);
                (u / (1.0 - u)).ln()
            })
            .collect()
    }

    /// `log p(x | data)` up to `log Z`, its gradient, and a Gauss-Newton curvature of
    /// `-log p` in `x` (positive semi-definite where the residuals are noise), for a
    /// Gauss-Newton search ([`map::SearchMethod::GaussNewton`]). Default `None`: the
    /// posterior has no least-squares structure to offer, and searches use L-BFGS.
    fn curvature(&self, _x: &[f64]) -> Option<Result<Curvature, DensityError>> {
        None
    }

    /// Log posterior density up to `log Z`, with its gradient when `grad` is given.
    fn log_posterior(&self, x: &[f64], grad: Option<&mut [f64]>) -> Result<f64, DensityError> {
        match grad {
            None => {
                let lp = self.log_prior(x, None);
                if lp == f64::NEG_INFINITY {
                    return Ok(lp);
                }
                Ok(lp + self.log_likelihood(x, None)?)
            }
            Some(g) => {
                let mut gp = vec![0.0; self.dim()];
                let lp = self.log_prior(x, Some(&mut gp));
                let ll = self.log_likelihood(x, Some(g))?;
                g.iter_mut().zip(&gp).for_each(|(a, b)| *a += b);
                Ok(lp + ll)
            }
        }
    }
}

/// A log density, its gradient and an approximation of the Hessian of minus it, in the
/// coordinates of whoever returns it: `x` for [`Posterior::curvature`] (the value as
/// [`Posterior::log_posterior`]), the physical law and noise coordinates for
/// [`likelihood::FrfLikelihood::information`] (the log likelihood).
#[derive(Clone, Debug, Default)]
pub struct Curvature {
    pub value: f64,
    pub grad: Vec<f64>,
    /// Row-major d x d.
    pub hess: Vec<f64>,
}

/// A reproducible RNG for independent unit `unit` (a chain, a start, a stage) of a run with
/// seed `seed`: one stream per unit, whatever thread runs it (SplitMix64 of the pair).
pub fn unit_rng(seed: u64, unit: u64) -> StdRng {
    use rand::SeedableRng;
    let mut z = seed ^ unit.wrapping_mul(0x9E37_79B9_7F4A_7C15).rotate_left(17);
    let mut next = || {
        z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut v = z;
        v = (v ^ (v >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        v = (v ^ (v >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        v ^ (v >> 31)
    };
    let mut key = [0u8; 32];
    for c in key.chunks_mut(8) {
        c.copy_from_slice(&next().to_le_bytes());
    }
    StdRng::from_seed(key)
}
