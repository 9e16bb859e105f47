//! Samplers of the `[inference]` part of a run (NUTS and TMCMC through [`crate::inference`]).

use super::bayes::SamplerResult;
use super::{Event, LevelData, RunError};
use crate::inference::likelihood::FrfPosterior;
use crate::inference::map::MapResult;
use crate::study::inference::Inference;
use crate::study::Study;

#[allow(clippy::too_many_arguments)]
pub fn run_samplers(
    _study: &Study,
    _inf: &Inference,
    _post: &FrfPosterior<'_>,
    _map: &MapResult,
    _seed: u64,
    _level: &LevelData,
    _model: &str,
    _progress: &(dyn Fn(Event) + Sync),
) -> Result<Vec<SamplerResult>, RunError> {
    Ok(Vec::new())
}
