//! The deterministic identification of one level (no I/O): Model 1 over bands (case study 1),
//! circle fit + IEM (paper Tables 2-3, eq. 20), the global RFM per model (eq. 37, Tables 4-5)
//! with the correlation of the FRFs before and after (FRAC eq. 38, SCC eq. 39, ACC eq. 40),
//! the per-line RFM (eq. 10-11, Fig. 13/18) and the sensitivities (Fig. 9).
//!
//! Each analysis runs inside the leakage fixed point of [`leakage`] when the level's H1
//! estimator is known. Inputs are the stage's [`IdentificationParams`] and typed values (the
//! built model, the FRF engine, the level's data, the laws); the study file's path only
//! names the key of an input error. Checked by `tests/suite/paper_joint.rs`,
//! `tests/suite/rfm.rs`, `tests/suite/iem.rs`, `tests/suite/correlation.rs` and
//! `tests/suite/default_study.rs`.

mod bands;
mod global;
pub mod leakage;
mod response;

use crate::common::C64;
use crate::frf::FrfEngine;
use crate::iem::IemResult;
use crate::material::ConstitutiveModel;
use crate::modal::circle_fit::CircleFitResult;
use crate::rfm::{BandResult, PerLineEstimate, RfmParams, RfmResult};
use crate::stage::{Event, LevelData, RunError};
use crate::study::build::BuiltModel;
use crate::study::{Band, ModelSpec};
use leakage::Leakage;
use std::path::Path;

/// The deterministic identification stage (per level): per-line RFM, Model 1 over bands,
/// circle fit + IEM, global RFM per model, correlation, sensitivities.
#[derive(Clone, Debug, PartialEq)]
pub struct IdentificationParams {
    /// The laws identified by the global RFM, with their initial values (SI).
    pub models: Vec<ModelSpec>,
    /// The RFM iteration's stopping rules and SVD truncation.
    pub rfm: RfmParams,
    pub per_line: bool,
    pub correlation: bool,
    pub sensitivity: bool,
    /// The mesh's discretisation error per mode (Richardson; meshed joints only).
    pub mesh_error: bool,
    pub band_constant: Vec<Band>,
    pub iem: Vec<Band>,
}

/// What the identification of one level reads besides its parameters.
pub struct LevelInputs<'a> {
    pub built: &'a BuiltModel,
    pub engine: &'a dyn FrfEngine,
    pub level: &'a LevelData,
    /// One law per entry of [`IdentificationParams::models`].
    pub laws: &'a [Box<dyn ConstitutiveModel>],
    /// The H1 estimator, when the study states it: the identification then corrects for its
    /// leakage with the level's measurement model ([`crate::stage::measurement::measurement_model`]).
    pub estimator: Option<&'a crate::study::Estimator>,
    /// The study file, named by input errors.
    pub file: &'a Path,
    /// The modulus box the engine is certified over (the reduced model's), `None` for an
    /// engine valid at every modulus (the full model): a fit whose modulus leaves it is
    /// flagged ([`crate::rfm::status`]).
    pub certified: Option<&'a crate::rom::ModulusRange>,
}

/// Default initial modulus where a study gives none (Pa): the paper's IEM value, Level 1 mode 1.
pub const DEFAULT_E0: C64 = C64::new(6.974e6, 1.4827e6);

/// Model 1 (constant E*) over one band (case study 1).
#[derive(Clone, Debug)]
pub struct BandConstantResult {
    pub center_hz: f64,
    pub width_hz: f64,
    pub result: BandResult,
    /// Leakage-corrected passes (0 without `[measurements.estimator]`).
    pub leakage_passes: usize,
}

/// Circle fit (Table 2) and IEM (Table 3) around one resonance.
#[derive(Clone, Debug)]
pub struct IemBandResult {
    pub center_hz: f64,
    pub width_hz: f64,
    /// Response id of the FRF the circle fit used (the drive point when measured).
    pub response_id: u32,
    pub circle: CircleFitResult,
    /// The IEM result, or why it failed (the circle fit is kept either way).
    pub iem: Result<IemResult, IemFailed>,
    /// Leakage-corrected passes (0 without `[measurements.estimator]`); the circle fit is then
    /// of the corrected data.
    pub leakage_passes: usize,
}

/// The IEM failed around one resonance (the circle fit is kept).
#[derive(Clone, Debug, thiserror::Error)]
#[error("IEM around {center_hz} Hz at level {level} failed: {source}")]
pub struct IemFailed {
    pub center_hz: f64,
    pub level: String,
    pub source: crate::iem::IemError,
}

