//! The parameters of the inference stages as a run's plan states them (`Plan::inference`):
//! per (model, level) the priors and the settings of the MAP search and the samplers. The
//! stages of one run share their sampler settings, and a model has the same priors at every
//! level (the plan's lowering checks both).

use crate::inference::prior::Prior;
use crate::study::inference::{
    CorrelationKind, Inference, NoiseSpec, NutsSettings, SteppingStoneSettings,
};

/// Settings of the MAP search and the samplers of an inference stage.
#[derive(Clone, Debug, PartialEq)]
pub struct SamplerParams {
    pub nuts: Option<NutsSettings>,
    pub tmcmc_particles: Option<usize>,
    pub stepping_stone: Option<SteppingStoneSettings>,
    pub noise: NoiseSpec,
    pub noise_scale_prior: Prior,
    pub nu_prior: Prior,
    pub map_starts: usize,
    pub map_max_iterations: u64,
    pub linearised_measurement: bool,
    pub channel_correlation: Option<(CorrelationKind, usize)>,
}

impl From<&Inference> for SamplerParams {
    /// The sampler settings of a study's `[inference]` section.
    fn from(inf: &Inference) -> SamplerParams {
        SamplerParams {
            nuts: inf.nuts.clone(),
            tmcmc_particles: inf.tmcmc_particles,
            stepping_stone: inf.stepping_stone.clone(),
            noise: inf.noise.clone(),
            noise_scale_prior: inf.noise_scale_prior.clone(),
            nu_prior: inf.nu_prior.clone(),
            map_starts: inf.map_starts,
            map_max_iterations: inf.map_max_iterations,
            linearised_measurement: inf.linearised_measurement,
            channel_correlation: inf.channel_correlation,
        }
    }
}

/// The posterior of one model at one level: MAP, samplers, evidence, model-comparison
/// criteria and redundancy.
#[derive(Clone, Debug, PartialEq)]
pub struct InferenceParams {
    pub level: String,
    pub model: String,
    /// One prior per law parameter, then the noise parameters'.
    pub priors: Vec<Prior>,
    pub samplers: SamplerParams,
}

/// The stages of `level` among `stages`, in order, one per model (the first when a model
/// appears twice).
pub fn stages_at<'a>(stages: &'a [InferenceParams], level: &str) -> Vec<&'a InferenceParams> {
    let mut out: Vec<&InferenceParams> = Vec::new();
    for s in stages.iter().filter(|s| s.level == level) {
        if !out.iter().any(|o| o.model == s.model) {
            out.push(s);
        }
    }
    out
}
