//! The Python interoperability checks shared by several test files: finding the interpreter
//! (skipped when missing, unless `CI` is set), the SciPy Matrix Market round trip
//! (matrix_market.rs, paper_joint.rs) and the Parquet read-back (output.rs, runner.rs).
#![allow(dead_code)]

use rfmlab::fe::matrix_market::{export_model, import_model, MmPaths};
use rfmlab::fe::model::StructuralModel;
use std::path::{Path, PathBuf};
use std::process::Command;

/// `RFMLAB_PYTHON`, else `<crate>/.venv/bin/python` (which may not exist).
pub fn interpreter() -> PathBuf {
    std::env::var_os("RFMLAB_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join(".venv/bin/python"))
}

/// `<crate>/scripts/<name>`.
pub fn script(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("scripts")
        .join(name)
}

/// `py scripts/<name> args...` with the environment `envs`; asserts that it succeeded (its
/// stderr in the message) and returns its output.
pub fn run_script<S: AsRef<std::ffi::OsStr>>(
    py: &Path,
    name: &str,
    args: &[S],
    envs: &[(&str, &str)],
) -> std::process::Output {
    let out = Command::new(py)
        .arg(script(name))
        .args(args)
        .envs(envs.iter().copied())
        .output()
        .expect("run python");
    assert!(
        out.status.success(),
        "{name} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// The interpreter for the SciPy round trips, when it exists. None (with a skip notice naming
/// `test`) when it does not; panics instead when `CI` is set.
pub fn python_for_scipy(test: &str) -> Option<PathBuf> {
    let py = interpreter();
    if py.exists() {
        return Some(py);
    }
    if std::env::var_os("CI").is_some() {
        panic!("CI is set but no Python with SciPy was found (set RFMLAB_PYTHON or create .venv)");
    }
    eprintln!("SKIP {test}: no Python found (set RFMLAB_PYTHON or create <crate>/.venv with numpy and scipy)");
    None
}

/// `model` exported with `export_model`, rewritten by scipy.io.mmread/mmwrite
/// (scripts/mm_roundtrip.py) and imported again.
pub fn scipy_round_trip(py: &Path, model: &StructuralModel) -> StructuralModel {
    let ours = tempfile::tempdir().unwrap();
    let theirs = tempfile::tempdir().unwrap();
    export_model(model, ours.path()).unwrap();
    run_script(py, "mm_roundtrip.py", &[ours.path(), theirs.path()], &[]);
    import_model(&MmPaths::in_dir(theirs.path())).unwrap()
}

/// The interpreter for the Parquet read-back, when it imports polars, pandas and pyarrow. None
/// (with a skip notice naming `test`) when it does not; panics instead when `CI` is set.
pub fn python_for_parquet(test: &str) -> Option<PathBuf> {
    python_with(&["polars", "pandas", "pyarrow"], test)
}

/// The interpreter when it imports every module of `modules`. None (with a skip notice naming
/// `test`) when it does not; panics instead when `CI` is set.
pub fn python_with(modules: &[&str], test: &str) -> Option<PathBuf> {
    let py = interpreter();
    let ok = Command::new(&py)
        .args(["-c", &format!("import {}", modules.join(", "))])
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false);
    if ok {
        return Some(py);
    }
    let msg = format!(
        "Python with {} not found at '{}' (set RFMLAB_PYTHON, or run scripts/setup_python.sh)",
        modules.join(", "),
        py.display()
    );
    if std::env::var_os("CI").is_some() {
        panic!("{msg}");
    }
    eprintln!("SKIPPED {test}: {msg}");
    None
}

/// scripts/check_parquet.py --json on a results folder: reads every table with polars and
/// pandas and checks the units metadata. Asserts that it succeeded; its JSON summary and stdout.
pub fn check_parquet(py: &Path, dir: &Path) -> (serde_json::Value, String) {
    let out = Command::new(py)
        .arg(script("check_parquet.py"))
        .arg(dir)
        .arg("--json")
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "check_parquet failed:\n{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let summary = serde_json::from_str(&stdout).unwrap();
    (summary, stdout)
}

/// The interpreter for the ArviZ reference of the MCMC diagnostics, when it imports arviz. None
/// (with a skip notice naming `test`) when it does not; panics instead when `CI` is set.
pub fn python_for_arviz(test: &str) -> Option<PathBuf> {
    python_with(&["arviz"], test)
}

/// scripts/arviz_reference.py on `input` (written to a temporary JSON file): ArviZ's report.
pub fn arviz_reference(py: &Path, input: &serde_json::Value) -> serde_json::Value {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("draws.json");
    std::fs::write(&path, serde_json::to_vec(input).unwrap()).unwrap();
    let out = run_script(py, "arviz_reference.py", &[&path], &[]);
    serde_json::from_slice(&out.stdout).expect("arviz_reference.py printed JSON")
}
