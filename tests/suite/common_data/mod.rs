//! Shared helpers for the data tests: the shared data folder and the pyuff interpreter.
#![allow(dead_code)]

use std::path::PathBuf;

/// `RFMLAB_SHARED`, else `<crate>/../shared`, else `/work/shared`.
pub fn shared() -> PathBuf {
    if let Some(p) = std::env::var_os("RFMLAB_SHARED") {
        return PathBuf::from(p);
    }
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared");
    if p.join("data").exists() {
        return p;
    }
    PathBuf::from("/work/shared")
}

pub fn data(rel: &str) -> PathBuf {
    shared().join("data").join(rel)
}

/// Python with pyuff: `RFMLAB_PYTHON` or `<crate>/.venv/bin/python`. None (with a skip notice)
/// when missing; panics when missing and `CI` is set.
pub fn python_with_pyuff() -> Option<PathBuf> {
    let py = std::env::var_os("RFMLAB_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(".venv/bin/python"));
    let ok = std::process::Command::new(&py)
        .args(["-c", "import pyuff, numpy"])
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false);
    if ok {
        return Some(py);
    }
    if std::env::var_os("CI").is_some() {
        panic!(
            "CI is set but {} cannot import pyuff and numpy; set RFMLAB_PYTHON or create the venv",
            py.display()
        );
    }
    eprintln!(
        "SKIP: no Python with pyuff at {} (python3 -m venv .venv && .venv/bin/pip install pyuff numpy)",
        py.display()
    );
    None
}

pub fn script() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("scripts/pyuff_interop.py")
}

/// Run `pyuff_interop.py dump` on files; the parsed JSON.
pub fn pyuff_dump(py: &PathBuf, files: &[PathBuf], tmp: &std::path::Path) -> serde_json::Value {
    let out = tmp.join("dump.json");
    let st = std::process::Command::new(py)
        .arg(script())
        .arg("dump")
        .arg(&out)
        .args(files)
        .status()
        .expect("run python");
    assert!(st.success(), "pyuff_interop.py dump failed");
    serde_json::from_slice(&std::fs::read(&out).expect("dump json")).expect("json")
}

/// A JSON array of numbers.
pub fn nums(v: &serde_json::Value) -> Vec<f64> {
    v.as_array()
        .map(|a| a.iter().map(|x| x.as_f64().unwrap_or(f64::NAN)).collect())
        .unwrap_or_default()
}
