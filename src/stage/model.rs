//! The structural model of a run and the check of every model's initial values on the full
//! model (`rfmlab check`, and before a run).

use super::{input_error, LevelData, RunError};
use crate::common::C64;
use crate::study::build::BuiltModel;
use crate::study::{ModelSpec, Structure};
use std::path::Path;

/// Build the structural model (errors name the study file `file`).
pub fn build(structure: &Structure, file: &Path) -> Result<BuiltModel, RunError> {
    build_with(structure, file, &|_| {})
}

/// [`build`] with a line per mesh of the refinement to `progress`.
pub fn build_with(
    structure: &Structure,
    file: &Path,
    progress: &dyn Fn(&str),
) -> Result<BuiltModel, RunError> {
    Ok(crate::study::build::build_model_with(
        structure,
        &file.display().to_string(),
        progress,
    )?)
}

/// Check every model's initial E*(w) at every line of each level it is fitted to: finite, a
/// positive storage modulus, a non-negative loss modulus and a magnitude in
/// [`crate::rfm::status::PHYSICAL_MODULUS_PA`] (beyond it Z is numerically singular). Z(w) = K_b + E*(w) S - w^2 M is
/// then regular at every line but an undamped resonance, which the RFM reports itself; the
/// law's own admissibility is checked with the study. This replaces a sparse LU of the full
/// model per line and model (minutes on a mesh refined to its tolerance) by the law alone.
pub fn check_initial_values(
    models: &[ModelSpec],
    file: &Path,
    levels: &[LevelData],
    laws: &[Box<dyn crate::material::ConstitutiveModel>],
) -> Result<usize, RunError> {
    let mut n_checked = 0;
    for level in levels {
        for (i, (m, law)) in models.iter().zip(laws).enumerate() {
            if !m.levels.contains(&level.name) {
                continue;
            }
            for (&w, &f) in level.column.omega_rad_s.iter().zip(&level.freq_hz) {
                let e: C64 = law.modulus(&m.initial, w);
                let (lo, hi) = crate::rfm::status::PHYSICAL_MODULUS_PA;
                if !(e.re.is_finite() && e.im.is_finite() && e.re > 0.0 && e.im >= 0.0) {
                    return Err(input_error(
                        file,
                        format!("models[{i}].initial"),
                        format!(
                            "the initial values of {} give E* = {:.4e} {:+.4e} j Pa at {f} Hz (level {}): a run needs a finite, positive storage modulus and a non-negative loss modulus at every line; choose different initial values",
                            m.name, e.re, e.im, level.name
                        ),
                    ));
                }
                if !(lo..=hi).contains(&e.norm()) {
                    return Err(input_error(
                        file,
                        format!("models[{i}].initial"),
                        format!(
                            "the initial values of {} give |E*| = {:.4e} Pa at {f} Hz (level {}), outside any adhesive's range ({lo:.0e}-{hi:.0e} Pa): the system would be numerically singular; choose different initial values",
                            m.name, e.norm(), level.name
                        ),
                    ));
                }
            }
        }
        n_checked += level.freq_hz.len();
    }
    Ok(n_checked)
}
