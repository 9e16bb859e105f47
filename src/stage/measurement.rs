//! The H1 estimator of a level's data as the identification and the likelihood model it:
//! its settings on the level's lines and the measurement model ([`crate::forward::measurement`]).

use super::{input_error, LevelData, RunError};
use crate::forward::{EstimatorSpec, MeasurementModel, MeasurementParams};
use crate::study::Estimator;
use std::path::Path;

/// The H1 estimator's settings on the lines `freq_hz`.
pub fn estimator_spec(estimator: &Estimator, freq_hz: &[f64]) -> EstimatorSpec {
    let lo = freq_hz.first().copied().unwrap_or(0.0);
    let hi = freq_hz.last().copied().unwrap_or(0.0);
    EstimatorSpec {
        window: estimator.window,
        block_s: estimator.block_s,
        fs_hz: estimator.fs_hz,
        force_band_hz: estimator.force_band((lo, hi)),
        shaker: estimator.shaker,
    }
}

/// The measurement model of a level, when the study states its estimator: the one chosen with
/// the engine ([`LevelData::measurement`]), else on the default grid.
pub fn measurement_model(
    estimator: Option<&Estimator>,
    level: &LevelData,
    file: &Path,
) -> Result<Option<MeasurementModel>, RunError> {
    let Some(est) = estimator else {
        return Ok(None);
    };
    if let Some((m, _)) = &level.measurement {
        return Ok(Some(m.clone()));
    }
    MeasurementModel::new(
        estimator_spec(est, &level.freq_hz),
        &level.freq_hz,
        &MeasurementParams::default(),
    )
    .map(Some)
    .map_err(|e| input_error(file, "measurements.estimator", e.to_string()))
}
