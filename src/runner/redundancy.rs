//! Parameter redundancy of one posterior: the SVD of the whitened,
//! log-scaled sensitivity at the MAP, the posterior correlation matrix and per-parameter
//! identifiability (posterior sd over prior sd in unconstrained coordinates). The numerics are
//! in [`crate::inference::identifiability`].

use super::bayes::SamplerResult;
use crate::inference::identifiability::{
    combination_text, correlation_matrix, prior_sd_x, sd, sensitivity_svd, SensitivitySvd,
};
use crate::inference::likelihood::FrfPosterior;
use crate::inference::map::MapResult;

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
    pub sampler: String,
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

/// The redundancy analysis of `post` at `map` with the draws of the first sampler in
/// `samplers` (NUTS's when it ran). `post` must be in the state the samplers saw.
pub fn analyse(
    post: &FrfPosterior<'_>,
    map: &MapResult,
    samplers: &[SamplerResult],
) -> Result<Redundancy, String> {
    let nl = post.n_law();
    let phys = &map.map_physical;
    let lik = &post.likelihood;
    let pred = lik
        .forward
        .predict(&phys[..nl], true)
        .map_err(|e| format!("sensitivity at the MAP: {e}"))?;
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
        .find(|s| s.sampler == "nuts")
        .or(samplers.first())
        .ok_or("no posterior draws")?;
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
        sampler: s.sampler.clone(),
        posterior_sd_x: xcols.iter().map(|c| sd(c)).collect(),
        prior_sd_x: post.priors.iter().map(prior_sd_x).collect(),
    })
}
