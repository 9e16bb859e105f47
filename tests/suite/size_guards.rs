//! Sizes beyond the machine refused before anything is allocated: a mesh far too fine
//! (`check`, `modes`), too many lines (`frf --step`), too many modes (`modes --count`) exit
//! with code 2 within seconds, naming the key or flag and the estimated memory; and data
//! files that are not UFF or CSV (empty, binary, other text) get an error naming the file.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

const BIN: &str = env!("CARGO_BIN_EXE_rfmlab");

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// studies/default.toml with absolute data paths and `from` replaced by `to` (once).
fn default_variant(dir: &Path, from: &str, to: &str) -> PathBuf {
    let s = std::fs::read_to_string(root().join("studies/default.toml")).unwrap();
    assert_eq!(s.matches(from).count(), 1, "`{from}` once");
    let s = s.replacen(from, to, 1);
    let data = root().join("studies/data/").display().to_string();
    let s = s.replace("\"data/", &format!("\"{data}"));
    let s = s.replacen(
        "seed = 1\n",
        &format!("seed = 1\noutput_dir = \"{}\"\n", dir.join("out").display()),
        1,
    );
    let p = dir.join("study.toml");
    std::fs::write(&p, s).unwrap();
    p
}

fn rfmlab(args: &[&str]) -> (Output, Duration) {
    let t = Instant::now();
    let o = Command::new(BIN)
        .arg("--quiet")
        .args(args)
        .env("CI", "1")
        .output()
        .expect("run rfmlab");
    (o, t.elapsed())
}

fn assert_refused(args: &[&str], key: &str) {
    let (o, t) = rfmlab(args);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
    assert!(err.contains(key), "{args:?} must name {key}: {err}");
    assert!(
        err.contains("GiB") || err.contains("MiB"),
        "{args:?} must state the estimated memory: {err}"
    );
    assert!(!err.contains("panicked"), "{err}");
    assert!(t < Duration::from_secs(20), "{args:?} took {t:?}");
}

#[test]
fn a_mesh_too_fine_for_the_machine_is_refused_by_check_and_modes() {
    let dir = tempfile::tempdir().unwrap();
    let f = default_variant(
        dir.path(),
        "element_size = 0.005 ",
        "element_size = 0.0005 ",
    );
    let f = f.to_str().unwrap();
    assert_refused(&["check", f], "structure.mesh.element_size");
    assert_refused(&["modes", f], "structure.mesh.element_size");
    assert_refused(&["rom", f], "structure.mesh.element_size");
}

#[test]
fn too_many_lines_or_modes_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let f = default_variant(dir.path(), "seed = 1", "seed = 1");
    let f = f.to_str().unwrap();
    assert_refused(&["frf", f, "--band", "1,2", "--step", "1e-9"], "--step");
    assert_refused(&["modes", f, "--count", "20000"], "--count");
}

#[test]
fn files_that_are_not_uff_or_csv_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let cases: [(&str, &[u8], &str); 4] = [
        ("empty.uff", b"", "empty"),
        (
            "blob.uff",
            &[0u8, 159, 146, 150, 0, 1, 2, 3, 255, 254],
            "binary",
        ),
        (
            "notes.uff",
            b"frequency response of the joint\nmeasured on Tuesday\n",
            "no UFF dataset",
        ),
        ("blank.csv", b"  \n", "empty"),
    ];
    for (name, bytes, why) in cases {
        let p = dir.path().join(name);
        std::fs::write(&p, bytes).unwrap();
        let (o, _) = rfmlab(&["inspect", p.to_str().unwrap()]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{name}: {err}");
        assert!(err.contains(name) && err.contains(why), "{name}: {err}");
        // the same file as a study's data: `check` names it too
        let f = default_variant(
            dir.path(),
            "files = [\"data/paper_virtual_L1.uff\"]",
            &format!("files = [\"{}\"]", p.display()),
        );
        let (o, _) = rfmlab(&["check", f.to_str().unwrap()]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "check with {name}: {err}");
        assert!(err.contains(name), "check with {name}: {err}");
    }
}
