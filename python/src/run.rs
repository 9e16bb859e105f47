//! `study.run()`: the in-memory pipeline on a worker thread, with the GIL released. The calling
//! thread waits in slices of 100 ms; between slices it forwards progress events to the Python
//! callback and checks for signals (Ctrl-C), which set the executor's cancel flag: the pipeline
//! stops at its next check and the call raises `KeyboardInterrupt`.
//!
//! Each result table crosses to Python as parquet bytes written in memory (the polars frame is
//! rebuilt from them on the Python side); nothing is read back from disk.

use super::{error, run_error};
use polars_core::prelude::DataFrame;
use polars_io::parquet::write::ParquetWriter;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyTuple};
use rfmlab::stage::RunError;
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
    /// The closed loop's summary (JSON), when the plan ran it.
    pub closed_loop: Option<String>,
}

pub(crate) fn parquet_bytes(df: &DataFrame) -> Result<Vec<u8>, String> {
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
    // Behind a mutex so that the wait without the GIL may borrow it.
    let rx = std::sync::Mutex::new(rx);
    let (mut step, mut done, mut total) = (String::new(), 0u64, 0u64);
    std::thread::scope(|s| -> PyResult<T> {
        let cancel_w = cancel.clone();
        let worker = s.spawn(move || work(tx, cancel_w));
        let mut interrupted: Option<PyErr> = None;
        loop {
            // Wait without the GIL; then, with it, report progress and look for Ctrl-C.
            let got = py.detach(|| {
                let rx = rx.lock().unwrap_or_else(|e| e.into_inner());
                rx.recv_timeout(Duration::from_millis(100))
                    .map(|ev| std::iter::once(ev).chain(rx.try_iter()).collect::<Vec<_>>())
            });
            let mut events = Vec::new();
            match got {
                Ok(evs) => events = evs,
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
    args: RunArgs,
    callback: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyTuple>> {
    let outcome = drive(py, callback, |tx, cancel| execute(study, &args, tx, cancel))?;
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
    (names, blobs, outcome.files, outcome.closed_loop).into_pyobject(py)
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
        let from_study = rfmlab::diagnose::params_of(study);
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
        let s = rfmlab::diagnose::diagnose_into(
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

/// The pipeline itself (on the worker thread): plan, run, and write when asked. `closed_loop`
/// overrides whether the plan runs the closed loop (None: as the study says; the loop takes
/// the study's `[closed_loop]` settings, else the defaults).
pub(crate) fn execute(
    study: &rfmlab::study::Study,
    opts: &RunArgs,
    tx: mpsc::Sender<Progress>,
    cancel: Arc<AtomicBool>,
) -> Result<Outcome, RunError> {
    use rfmlab::pipeline::{Event, Executor};
    let mut plan = study.plan()?;
    plan.figures = plan.figures && opts.figures;
    match opts.closed_loop {
        Some(true) if plan.closed_loop.is_none() => {
            if study.inference.is_none() {
                return Err(RunError::Study(rfmlab::study::StudyError {
                    file: study.file.display().to_string(),
                    key: "inference".into(),
                    message: "the closed loop needs an [inference] section (its noise model and priors define the likelihood the loop tests); add one as in studies/bayes.toml".into(),
                }));
            }
            plan.closed_loop = Some(rfmlab::diagnose::params_of(study));
        }
        Some(false) => plan.closed_loop = None,
        _ => {}
    }
    let tx = std::sync::Mutex::new(tx);
    let mut ex = Executor::new()
        .with_cancel_flag(cancel)
        .observer(move |e: &Event| {
            let p = match e {
                Event::Start { step, total } => Progress::Start(step.clone(), *total),
                Event::Advance => Progress::Advance,
                Event::Finish => Progress::Finish,
            };
            if let Ok(t) = tx.lock() {
                let _ = t.send(p);
            }
        });
    if opts.rom_cache {
        ex = ex.rom_cache(rfmlab::stage::rom_cache_dir(&study.output_dir));
    }
    let results = rfmlab::pipeline::run(&plan, &mut ex)?;
    let files = match &opts.output {
        Some(dir) => rfmlab::report::write(&results, dir)?.files,
        None => Vec::new(),
    };
    let tables = results
        .table_names()
        .iter()
        .filter_map(|n| results.table(n).map(|df| (n.to_string(), df.clone())))
        .collect();
    let closed_loop = results
        .closed_loop()
        .and_then(|o| serde_json::to_string(&o.summary).ok());
    Ok(Outcome {
        tables,
        files,
        closed_loop,
    })
}

/// The options of `study.run()`.
pub(crate) struct RunArgs {
    pub output: Option<PathBuf>,
    pub figures: bool,
    pub rom_cache: bool,
    pub closed_loop: Option<bool>,
}
