//! Parameter redundancy of one posterior: the SVD of the whitened,
//! log-scaled sensitivity at the MAP, the posterior correlation matrix and per-parameter
//! identifiability (posterior sd over prior sd in unconstrained coordinates). The numerics are
//! in [`crate::inference::identifiability`] (and checked by its unit tests).
//!
//! The sensitivity is `S_ok = p_k dE[H1]_o/dp_k / sqrt(v_o)` (real and imaginary parts as
//! rows, `v_o` the noise variance at the MAP): its singular values say how many combinations
//! of `ln p` the data determine, the weakest right singular vector which one they do not.

use super::posterior::SamplerResult;
use crate::forward::ForwardError;
use crate::inference::identifiability::{
    combination_text, correlation_matrix, prior_sd_x, sd, sensitivity_svd, SensitivityError,
    SensitivitySvd,
};
use crate::inference::likelihood::FrfPosterior;
use crate::inference::map::MapResult;
use crate::inference::Sampler;

/// Redundancy of one model at one level.
#[derive(Clone, Debug)]
pub struct Redundancy {
    /// The law's parameter names (the SVD's columns).
    pub law_names: Vec<String>,
    /// SVD of `S_ok = p_k dE[H1]_o/dp_k / sqrt(v_o)` (real and imaginary rows) at the MAP.
    pub svd: SensitivitySvd,
    /// The weakest direction as text (`+0.71 d ln E0 -0.70 d ln eta0`).
    pub weakest_text: String,
    /// Names of all coordinates (law and noise) of the correlation matrix and ratios.
    pub names: Vec<String>,
    /// Posterior correlation (row-major) of the unconstrained coordinates, from the draws of
    /// `sampler`.
    pub correlation: Vec<f64>,
    pub sampler: Sampler,
    pub posterior_sd_x: Vec<f64>,
    pub prior_sd_x: Vec<f64>,
}

impl Redundancy {
    /// Posterior sd over prior sd per coordinate.
    pub fn ratio(&self) -> Vec<f64> {
        self.posterior_sd_x
            .iter()
            .zip(&self.prior_sd_x)
            .map(|(a, b)| a / b)
            .collect()
    }
}

/// Why a posterior has no redundancy analysis.
#[derive(Debug, Clone, thiserror::Error)]
pub enum RedundancyError {
    #[error("sensitivity at the MAP: {0}")]
    Sensitivity(#[from] ForwardError),
    #[error(transparent)]
    Svd(#[from] SensitivityError),
    #[error("no posterior draws")]
    NoDraws,
}

/// The redundancy analysis of `post` at `map` with the draws of the first sampler in
/// `samplers` (NUTS's when it ran). `post` must be in the state the samplers saw.
pub fn analyse(
    post: &FrfPosterior<'_>,
    map: &MapResult,
    samplers: &[SamplerResult],
) -> Result<Redundancy, RedundancyError> {
    let nl = post.n_law();
    let phys = &map.map_physical;
    let lik = &post.likelihood;
    let pred = lik.forward.predict(&phys[..nl], true)?;
    let var = lik.variances(&phys[nl..]);
    let cols: Vec<Vec<f64>> = (0..nl)
        .map(|k| {
            pred.jac[k]
                .iter()
                .zip(&var)
                .flat_map(|(j, v)| {
                    let s = phys[k] / v.sqrt();
                    [j.re * s, j.im * s]
                })
                .collect()
        })
        .collect();
    let svd = sensitivity_svd(&cols)?;
    let law_names: Vec<String> = post.names[..nl].to_vec();
    let weakest_text = svd
        .weakest()
        .map(|(_, v)| combination_text(&law_names, v))
        .unwrap_or_default();
    let s = samplers
        .iter()
        .find(|s| s.sampler == Sampler::Nuts)
        .or(samplers.first())
        .ok_or(RedundancyError::NoDraws)?;
    let xcols: Vec<Vec<f64>> = s
        .draws
        .values
        .iter()
        .zip(&post.priors)
        .map(|(col, p)| col.iter().map(|v| p.to_unconstrained(*v)).collect())
        .collect();
    Ok(Redundancy {
        law_names,
        weakest_text,
        svd,
        names: post.names.clone(),
        correlation: correlation_matrix(&xcols),
        sampler: s.sampler,
        posterior_sd_x: xcols.iter().map(|c| sd(c)).collect(),
        prior_sd_x: post.priors.iter().map(prior_sd_x).collect(),
    })
}
