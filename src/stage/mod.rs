//! What every stage of a run shares: the measured data of a level ([`LevelData`]) as the
//! identification, the inference and the closed loop read it, the progress events of long
//! steps ([`Event`]) and the run's error ([`RunError`]).

use crate::common::C64;
use crate::data::DataError;
use crate::study::StudyError;

pub mod data;
pub mod engine;
pub mod measurement;
pub mod mesh_error;
pub mod model;
pub mod preflight;
pub mod rom_engine;
pub mod setup;

/// Progress of a run, for progress bars.
#[derive(Clone, Debug, PartialEq)]
pub enum Event {
    /// A step started; `total` units of work follow (0 = unknown length).
    Start { step: String, total: u64 },
    /// One unit of the current step is done.
    Advance,
    /// The current step finished.
    Finish,
}

/// Errors of a run. [`RunError::is_input`] tells bad input (exit code 2) from other failures.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    #[error(transparent)]
    Study(#[from] StudyError),
    #[error(transparent)]
    Data(#[from] DataError),
    #[error("building the FRF engine failed: {0}")]
    Engine(String),
    #[error("{analysis} failed: {message}")]
    Analysis { analysis: String, message: String },
    #[error(transparent)]
    Output(#[from] crate::output::OutputError),
    #[error("figure: {0}")]
    Plot(#[from] crate::plot::PlotError),
    /// The executor's cancellation flag was set; nothing was written.
    #[error("the run was cancelled")]
    Cancelled,
}

impl RunError {
    /// True for errors caused by the study file or the data (the CLI exits with code 2).
    pub fn is_input(&self) -> bool {
        match self {
            RunError::Study(_) | RunError::Data(_) => true,
            // A refused or unwritable output folder is the user's choice of path.
            RunError::Output(o) => o.is_input(),
            _ => false,
        }
    }
}

/// Measured data of one level, reduced to what the identification uses.
#[derive(Clone, Debug)]
pub struct LevelData {
    pub name: String,
    /// Lines (Hz) inside the band.
    pub freq_hz: Vec<f64>,
    /// Response point ids, in the order of the column's outputs.
    pub response_ids: Vec<u32>,
    pub reference_id: u32,
    /// The measured accelerance column ((m/s^2)/N) on the band's lines.
    pub column: crate::rfm::MeasuredColumn,
    /// The law that made simulated data, from `measurements.truth`.
    pub truth: Option<LevelTruth>,
    /// Ordinary coherence per value, `[line * n_out + k]`, when every channel has it.
    pub coherence: Option<Vec<f64>>,
    /// Number of averaged blocks of the H1 estimate, when the file says.
    pub n_averages: Option<u32>,
    /// The H1 estimator's model on these lines with its grid chosen by convergence
    /// ([`crate::forward::Observation::converged_measurement`]), set with the engine (or
    /// before it, by [`crate::stage::setup::setup_with_grids`]); `None` before, or without an
    /// estimator (then [`crate::stage::measurement::measurement_model`] uses the default grid).
    pub measurement: Option<(crate::forward::MeasurementModel, crate::forward::GridChoice)>,
}

/// The constitutive law and parameters (in the law's order, SI) that made a simulated level.
#[derive(Clone, Debug)]
pub struct LevelTruth {
    /// The law's name as in the sidecar (`"model4"`, ...).
    pub law: String,
    pub model: std::sync::Arc<dyn crate::material::ConstitutiveModel>,
    pub params: Vec<f64>,
}

impl LevelTruth {
    /// E*(w) of the truth (Pa).
    pub fn modulus(&self, omega_rad_s: f64) -> C64 {
        self.model.modulus(&self.params, omega_rad_s)
    }
}

/// An input error of the study file `file` at `key` (the CLI exits with code 2).
pub fn input_error(
    file: &std::path::Path,
    key: impl Into<String>,
    message: impl Into<String>,
) -> RunError {
    RunError::Study(StudyError {
        file: file.display().to_string(),
        key: key.into(),
        message: message.into(),
    })
}

/// The environment variable that names one ROM cache folder for every study (studies of the
/// same joint then share their certified ROMs and term ROMs; a ROM's key holds every setting
/// it depends on).
pub const ROM_CACHE_ENV: &str = "RFMLAB_ROM_CACHE";

/// The folder of cached ROMs of a study whose results go to `output_dir` (`.rom-cache/`
/// beside it, or the folder `RFMLAB_ROM_CACHE` names): where `rfmlab run` keeps its certified
/// ROM and `rfmlab diagnose` its term ROM.
pub fn rom_cache_dir(output_dir: &std::path::Path) -> std::path::PathBuf {
    if let Some(dir) = std::env::var_os(ROM_CACHE_ENV).filter(|d| !d.is_empty()) {
        return std::path::PathBuf::from(dir);
    }
    output_dir
        .parent()
        .unwrap_or(std::path::Path::new("."))
        .join(".rom-cache")
}

/// `<dir>.<suffix>` next to `dir`.
pub fn sibling(dir: &std::path::Path, suffix: &str) -> std::path::PathBuf {
    let name = dir
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "results".into());
    dir.with_file_name(format!("{name}.{suffix}"))
}

/// The laws of `models`, checked against their initial values (errors name `models[i]`).
pub fn model_laws(
    models: &[crate::study::ModelSpec],
    file: &std::path::Path,
) -> Result<Vec<Box<dyn crate::material::ConstitutiveModel>>, RunError> {
    let mut laws = Vec::new();
    for (i, m) in models.iter().enumerate() {
        let law = crate::material::model_from_name(&m.name, m.branches)
            .map_err(|e| input_error(file, format!("models[{i}].name"), e.to_string()))?;
        crate::material::check_params(law.as_ref(), &m.initial)
            .map_err(|e| input_error(file, format!("models[{i}].initial"), e.to_string()))?;
        laws.push(law);
    }
    Ok(laws)
}
