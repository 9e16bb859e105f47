//! `study.design()`: plan the test as `rfmlab design` does, on a worker thread with the GIL
//! released (see `run::drive`). The progress lines go to the Python callback as steps of
//! unknown length; the search has no cancellation point, so Ctrl-C is honoured when it ends.
//!
//! What crosses to Python: a dict with the best and the study's own design (drive, sensors,
//! predicted relative sds per model, level and parameter, worst sd, information gain), the
//! design tables as parquet bytes (`design`, `design_candidates`), the notes, the timings and
//! the report's markdown.

use super::run::{drive, parquet_bytes, Progress};
use super::{error, study_error};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict};
use rfmlab::design::{DesignError, DesignResult, Evaluated};
use rfmlab::study::{Study, StudyError};
use std::path::PathBuf;

/// The options of `study.design()`.
pub(crate) struct DesignArgs {
    /// Folder to write the design's files into (nothing is written without it).
    pub output: Option<PathBuf>,
    /// Response sensors per design (overrides `[design] sensors`).
    pub sensors: Option<usize>,
    /// Replace `output` even when rfmlab did not write it.
    pub force: bool,
}

/// Why `study.design()` failed, before it becomes a Python exception.
enum Failure {
    Study(StudyError),
    Other(String),
}

/// What the worker hands back.
struct Outcome {
    result: DesignResult,
    designs: Vec<u8>,
    candidates: Vec<u8>,
    report: String,
}

/// `study` with the `sensors` override applied to its `[design]` section
/// ([`rfmlab::design::with_sensors`], as `rfmlab design --sensors` does).
fn with_sensors(study: &Study, sensors: Option<usize>) -> Result<Study, StudyError> {
    match sensors {
        None => Ok(study.clone()),
        Some(k) => rfmlab::design::with_sensors(study, k),
    }
}

fn table_bytes(
    t: Result<rfmlab::output::Table, rfmlab::output::OutputError>,
) -> Result<Vec<u8>, Failure> {
    let df = t
        .and_then(|t| t.to_dataframe())
        .map_err(|e| Failure::Other(e.to_string()))?;
    parquet_bytes(&df).map_err(Failure::Other)
}

/// The design itself (on the worker thread): the output claimed first, then the search, the
/// files when asked, the tables and the report.
fn execute(
    study: &Study,
    args: &DesignArgs,
    tx: std::sync::mpsc::Sender<Progress>,
) -> Result<Outcome, Failure> {
    let study = with_sensors(study, args.sensors).map_err(Failure::Study)?;
    let replace = rfmlab::output::Replace::forced(args.force);
    // The output contract before anything is computed.
    if let Some(out) = &args.output {
        rfmlab::output::claim_folder(out, replace).map_err(|e| Failure::Other(e.to_string()))?;
    }
    let tx = std::sync::Mutex::new(tx);
    let progress = move |m: &str| {
        if let Ok(t) = tx.lock() {
            let _ = t.send(Progress::Start(m.to_string(), 0));
        }
    };
    let r = rfmlab::design::design(&study, &progress).map_err(|e| match e {
        DesignError::Study(s) => Failure::Study(s),
        e => Failure::Other(e.to_string()),
    })?;
    if let Some(out) = &args.output {
        rfmlab::design::write::write(&r, &study.file, study.seed, out, replace)
            .map_err(|e| Failure::Other(e.to_string()))?;
    }
    Ok(Outcome {
        designs: table_bytes(rfmlab::design::write::designs_table(&r))?,
        candidates: table_bytes(rfmlab::design::write::candidates_table(&r))?,
        report: rfmlab::design::write::markdown(&r, None).to_markdown(),
        result: r,
    })
}

/// A scored design as a dict: drive, sensors ("id +axis"), `sd_rel[model][level][parameter]`,
/// worst_sd_rel, info_gain (nats), own_masses.
fn evaluated<'py>(
    py: Python<'py>,
    r: &DesignResult,
    e: &Evaluated,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("drive", e.drive)?;
    let sensors: Vec<String> = e.channels.iter().map(|&c| r.label(c)).collect();
    d.set_item("sensors", sensors)?;
    let sd = PyDict::new(py);
    for (mi, model) in r.models.iter().enumerate() {
        let per_level = PyDict::new(py);
        for (li, level) in r.levels.iter().enumerate() {
            let per_param = PyDict::new(py);
            for (pi, p) in r.params[mi].iter().enumerate() {
                per_param.set_item(p, e.score.rel_sd[mi][li][pi])?;
            }
            per_level.set_item(level, per_param)?;
        }
        sd.set_item(model, per_level)?;
    }
    d.set_item("sd_rel", sd)?;
    d.set_item("worst_sd_rel", e.score.worst)?;
    d.set_item("info_gain", e.score.info_gain)?;
    d.set_item("own_masses", e.own_masses)?;
    Ok(d)
}

pub(crate) fn design<'py>(
    py: Python<'py>,
    study: &Study,
    args: DesignArgs,
    callback: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    let outcome = drive(py, callback, |tx, _cancel| execute(study, &args, tx))?;
    let o = outcome.map_err(|f| match f {
        Failure::Study(s) => study_error(py, &s),
        Failure::Other(m) => error(py, "RunError", (m,)),
    })?;
    let r = &o.result;
    let d = PyDict::new(py);
    d.set_item("models", r.models.clone())?;
    d.set_item("levels", r.levels.clone())?;
    d.set_item("params", r.params.clone())?;
    d.set_item("best", evaluated(py, r, &r.best)?)?;
    match &r.current {
        Some(c) => d.set_item("current", evaluated(py, r, c)?)?,
        None => d.set_item("current", py.None())?,
    }
    d.set_item("notes", r.notes.clone())?;
    d.set_item("timings", r.timings.clone())?;
    d.set_item("table", PyBytes::new(py, &o.designs))?;
    d.set_item("candidates", PyBytes::new(py, &o.candidates))?;
    d.set_item("report", o.report.clone())?;
    Ok(d)
}
