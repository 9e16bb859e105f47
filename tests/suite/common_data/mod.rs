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

/// `rfmlab simulate`'s UFF `uff` (one level) with every channel replaced by the exact
/// accelerance its truth sidecar `truth` holds, written to `out`: noise-free data without the
/// frequency-domain mode's Hann leakage and its scatter, for identifications that must be
/// exact. The sidecar lists channels in the order of the UFF's datasets; each channel is
/// checked to be nearer its own `expected_h1` than any other channel's (noise-free H1 still
/// scatters where leakage lowers the coherence).
pub fn exact_uff(uff: &std::path::Path, truth: &std::path::Path, out: &std::path::Path) {
    use rfmlab::common::C64;
    use rfmlab::data::{frf_set_from_uff, frf_set_to_uff, UffImportOptions};
    let truth: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(truth).unwrap()).unwrap();
    let values = |v: &serde_json::Value| -> Vec<C64> {
        nums(&v["re"])
            .into_iter()
            .zip(nums(&v["im"]))
            .map(|(r, i)| C64::new(r, i))
            .collect()
    };
    let mut set =
        frf_set_from_uff(&[(uff, "L1".to_string())], &UffImportOptions::default()).unwrap();
    let channels = truth["levels"][0]["channels"].as_array().unwrap();
    let level = &mut set.levels[0];
    assert_eq!(level.channels.len(), channels.len());
    let norm = |v: &[C64]| v.iter().map(|x| x.norm_sqr()).sum::<f64>().sqrt();
    let h1: Vec<Vec<C64>> = channels.iter().map(|t| values(&t["expected_h1"])).collect();
    let dist = |a: &[C64], b: &[C64]| {
        let d: Vec<C64> = a.iter().zip(b).map(|(x, y)| x - y).collect();
        norm(&d) / norm(b)
    };
    for (i, (ch, t)) in level.channels.iter_mut().zip(channels).enumerate() {
        let own = dist(&ch.values, &h1[i]);
        let other = (0..h1.len())
            .filter(|&j| j != i)
            .map(|j| dist(&ch.values, &h1[j]))
            .fold(f64::INFINITY, f64::min);
        assert!(
            own < other,
            "channel {}: the UFF's channel is nearer another sidecar channel ({own:.2e} vs {other:.2e})",
            ch.response_id
        );
        ch.values = values(&t["exact"]);
    }
    frf_set_to_uff(&set, out, false).unwrap();
}
