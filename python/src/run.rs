//! `study.run()`: the in-memory pipeline on a worker thread, with the GIL released. The calling
//! thread waits in slices of 100 ms; between slices it forwards progress events to the Python
//! callback and checks for signals (Ctrl-C), which set the executor's cancel flag: the pipeline
//! stops at its next check and the call raises `KeyboardInterrupt`.
//!
//! Each result table crosses to Python as parquet bytes written in memory (the polars frame is
//! rebuilt from them on the Python side); nothing is read back from disk.

use super::{error, run_error};
use polars::prelude::{DataFrame, ParquetWriter};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyTuple};
use rfmlab::runner::RunError;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::sync::Arc;
use std::time::Duration;

/// A progress event for the Python callback: (step, done, total); total 0 = unknown length.
pub(crate) enum Progress {
    Start(String, u64),
    Advance,
    Finish,
}

/// What the worker hands back: tables and the files written (relative to the output folder).
pub(crate) struct Outcome {
    pub tables: Vec<(String, DataFrame)>,
    pub files: Vec<String>,
}

fn parquet_bytes(df: &DataFrame) -> Result<Vec<u8>, String> {
    let mut buf = Vec::new();
    let mut df = df.clone();
    ParquetWriter::new(&mut buf)
        .finish(&mut df)
        .map_err(|e| e.to_string())?;
    Ok(buf)
}

/// Run `work` on a worker thread with the GIL released, forwarding its progress events to
/// `callback` (called as `callback(step, done, total)`) and turning Ctrl-C (or an exception in
/// the callback) into the cancel flag; the exception is raised once the worker has stopped.
pub(crate) fn drive<T, W>(py: Python<'_>, callback: Option<Py<PyAny>>, work: W) -> PyResult<T>
where
    T: Send,
    W: FnOnce(mpsc::Sender<Progress>, Arc<AtomicBool>) -> T + Send,
{
    let cancel = Arc::new(AtomicBool::new(false));
    let (tx, rx) = mpsc::channel::<Progress>();
    let (mut step, mut done, mut total) = (String::new(), 0u64, 0u64);
    std::thread::scope(|s| -> PyResult<T> {
        let cancel_w = cancel.clone();
        let worker = s.spawn(move || work(tx, cancel_w));
        let mut interrupted: Option<PyErr> = None;
        loop {
            // Wait without the GIL; then, with it, report progress and look for Ctrl-C.
            let got = py.detach(|| rx.recv_timeout(Duration::from_millis(100)));
            let mut events = Vec::new();
            match got {
                Ok(ev) => {
                    events.push(ev);
                    events.extend(rx.try_iter());
                }
                Err(mpsc::RecvTimeoutError::Timeout) => {}
                Err(mpsc::RecvTimeoutError::Disconnected) => break,
            }
            for ev in events {
                match ev {
                    Progress::Start(st, t) => {
                        step = st;
                        done = 0;
                        total = t;
                    }
                    Progress::Advance => done += 1,
                    Progress::Finish => done = total,
                }
                if let (Some(cb), None) = (&callback, &interrupted) {
                    if let Err(e) = cb.call1(py, (step.clone(), done, total)) {
                        // A failing callback stops the run like Ctrl-C, and its error is raised.
                        cancel.store(true, Ordering::SeqCst);
                        interrupted = Some(e);
                    }
                }
            }
            if interrupted.is_none() {
                if let Err(e) = py.check_signals() {
                    cancel.store(true, Ordering::SeqCst);
                    interrupted = Some(e);
                }
            }
        }
        let r = py.detach(|| worker.join());
        if let Some(e) = interrupted {
            return Err(e);
        }
        r.map_err(|_| {
            error(
                py,
                "RunError",
                ("the computation stopped on an internal error (a panic); please report it with the study file",),
            )
        })
    })
}

pub(crate) fn run<'py>(
    py: Python<'py>,
    study: &rfmlab::study::Study,
    output: Option<PathBuf>,
    callback: Option<Py<PyAny>>,
    figures: bool,
    rom_cache: bool,
) -> PyResult<Bound<'py, PyTuple>> {
    let outcome = drive(py, callback, |tx, cancel| {
        execute(study, output.as_deref(), figures, rom_cache, tx, cancel)
    })?;
    let outcome = outcome.map_err(|e| run_error(py, &e))?;
    let mut names = Vec::new();
    let mut blobs = Vec::new();
    for (name, df) in &outcome.tables {
        let bytes = py
            .detach(|| parquet_bytes(df))
            .map_err(|m| error(py, "RunError", (format!("table {name}: {m}"),)))?;
        names.push(name.clone());
        blobs.push(PyBytes::new(py, &bytes));
    }
    (names, blobs, outcome.files).into_pyobject(py)
}

/// The closed loop (`rfmlab diagnose`) on the worker thread: its summary as JSON text. The
/// loop writes its tables and figures into `<parent>/<dir_name>`; without `output` that is a
/// temporary folder removed afterwards (the summary holds the before/after comparison).
pub(crate) fn diagnose(
    py: Python<'_>,
    study: &rfmlab::study::Study,
    model: Option<String>,
    threshold_nats: Option<f64>,
    output: Option<PathBuf>,
    figures: bool,
    callback: Option<Py<PyAny>>,
) -> PyResult<String> {
    use rfmlab::closed_loop::{ClosedLoopParams, Progress as LoopProgress};
    let r = drive(py, callback, move |tx, _cancel| {
        let from_study = rfmlab::runner::closed_loop::params_of(study);
        let tx = std::sync::Mutex::new(tx);
        let params = ClosedLoopParams {
            threshold_nats: threshold_nats.unwrap_or(from_study.threshold_nats),
            progress: LoopProgress::new(move |m| {
                if let Ok(t) = tx.lock() {
                    let _ = t.send(Progress::Start(m.to_string(), 0));
                }
            }),
            ..from_study
        };
        let (parent, name, temporary) = match &output {
            Some(o) => (
                o.parent().map(|p| p.to_path_buf()).unwrap_or_default(),
                o.file_name()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_else(|| "diagnose".into()),
                None,
            ),
            None => {
                let t = std::env::temp_dir().join(format!(
                    "rfmlab-diagnose-{}-{}",
                    std::process::id(),
                    std::time::SystemTime::now()
                        .duration_since(std::time::UNIX_EPOCH)
                        .map(|d| d.as_nanos())
                        .unwrap_or(0)
                ));
                (t.clone(), "diagnose".to_string(), Some(t))
            }
        };
        let s = rfmlab::runner::closed_loop::diagnose_into(
            study,
            model.as_deref(),
            &params,
            &parent,
            &name,
            figures && output.is_some(),
        );
        if let Some(t) = temporary {
            let _ = std::fs::remove_dir_all(t);
        }
        s
    })?;
    let s = r.map_err(|e| run_error(py, &e))?;
    serde_json::to_string(&s).map_err(|e| error(py, "RunError", (e.to_string(),)))
}

/// The pipeline itself (on the worker thread).
pub(crate) fn execute(
    _study: &rfmlab::study::Study,
    _output: Option<&std::path::Path>,
    _figures: bool,
    _rom_cache: bool,
    _tx: mpsc::Sender<Progress>,
    _cancel: Arc<AtomicBool>,
) -> Result<Outcome, RunError> {
    Err(RunError::Engine(
        "the in-memory pipeline is not available in this build".into(),
    ))
}
