//! The closed loop stage's settings ([`DiagnoseParams`], made from a study by
//! [`DiagnoseParams::of`]) and what it runs on ([`LoopInputs`]): the run's model, data, laws
//! and engine, and how a level's posterior is made ([`LevelPosterior`]).

use crate::frf::FrfEngine;
use crate::inference::likelihood::FrfPosterior;
use crate::material::ConstitutiveModel;
use crate::stage::{LevelData, RunError};
use crate::study::build::BuiltModel;
use crate::study::effects::{ClosedLoopSettings, DeclaredEffect};
use crate::study::inference::CorrelationKind;
use crate::study::{Estimator, ModelSpec};
use std::path::PathBuf;

/// The stage's settings besides the loop's own ([`crate::closed_loop::ClosedLoopParams`]).
#[derive(Clone, Debug)]
pub struct DiagnoseParams {
    /// The study's name (the markdown's heading, the summary).
    pub study_name: String,
    /// The study file, named with the key in errors.
    pub study_file: PathBuf,
    /// The model the loop starts from: its name as asked (else the first of `[inference]
    /// models`).
    pub model: String,
    /// Its index among the study's models (and the run's laws).
    pub model_index: usize,
    /// Its initial values (SI, in the law's order): the MAP searches' first start.
    pub initial: Vec<f64>,
    /// The levels of `[inference]`: the loop runs at these.
    pub levels: Vec<String>,
    /// `inference.noise.channel_correlation`: estimated once at the starting model's MAP and
    /// held fixed during the loop.
    pub channel_correlation: Option<(CorrelationKind, usize)>,
    /// `[closed_loop]`: which candidates to try (None: every default candidate, none of the
    /// opt-in ones).
    pub settings: Option<ClosedLoopSettings>,
    /// The declared effects (`[[structure.effects]]`): their degraded bonds, base springs and
    /// adherend damping join the term ROM.
    pub declared: Vec<DeclaredEffect>,
    pub terms: TermParams,
    pub null: NullChainParams,
}

/// The term ROM's settings ([`super::terms::term_rom_for`]).
#[derive(Clone, Debug)]
pub struct TermParams {
    /// The mesher's joint (None for an imported structure: no adhesive elements to split, no
    /// base face to free).
    pub joint: Option<crate::fe::joint::JointSpec>,
    /// Certificate tolerance (relative FRF error), the study's `solver.rom_tolerance`.
    pub tolerance: f64,
    /// The models whose initial E*(w) make the modulus box ([`super::term_modulus_range`]):
    /// the `[inference]` models.
    pub box_models: Vec<ModelSpec>,
    /// Every model of the study: the effect-free ROM's box, when `box_models` give no modulus.
    pub all_models: Vec<ModelSpec>,
    /// Folder of cached term ROMs (`.rom-cache/` beside the study's output folder).
    pub cache: PathBuf,
    /// The study file, named with the key in errors.
    pub study_file: PathBuf,
    /// Points (ids) whose sensor mass in x, y and z joins the term ROM and the candidates as
    /// a term ([`crate::forward::Effect::SensorMassTerm`]): the three-direction pass of a
    /// joint on base springs. Empty by default.
    pub sensor_masses: Vec<u32>,
}

/// The measurement chain of the verdict's null level ([`crate::closed_loop::null`]).
#[derive(Clone, Debug)]
pub struct NullChainParams {
    /// `[measurements.estimator]`: replicate Welch experiments through it; None: the noise
    /// model's own errors.
    pub estimator: Option<Estimator>,
    /// The force RMS (N) of each level (`measurements.levels[].force_rms`), by level name.
    pub force_rms_n: Vec<(String, Option<f64>)>,
    /// Seed of the replicates (the study's).
    pub seed: u64,
}

impl NullChainParams {
    /// The force RMS (N) of `level`: the study's, else 1 N.
    pub fn force_of(&self, level: &str) -> f64 {
        self.force_rms_n
            .iter()
            .find(|(n, _)| n == level)
            .and_then(|(_, f)| *f)
            .unwrap_or(1.0)
    }
}

/// How the stage gets the posterior of a law at a level on an engine: the likelihood the run's
/// inference builds (noise model, priors, H1 measurement model, declared effects).
pub trait LevelPosterior {
    fn posterior<'a>(
        &self,
        engine: &'a dyn FrfEngine,
        level: &LevelData,
        law: &'a dyn ConstitutiveModel,
        model: &str,
    ) -> Result<FrfPosterior<'a>, RunError>;
}

/// What the stage runs on.
pub struct LoopInputs<'a> {
    /// The structural model (its points: the sensor-mass candidates; its `C_b`: the beam factor).
    pub built: &'a BuiltModel,
    /// The measured data of every level (the loop runs at those of [`DiagnoseParams::levels`]).
    pub levels: &'a [LevelData],
    /// One law per model of the study.
    pub laws: &'a [Box<dyn ConstitutiveModel>],
    /// The likelihood's engine, with every measured point an input (the point-mass candidates).
    pub engine: &'a dyn FrfEngine,
    pub posterior: &'a dyn LevelPosterior,
    /// Fits of the starting model from an earlier pass (the measured directions' pass before
    /// the three-direction one): a level with one starts its loop from it.
    pub starting_fits: &'a [crate::closed_loop::StartingFit],
}

pub(crate) use crate::stage::input_error as key_error;
