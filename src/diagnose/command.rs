//! `rfmlab diagnose`: a study's closed loop into a results folder of its own
//! (`<output_dir>.diagnose/`). The model, the data and the engine are built as a run builds
//! them, with every measured point an engine input (the point-mass candidates), then the stage
//! runs ([`super::loop_stage`]) and writes its tables, figures and markdown.
//!
//! These are the entry points of the CLI and the Python binding: they take the study, make the
//! stage's params from it ([`DiagnoseParams::of`]) and build the engine with the run's
//! functions ([`crate::stage::setup::setup`]).

use super::of_study::{no_inference, wants_sensor_mass, StudyPosterior};
use super::params::{DiagnoseParams, LoopInputs};
use super::summary::DiagnoseSummary;
use crate::closed_loop::ClosedLoopParams;
use crate::output::ResultsDir;
use crate::stage::RunError;
use crate::study::Study;
use std::path::Path;

/// Run the loop on `study` (model `model`, else the first of `[inference] models`); results in
/// `<output_dir>.diagnose/`.
pub fn diagnose_study(
    study: &Study,
    model: Option<&str>,
    params: &ClosedLoopParams,
) -> Result<DiagnoseSummary, RunError> {
    let out = crate::stage::sibling(&study.output_dir, "diagnose");
    let parent = out.parent().unwrap_or(Path::new("."));
    let dir_name = out
        .file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "diagnose".into());
    diagnose_into(study, model, params, parent, &dir_name, true)
}

/// [`diagnose_study`] into `<parent>/<dir_name>/`, with the residual figures when `figures`.
pub fn diagnose_into(
    study: &Study,
    model: Option<&str>,
    params: &ClosedLoopParams,
    parent: &Path,
    dir_name: &str,
    figures: bool,
) -> Result<DiagnoseSummary, RunError> {
    let t0 = std::time::Instant::now();
    let mut with_loop = study.clone();
    // A sensor's mass acts in x, y and z: when `[closed_loop] candidates` names the
    // sensor-mass candidate, the other two directions of every measured point of a meshed
    // joint become model points (and engine inputs) for it. Opt-in: the engine's inputs
    // triple, and its reduced basis with them (minutes to build on the paper's joint).
    if crate::study::build::joint_spec(&with_loop.structure).is_some() && wants_sensor_mass(study) {
        with_loop.structure.points = with_all_directions(&with_loop.structure.points);
    }
    let study = &with_loop;
    if study.inference.is_none() {
        return Err(no_inference(study));
    }
    let crate::stage::setup::Setup {
        laws,
        built,
        levels,
        engines,
    } = crate::stage::setup::setup(
        study,
        // The loop's candidate masses act at every measured point.
        Some(crate::stage::engine::LikelihoodInputs::EveryMeasuredPoint),
        None,
    )?;
    let engine = engines
        .likelihood
        .as_deref()
        .unwrap_or(engines.engine.as_ref());
    let p = DiagnoseParams::of(study, model)?;
    let inputs = LoopInputs {
        built: &built,
        levels: &levels,
        laws: &laws,
        engine,
        posterior: &StudyPosterior(study),
    };
    let mut outcome = super::loop_stage(&p, params, &inputs)?;
    let mut dir = ResultsDir::create(parent, dir_name).map_err(RunError::Output)?;
    super::write_loop(&mut dir, &outcome, &study.name, figures)?;
    outcome.summary.output_dir = dir.path().to_path_buf();
    outcome.summary.seconds = t0.elapsed().as_secs_f64();
    Ok(outcome.summary)
}

/// `points` with, for every point, the two other axes' directions at the same position (same
/// id, after the declared points so that a point's id still names its measured direction).
fn with_all_directions(points: &[crate::study::Point]) -> Vec<crate::study::Point> {
    use crate::common::{Axis, Direction};
    let mut out = points.to_vec();
    for p in points {
        for axis in [Axis::X, Axis::Y, Axis::Z] {
            if !out.iter().any(|q| q.id == p.id && q.direction.axis == axis) {
                out.push(crate::study::Point {
                    direction: Direction::new(axis, 1),
                    ..p.clone()
                });
            }
        }
    }
    out
}
