//! The closed loop's settings made from a validated study: the one file of the stage that reads
//! a [`Study`]. The plan ([`crate::pipeline::Plan`]) takes the loop's own settings from
//! [`params_of`]; the run and `rfmlab diagnose` make the stage's from [`DiagnoseParams::of`]
//! and a level's posterior from [`StudyPosterior`]. Everything below takes these params.

use super::params::{key_error, DiagnoseParams, LevelPosterior, NullChainParams, TermParams};
use crate::closed_loop::ClosedLoopParams;
use crate::frf::FrfEngine;
use crate::inference::likelihood::FrfPosterior;
use crate::material::ConstitutiveModel;
use crate::stage::{LevelData, RunError};
use crate::study::Study;

/// The loop's settings from the study's `[closed_loop]` section (defaults without one), its
/// MAP searches seeded with the study's seed: how the plan is made.
pub fn params_of(study: &Study) -> ClosedLoopParams {
    let mut d = ClosedLoopParams::default();
    d.map.seed = study.seed;
    match &study.closed_loop {
        None => d,
        Some(s) => ClosedLoopParams {
            threshold_nats: s.evidence_threshold_nats,
            top: s.top,
            max_rounds: s.max_effects + 1,
            p_threshold: s.p_threshold,
            ..d
        },
    }
}

/// Whether `[closed_loop] candidates` names the three-direction sensor mass (its type
/// `sensor_mass` or a name `mass3_pt<id>`): it is not among `candidates = "all"`.
pub fn wants_sensor_mass(study: &Study) -> bool {
    study
        .closed_loop
        .as_ref()
        .is_some_and(|c| c.names(|n| n == "sensor_mass" || n.starts_with("mass3_pt")))
}

/// The loop needs the likelihood of `[inference]`.
pub(crate) fn no_inference(study: &Study) -> RunError {
    key_error(
        &study.file,
        "inference",
        "diagnose needs an [inference] section (its noise model and priors define the likelihood the loop tests); add one as in studies/bayes.toml",
    )
}

impl DiagnoseParams {
    /// The stage's settings from `study`, for `model` (else the first of `[inference]
    /// models`); errors name the key.
    pub fn of(study: &Study, model: Option<&str>) -> Result<DiagnoseParams, RunError> {
        let Some(inf) = &study.inference else {
            return Err(no_inference(study));
        };
        let name = match model {
            Some(m) => m.to_string(),
            None => inf.models.first().cloned().ok_or_else(|| {
                key_error(&study.file, "inference.models", "list at least one model")
            })?,
        };
        let Some(model_index) = study
            .models
            .iter()
            .position(|m| m.name.eq_ignore_ascii_case(&name))
        else {
            return Err(key_error(
                &study.file,
                "inference.models",
                format!("model {name} is not a model of the study"),
            ));
        };
        let measurements = study.measurements.as_ref();
        Ok(DiagnoseParams {
            study_name: study.name.clone(),
            study_file: study.file.clone(),
            initial: study.models[model_index].initial.clone(),
            model: name,
            model_index,
            levels: inf.levels.clone(),
            channel_correlation: inf.channel_correlation,
            settings: study.closed_loop.clone(),
            declared: study.declared_effects.clone(),
            terms: TermParams::of(study),
            null: NullChainParams {
                estimator: measurements.and_then(|m| m.estimator.clone()),
                force_rms_n: measurements
                    .map(|m| {
                        m.levels
                            .iter()
                            .map(|l| (l.name.clone(), l.force_rms_n))
                            .collect()
                    })
                    .unwrap_or_default(),
                seed: study.seed,
            },
        })
    }
}

/// A level's posterior as the run's inference makes it from the study (its `[inference]`
/// noise model and priors, the H1 measurement model of `[measurements.estimator]`, the
/// declared effects).
pub struct StudyPosterior<'s>(pub &'s Study);

impl LevelPosterior for StudyPosterior<'_> {
    fn posterior<'a>(
        &self,
        engine: &'a dyn FrfEngine,
        level: &LevelData,
        law: &'a dyn ConstitutiveModel,
        model: &str,
    ) -> Result<FrfPosterior<'a>, RunError> {
        let study = self.0;
        let inf = study
            .inference
            .as_ref()
            .ok_or_else(|| no_inference(study))?;
        build_posterior(study, inf, engine, level, law, model)
    }
}

/// The posterior of `model_name` at `level` with the priors and sampler settings of the
/// study's `[inference]` section `inf` (the study's point ids, estimator and declared effects).
pub(crate) fn build_posterior<'a>(
    study: &Study,
    inf: &crate::study::inference::Inference,
    engine: &'a dyn FrfEngine,
    level: &LevelData,
    law: &'a dyn ConstitutiveModel,
    model_name: &str,
) -> Result<FrfPosterior<'a>, RunError> {
    let ids: Vec<u32> = study.structure.points.iter().map(|p| p.id).collect();
    let stage = crate::bayes::InferenceParams {
        level: level.name.clone(),
        model: model_name.to_string(),
        priors: inf.priors.get(model_name).cloned().unwrap_or_default(),
        samplers: crate::bayes::SamplerParams::from(inf),
    };
    let inputs = crate::bayes::PosteriorInputs {
        file: &study.file,
        estimator: study
            .measurements
            .as_ref()
            .and_then(|m| m.estimator.as_ref()),
        point_ids: &ids,
        declared: &study.declared_effects,
    };
    crate::bayes::posterior::build_posterior(&inputs, &stage, engine, level, law)
}

impl TermParams {
    /// The term ROM's settings of `study`: its joint, ROM tolerance, the `[inference]` models'
    /// (box) and every model's initial values, and the cache beside its output folder.
    pub fn of(study: &Study) -> TermParams {
        let inference_models: &[String] = study
            .inference
            .as_ref()
            .map_or(&[], |i| i.models.as_slice());
        TermParams {
            joint: crate::study::build::joint_spec(&study.structure),
            tolerance: study.solver.rom_tolerance,
            box_models: study
                .models
                .iter()
                .filter(|m| {
                    inference_models
                        .iter()
                        .any(|x| x.eq_ignore_ascii_case(&m.name))
                })
                .cloned()
                .collect(),
            all_models: study.models.clone(),
            cache: crate::stage::rom_cache_dir(&study.output_dir),
            study_file: study.file.clone(),
            sensor_masses: Vec::new(),
        }
    }
}
