//! The pre-flight: what `rfmlab run`, `rfmlab diagnose` and `rfmlab check` check before
//! anything is fitted. [`check_settings`] (at least one model, a writable output folder) and
//! [`check_data`] (the data against the study: each level's files against the level, the
//! direction of every channel against its point, every point measured unless optional, the
//! analysis bands inside the data) run first in all three; `rfmlab check` adds the model's
//! first mode at the initial values against the data's first peak, the cost of the engine
//! and the mesh's remaining discretisation error per mode.
//!
//! The mesh-error estimate is [`super::mesh_error`]'s.

use super::{input_error, LevelData, RunError};
use crate::common::C64;
use crate::study::build::BuiltModel;
use crate::study::Band;
use crate::study::ModelSpec;
use std::path::Path;

pub use super::data::first_peak_hz;
pub use super::mesh_error::*;

/// Complex modes computed for the first-mode check.
pub const N_MODES_CHECKED: usize = 6;

/// The model's first mode and the data's first peak are "far apart" beyond this ratio.
pub const FIRST_MODE_RATIO_WARN: f64 = 1.5;

/// The engine's estimated cost.
#[derive(Clone, Debug, serde::Serialize)]
pub struct CostSummary {
    pub n_dof: usize,
    pub memory_bytes: f64,
    pub factor_seconds: f64,
    pub available_memory_bytes: f64,
}

/// What the pre-flight found besides hard errors.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct Preflight {
    pub warnings: Vec<String>,
    pub cost: Option<CostSummary>,
    /// Per mode: the mesh's discretisation error (meshed structures only).
    pub discretisation: Vec<ModeDiscretisation>,
    /// How the mesh was chosen and the error it leaves (meshed structures only).
    pub mesh: Option<crate::discretisation::Discretisation>,
    /// The model's first y mode at the initial values and the data's first peak (Hz).
    pub first_mode_hz: Option<f64>,
    pub first_peak_hz: Option<f64>,
}

/// Checks that need no model: at least one model, a writable output folder.
pub fn check_settings(
    models: &[ModelSpec],
    output_dir: &Path,
    file: &Path,
) -> Result<(), RunError> {
    if models.is_empty() {
        return Err(input_error(
            file,
            "models",
            "no [[models]] to identify: add at least one, e.g. [[models]] name = \"model1\" with [models.initial] E0 and h",
        ));
    }
    if let Err(e) = crate::output::contract::check_writable(output_dir) {
        return Err(input_error(
            file,
            "study.output_dir",
            format!(
                "the results folder {} cannot be written ({e}): choose a folder you can write to ([study] output_dir or -o/--output)",
                output_dir.display()
            ),
        ));
    }
    Ok(())
}

/// What [`check_data`] checks the data against: the study's points and measurements, and the
/// analysis bands.
pub struct DataChecks<'a> {
    /// The study file (errors name it).
    pub file: &'a Path,
    pub measurements: Option<&'a crate::study::Measurements>,
    /// The structure's points (their `optional` flags).
    pub points: &'a [crate::study::Point],
    pub band_constant: &'a [Band],
    pub iem: &'a [Band],
}

/// The data part of the pre-flight: every level loaded and checked against the study
/// ([`super::data::load_checked`]) and the analysis bands against its lines
/// ([`check_bands`]). Returns the levels and the warnings that bear on the results.
pub fn check_data(
    checks: &DataChecks<'_>,
    built: &BuiltModel,
) -> Result<super::data::LoadedLevels, RunError> {
    let mut loaded =
        super::data::load_checked(checks.measurements, built, checks.points, checks.file)?;
    check_bands(
        checks.band_constant,
        checks.iem,
        checks.file,
        &loaded.levels,
        &mut loaded.warnings,
    )?;
    Ok(loaded)
}

