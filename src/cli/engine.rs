//! Choosing the FRF engine (full model or certified ROM) for CLI commands.

use super::common::Global;
use rfmlab::fe::StructuralModel;
use rfmlab::frf::full::{FullModel, FullParams};
use rfmlab::frf::FrfEngine;
use rfmlab::study::experiment::Experiment;

/// The engine that drives a virtual experiment (all points as outputs, the drive point as input).
pub fn plant_engine(model: &StructuralModel, excitation: usize, _ex: &Experiment, _g: &Global) -> anyhow::Result<Box<dyn FrfEngine>> {
    Ok(Box::new(FullModel::new(model, &[excitation], FullParams::default())?))
}
