//! Old paths of the Bayesian stages ([`crate::bayes`]), removed once every caller moved: the
//! runner's stages that still read a study call these, which take the study and pass the
//! bayes functions what they read of it.

use crate::bayes::{InferenceParams, PosteriorInputs, SamplerParams};
use crate::study::inference::Inference;
use crate::study::Study;

/// The posterior inputs of `study` (`point_ids`: its structure's point ids).
fn posterior_inputs<'a>(study: &'a Study, point_ids: &'a [u32]) -> PosteriorInputs<'a> {
    PosteriorInputs {
        file: &study.file,
        estimator: study
            .measurements
            .as_ref()
            .and_then(|m| m.estimator.as_ref()),
        point_ids,
        declared: &study.declared_effects,
    }
}

/// Old path of [`crate::bayes::posterior`], with the functions that took the study.
pub mod posterior {
    pub use crate::bayes::posterior::*;

    use super::*;
    use crate::forward::MeasurementModel;
    use crate::frf::FrfEngine;
    use crate::inference::likelihood::FrfPosterior;
    use crate::material::ConstitutiveModel;
    use crate::stage::{LevelData, RunError};

    /// [`crate::bayes::posterior::measurement_model`] of `study`'s estimator.
    pub fn measurement_model(
        study: &Study,
        level: &LevelData,
    ) -> Result<Option<MeasurementModel>, RunError> {
        let inputs = posterior_inputs(study, &[]);
        crate::bayes::posterior::measurement_model(inputs.estimator, inputs.file, level)
    }

    /// [`crate::bayes::posterior::build_posterior`] of `model_name` (its priors and sampler
    /// settings in `inf`) at `level`.
    pub fn build_posterior<'a>(
        study: &Study,
        inf: &Inference,
        engine: &'a dyn FrfEngine,
        level: &LevelData,
        law: &'a dyn ConstitutiveModel,
        model_name: &str,
    ) -> Result<FrfPosterior<'a>, RunError> {
        let ids: Vec<u32> = study.structure.points.iter().map(|p| p.id).collect();
        let stage = InferenceParams {
            level: level.name.clone(),
            model: model_name.to_string(),
            priors: inf.priors.get(model_name).cloned().unwrap_or_default(),
            samplers: SamplerParams::from(inf),
        };
        crate::bayes::posterior::build_posterior(
            &posterior_inputs(study, &ids),
            &stage,
            engine,
            level,
            law,
        )
    }
}

/// Old path of [`crate::bayes::declared`], with the function that took the study.
pub mod declared {
    pub use crate::bayes::declared::*;

    use super::*;

    /// [`crate::bayes::declared::deterministic_note`] of `study`'s declared effects.
    pub fn deterministic_note(study: &Study) -> Option<String> {
        crate::bayes::declared::deterministic_note(&study.declared_effects)
    }
}