/// The analysis bands against each level's lines: an error when a band holds no line of a
/// level, a warning when it reaches beyond the data.
pub fn check_bands(
    band_constant: &[Band],
    iem: &[Band],
    file: &Path,
    levels: &[LevelData],
    warnings: &mut Vec<String>,
) -> Result<(), RunError> {
    let bands = band_constant
        .iter()
        .enumerate()
        .map(|(i, b)| (format!("analyses.band_constant[{i}]"), b))
        .chain(
            iem.iter()
                .enumerate()
                .map(|(i, b)| (format!("analyses.iem[{i}]"), b)),
        );
    for (key, b) in bands {
        let (lo, hi) = (
            b.center_hz - 0.5 * b.width_hz,
            b.center_hz + 0.5 * b.width_hz,
        );
        for level in levels {
            let (f0, f1) = match (level.freq_hz.first(), level.freq_hz.last()) {
                (Some(&a), Some(&z)) => (a, z),
                _ => continue,
            };
            let inside = level
                .freq_hz
                .iter()
                .filter(|&&f| f >= lo && f <= hi)
                .count();
            if inside == 0 {
                return Err(input_error(
                    file,
                    key,
                    format!(
                        "the band {lo}-{hi} Hz holds no line of level {} (its data cover {f0}-{f1} Hz within measurements.band_hz): move center_hz inside the data",
                        level.name
                    ),
                ));
            }
            if lo < f0 || hi > f1 {
                warnings.push(format!(
                    "{key}: the band {lo}-{hi} Hz reaches beyond level {}'s data ({f0}-{f1} Hz); only its {inside} line(s) inside are used",
                    level.name
                ));
            }
        }
    }
    Ok(())
}

/// The structure's points against each level's channels: a note for each optional point
/// without a channel (a required one is an error of [`check_data`]).
pub fn check_channels(built: &BuiltModel, levels: &[LevelData], warnings: &mut Vec<String>) {
    for level in levels {
        let missing: Vec<u32> = built
            .model
            .points
            .iter()
            .map(|p| p.id)
            .filter(|id| !level.response_ids.contains(id))
            .collect();
        if !missing.is_empty() {
            warnings.push(format!(
                "structure.points: optional point(s) {missing:?} have no channel in level {}'s files, which hold responses {:?} to the excitation at point {}; they are not used",
                level.name, level.response_ids, level.reference_id
            ));
        }
    }
}

/// The first model's first y-dominant mode at its initial values (modulus at the data's
/// first peak) against that peak: a warning when they are more than a factor
/// [`FIRST_MODE_RATIO_WARN`] apart.
pub fn check_first_mode(
    models: &[ModelSpec],
    built: &BuiltModel,
    levels: &[LevelData],
    laws: &[Box<dyn crate::material::ConstitutiveModel>],
    out: &mut Preflight,
) -> Result<(), RunError> {
    let (Some(level), Some(spec), Some(law)) = (levels.first(), models.first(), laws.first())
    else {
        return Ok(());
    };
    let Some(peak) = first_peak_hz(level) else {
        return Ok(());
    };
    let e: C64 = law.modulus(&spec.initial, std::f64::consts::TAU * peak);
    // real modes at the storage modulus (a Cholesky and a Lanczos run, seconds on a refined
    // mesh; the loss modulus moves the frequencies far less than the factor checked here); the
    // first with most of its kinetic energy along y (every mode counts without DOF axes)
    let y_only = if built.dof_axes.is_some() {
        [false, true, false]
    } else {
        [true; 3]
    };
    let (freqs, _, y_share) =
        crate::discretisation::modes_with_shares(&built.model, e.re, N_MODES_CHECKED, &y_only)
            .map_err(|err| {
                RunError::Engine(format!("the model's modes at the initial values: {err}"))
            })?;
    let first = freqs
        .iter()
        .zip(&y_share)
        .find(|(_, &s)| s > 0.5)
        .map(|(&f, _)| f);
    out.first_peak_hz = Some(peak);
    out.first_mode_hz = first;
    if let Some(f) = first {
        let r = f / peak;
        if !(1.0 / FIRST_MODE_RATIO_WARN..=FIRST_MODE_RATIO_WARN).contains(&r) {
            out.warnings.push(format!(
                "the model's first y mode at {}'s initial values is at {f:.2} Hz but level {}'s first peak is at {peak:.2} Hz: check [structure] (the data may belong to another joint) and models[0].initial",
                spec.name, level.name
            ));
        }
    }
    Ok(())
}
