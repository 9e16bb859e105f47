//! The structural model of a run and the check of every model's initial values on the full
//! model (`rfmlab check`, and before a run).

use super::{input_error, LevelData, RunError};
use crate::common::C64;
use crate::frf::FrfEngine;
use crate::study::build::BuiltModel;
use crate::study::{ModelSpec, Structure};
use std::path::Path;

/// Build the structural model (errors name the study file `file`).
pub fn build(structure: &Structure, file: &Path) -> Result<BuiltModel, RunError> {
    Ok(crate::study::build::build_model(
        structure,
        &file.display().to_string(),
    )?)
}

/// Evaluate the full model at every model's initial E*(w) on 3 lines of each level
/// (both band ends included): a singular or ill-conditioned Z is an input error naming the model.
pub fn check_initial_values(
    models: &[ModelSpec],
    file: &Path,
    built: &BuiltModel,
    levels: &[LevelData],
    laws: &[Box<dyn crate::material::ConstitutiveModel>],
) -> Result<usize, RunError> {
    let full = crate::frf::FullModel::new(
        &built.model,
        &[built.excitation],
        crate::frf::FullParams::default(),
    )
    .map_err(|e| RunError::Engine(e.to_string()))?;
    let mut n_checked = 0;
    for level in levels {
        let n = level.freq_hz.len();
        // Band ends and centre: a sparse LU per line on the full model is the expensive part
        // of `rfmlab check`, and a law that is admissible (check_params) cannot make Z
        // singular in between except at an undamped resonance, which the RFM reports itself.
        let picks: Vec<usize> = if n <= 3 {
            (0..n).collect()
        } else {
            vec![0, n / 2, n - 1]
        };
        let omega: Vec<f64> = picks.iter().map(|&l| level.column.omega_rad_s[l]).collect();
        for (i, (m, law)) in models.iter().zip(laws).enumerate() {
            if !m.levels.contains(&level.name) {
                continue;
            }
            let moduli: Vec<C64> = omega.iter().map(|&w| law.modulus(&m.initial, w)).collect();
            let sw = full.sweep(&omega, &moduli, false).map_err(|e| {
                input_error(
                    file,
                    format!("models[{i}].initial"),
                    format!(
                        "the initial values of {} make the system singular at level {}: {e}; choose different initial values",
                        m.name, level.name
                    ),
                )
            })?;
            if sw.h.iter().any(|z| !(z.re.is_finite() && z.im.is_finite())) {
                return Err(input_error(
                    file,
                    format!("models[{i}].initial"),
                    format!(
                        "the initial values of {} give non-finite FRFs at level {}; choose different initial values",
                        m.name, level.name
                    ),
                ));
            }
        }
        n_checked += omega.len();
    }
    Ok(n_checked)
}
