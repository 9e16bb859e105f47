//! The closed loop as a stage of a run ([`crate::diagnose::loop_stage`]): on the run's
//! likelihood engine, with the posteriors the plan's inference stages define.

use crate::bayes::{InferenceParams, PosteriorInputs};
use crate::diagnose::LevelPosterior;
use crate::frf::FrfEngine;
use crate::inference::likelihood::FrfPosterior;
use crate::material::ConstitutiveModel;
use crate::stage::{input_error, LevelData, RunError};

/// The posterior of a law at a level as the plan's inference stage of that model builds it
/// (at that level, else the model's stage at another level: the same priors and settings).
pub(super) struct PlanPosterior<'p> {
    pub stages: &'p [InferenceParams],
    pub inputs: PosteriorInputs<'p>,
}

impl LevelPosterior for PlanPosterior<'_> {
    fn posterior<'a>(
        &self,
        engine: &'a dyn FrfEngine,
        level: &LevelData,
        law: &'a dyn ConstitutiveModel,
        model: &str,
    ) -> Result<FrfPosterior<'a>, RunError> {
        let of_model = |s: &&InferenceParams| s.model.eq_ignore_ascii_case(model);
        let stage = self
            .stages
            .iter()
            .filter(of_model)
            .find(|s| s.level == level.name)
            .or_else(|| self.stages.iter().find(of_model))
            .ok_or_else(|| {
                input_error(
                    self.inputs.file,
                    "inference.models",
                    format!("the closed loop's model {model} has no inference stage"),
                )
            })?;
        let mut stage = stage.clone();
        stage.level = level.name.clone();
        crate::bayes::posterior::build_posterior(&self.inputs, &stage, engine, level, law)
    }
}
