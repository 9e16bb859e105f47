//! The start of a command that runs one stage of a study.

use super::engine::{build_engine, EngineParams, Engines, LikelihoodInputs, ModelsAndData};
use super::model::build;
use super::{LevelData, RunError};
use crate::material::ConstitutiveModel;
use crate::study::build::BuiltModel;
use std::path::Path;

/// What a command that runs one stage of a study starts from (`rfmlab diagnose`, a prepared
/// posterior): the laws, the built model, the levels' data and the engines, made as
/// `rfmlab run` makes them.
pub struct Setup {
    pub laws: Vec<Box<dyn ConstitutiveModel>>,
    pub built: BuiltModel,
    pub levels: Vec<LevelData>,
    pub engines: Engines,
    /// The pre-flight's warnings that bear on the results (channels flipped, a level's file
    /// whose force level differs from the level's).
    pub warnings: Vec<String>,
}

/// The [`Setup`] of `study`, with the likelihood's engine on `likelihood`'s inputs, reusing
/// certified ROMs from `rom_cache` when given. The one function of the stages that reads a
/// whole study: it is where a single-stage command enters.
pub fn setup(
    study: &crate::study::Study,
    likelihood: Option<LikelihoodInputs>,
    rom_cache: Option<&Path>,
) -> Result<Setup, RunError> {
    setup_with_grids(study, likelihood, rom_cache, &[])
}

/// A level's H1 measurement model with the grid chosen for it
/// ([`LevelData::measurement`](super::LevelData::measurement)), by level name.
pub type LevelGrid = (
    String,
    (crate::forward::MeasurementModel, crate::forward::GridChoice),
);

/// [`setup`] with the measurement models' grids of the levels named in `grids` already
/// chosen (by an earlier setup of the same structure and data, e.g. the closed loop's first
/// pass): the engine does not choose them again.
pub fn setup_with_grids(
    study: &crate::study::Study,
    likelihood: Option<LikelihoodInputs>,
    rom_cache: Option<&Path>,
    grids: &[LevelGrid],
) -> Result<Setup, RunError> {
    let file = study.file.as_path();
    let laws = crate::stage::model_laws(&study.models, file)?;
    let built = build(&study.structure, file)?;
    // The pre-flight of the data, before anything is fitted (the analysis bands are
    // `rfmlab run`'s and are not checked here).
    let super::data::LoadedLevels {
        mut levels,
        warnings,
    } = super::preflight::check_data(
        &super::preflight::DataChecks {
            file,
            measurements: study.measurements.as_ref(),
            points: &study.structure.points,
            band_constant: &[],
            iem: &[],
        },
        &built,
    )?;
    for level in levels.iter_mut() {
        if let Some((_, chosen)) = grids.iter().find(|(name, _)| *name == level.name) {
            level.measurement = Some(chosen.clone());
        }
    }
    let models = ModelsAndData {
        models: &study.models,
        laws: &laws,
        estimator: study
            .measurements
            .as_ref()
            .and_then(|m| m.estimator.as_ref()),
        file,
    };
    let engines = build_engine(
        &EngineParams::of(study),
        likelihood,
        &models,
        &built,
        &mut levels,
        rom_cache,
    )?;
    Ok(Setup {
        laws,
        built,
        levels,
        engines,
        warnings,
    })
}