/// One global RFM run with the FRFs and correlation before and after.
#[derive(Clone, Debug)]
pub struct GlobalResult {
    pub result: RfmResult,
    /// Whether the fit is a result ([`crate::rfm::status::rfm_status`]): the one status the
    /// console, the tables and the report show.
    pub status: crate::rfm::FitStatus,
    /// Leakage-corrected passes (0 without `[measurements.estimator]`).
    pub leakage_passes: usize,
    /// The H1 estimator's leakage bias at the updated parameters, `[line][k]` flattened (empty
    /// without `[measurements.estimator]`).
    pub leakage_bias: Vec<C64>,
    /// Predicted measurement at the initial and updated parameters, `[line][k]` flattened
    /// like [`crate::rfm::MeasuredColumn::accelerance`]: the analytical accelerance, plus the H1
    /// estimator's leakage bias when the study states its estimator.
    pub initial_frf: Vec<C64>,
    pub updated_frf: Vec<C64>,
    /// E*(w) at the initial parameters (Pa), one per line.
    pub initial_modulus: Vec<C64>,
    pub frac_initial: Vec<f64>,
    pub frac_updated: Vec<f64>,
    pub scc_initial: Vec<f64>,
    pub acc_initial: Vec<f64>,
    pub scc_updated: Vec<f64>,
    pub acc_updated: Vec<f64>,
}

/// Normalised sensitivities |dH'_ij/dE'| E' / max|H'_ij| and |dH'_ij/dE''| E'' / max|H'_ij|
/// per FRF and line (the paper's Fig. 9), at the modulus `modulus` (Pa, per line).
#[derive(Clone, Debug)]
pub struct SensitivityCurves {
    /// Where the modulus came from, e.g. "model4 updated".
    pub at: String,
    pub modulus: Vec<C64>,
    /// `[k][line]`.
    pub storage: Vec<Vec<f64>>,
    pub loss: Vec<Vec<f64>>,
}

/// The deterministic identification of one level.
#[derive(Clone, Debug)]
pub struct Identification {
    pub level: String,
    pub per_line: Option<Vec<PerLineEstimate>>,
    /// The model whose leakage bias corrected the per-line data, if any.
    pub per_line_leakage_from: Option<String>,
    pub band_constant: Vec<BandConstantResult>,
    pub iem: Vec<IemBandResult>,
    pub global: Vec<GlobalResult>,
    pub sensitivity: Option<SensitivityCurves>,
}

pub(crate) fn analysis(name: impl Into<String>, e: impl std::fmt::Display) -> RunError {
    RunError::Analysis {
        analysis: name.into(),
        message: e.to_string(),
    }
}

/// Rows `[line][k]` of a flattened column.
fn rows(v: &[C64], n_out: usize) -> Vec<&[C64]> {
    v.chunks(n_out).collect()
}

/// FRF k of a flattened `[line][k]` array.
pub fn frf_of(v: &[C64], n_out: usize, k: usize) -> Vec<C64> {
    v.iter().skip(k).step_by(n_out).copied().collect()
}

/// What the analyses of one level share.
struct Level<'a> {
    params: &'a IdentificationParams,
    inputs: &'a LevelInputs<'a>,
    leak: Option<Leakage<'a>>,
    /// The starting E* of Model 1 (Pa): its initial values, else [`DEFAULT_E0`].
    model1_e0: C64,
}

/// E* constant over the lines (Model 1's modulus as a function of its two parameters).
fn constant(p: &[f64], _w: f64) -> C64 {
    C64::new(p[0], p[1])
}

/// Run every analysis `params` asks for on one level.
pub fn analyse_level(
    params: &IdentificationParams,
    inputs: &LevelInputs<'_>,
    progress: &(dyn Fn(Event) + Sync),
) -> Result<Identification, RunError> {
    let col = &inputs.level.column;
    let lname = &inputs.level.name;
    // A starting modulus per line: the first model's initial E*(w), else the default.
    let first_model = params
        .models
        .iter()
        .zip(inputs.laws)
        .find(|(m, _)| m.levels.contains(lname));
    let e_start: Vec<C64> = match first_model {
        Some((m, law)) => col
            .omega_rad_s
            .iter()
            .map(|&w| law.modulus(&m.initial, w))
            .collect(),
        None => vec![DEFAULT_E0; col.n_lines()],
    };
    let model1_e0 = params
        .models
        .iter()
        .find(|m| m.name.eq_ignore_ascii_case("model1"))
        .map(|m| C64::new(m.initial[0], m.initial[1]))
        .unwrap_or(DEFAULT_E0);
    let ctx = Level {
        params,
        inputs,
        leak: crate::stage::measurement::measurement_model(
            inputs.estimator,
            inputs.level,
            inputs.file,
        )?
        .map(|measurement| Leakage {
            engine: inputs.engine,
            measurement,
        }),
        model1_e0,
    };
    let band_constant = bands::band_constant(&ctx)?;
    let iem = bands::iem(&ctx, &band_constant, progress)?;
    let global = global::global_models(&ctx, progress)?;
    let (per_line, per_line_leakage_from) = if params.per_line {
        let (r, from) = response::per_line(&ctx, &global, &e_start, progress)?;
        (Some(r), from)
    } else {
        (None, None)
    };
    let sensitivity = if params.sensitivity {
        Some(response::sensitivity(&ctx, &global, &e_start)?)
    } else {
        None
    };
    Ok(Identification {
        level: lname.clone(),
        per_line,
        per_line_leakage_from,
        band_constant,
        iem,
        global,
        sensitivity,
    })
}
