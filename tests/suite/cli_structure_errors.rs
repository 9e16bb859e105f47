//! Bad structure input through the CLI: each variant of
//! studies/paper_geometry.toml written to a temp dir makes `rfmlab modes FILE` exit with code 2,
//! print an error naming the key and the problem on stderr, and never panic.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const BIN: &str = env!("CARGO_BIN_EXE_rfmlab");

fn paper_study() -> String {
    std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("studies/paper_geometry.toml"),
    )
    .expect("studies/paper_geometry.toml")
}

/// Replace exactly one occurrence of `from` in the paper study.
fn variant(from: &str, to: &str) -> String {
    let s = paper_study();
    assert_eq!(
        s.matches(from).count(),
        1,
        "`{from}` must occur once in the study"
    );
    s.replacen(from, to, 1)
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

fn rfmlab(args: &[&str]) -> Output {
    Command::new(BIN)
        .arg("--quiet")
        .args(args)
        .env("CI", "1")
        .output()
        .expect("run rfmlab")
}

/// `rfmlab modes FILE` fails with exit code 2 and a message containing every `needles` entry.
fn expect_input_error(file: &Path, needles: &[&str]) -> String {
    let out = rfmlab(&["modes", file.to_str().unwrap(), "--count", "2"]);
    let err = String::from_utf8_lossy(&out.stderr).to_string();
    assert_eq!(
        out.status.code(),
        Some(2),
        "exit code for {}: stderr {err}",
        file.display()
    );
    assert!(!err.contains("panicked"), "panic: {err}");
    let name = file.file_name().unwrap().to_str().unwrap();
    assert!(
        err.contains(name),
        "error does not name the file {name}: {err}"
    );
    for n in needles {
        assert!(err.contains(n), "error lacks `{n}`: {err}");
    }
    eprintln!("{name}: {}", err.trim());
    err
}

#[test]
fn unknown_keys_are_rejected() {
    let dir = tempfile::tempdir().unwrap();
    let f = write(
        dir.path(),
        "unknown_top.toml",
        &variant("seed = 1\n", "seed = 1\ncolour = \"red\"\n"),
    );
    expect_input_error(&f, &["colour", "unknown"]);
    let f = write(
        dir.path(),
        "unknown_beam.toml",
        &variant("width = 0.020 ", "widht = 0.020 "),
    );
    expect_input_error(&f, &["widht", "unknown"]);
}

#[test]
fn non_positive_dimension() {
    let dir = tempfile::tempdir().unwrap();
    let f = write(
        dir.path(),
        "neg_thickness.toml",
        &variant(
            "thickness = 0.010        # m, along y",
            "thickness = -0.010 # m",
        ),
    );
    expect_input_error(&f, &["structure.beam.thickness", "positive"]);
    let f = write(
        dir.path(),
        "zero_width.toml",
        &variant("width = 0.020 ", "width = 0.0 "),
    );
    expect_input_error(&f, &["structure.beam.width", "positive"]);
}

#[test]
fn point_off_the_beam_surface() {
    let dir = tempfile::tempdir().unwrap();
    let f = write(
        dir.path(),
        "off_surface.toml",
        &variant("[0.200, 0.010, 0.010]", "[0.200, 0.013, 0.010]"),
    );
    expect_input_error(&f, &["structure.points[2].position", "surface"]);
    // inside the beam, not on a face
    let f = write(
        dir.path(),
        "inside.toml",
        &variant("[0.200, 0.010, 0.010]", "[0.200, 0.005, 0.010]"),
    );
    expect_input_error(&f, &["structure.points[2].position", "surface"]);
}

#[test]
fn adhesive_longer_than_the_beam() {
    let dir = tempfile::tempdir().unwrap();
    let f = write(
        dir.path(),
        "long_adhesive.toml",
        &variant("length = 0.050 ", "length = 0.400 "),
    );
    expect_input_error(&f, &["structure.adhesive.length", "longer than the beam"]);
    // fits alone but not from its x_start
    let f = write(
        dir.path(),
        "shifted_adhesive.toml",
        &variant("x_start = 0.0 ", "x_start = 0.27 "),
    );
    expect_input_error(&f, &["structure.adhesive", "longer than the beam"]);
}

/// Without adhesive the model has no support (the adhesive's lower face is the only fixed
/// face): validation reports it as unconstrained.
#[test]
fn unconstrained_model() {
    let dir = tempfile::tempdir().unwrap();
    let f = write(
        dir.path(),
        "no_adhesive.toml",
        &variant("length = 0.050 ", "length = 0.0 "),
    );
    expect_input_error(&f, &["structure.adhesive.length", "unconstrained"]);
    let f = write(
        dir.path(),
        "flat_adhesive.toml",
        &variant(
            "thickness = 0.010        # m, below",
            "thickness = 0.0 # m, below",
        ),
    );
    expect_input_error(&f, &["structure.adhesive.thickness", "unconstrained"]);
}

/// An imported model whose M comes from a coarser mesh than K_b and S.
#[test]
fn mismatched_imported_matrix_sizes() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for (name, h) in [("ten", "0.01"), ("coarse", "0.05")] {
        let f = write(
            d,
            &format!("{name}.toml"),
            &variant("element_size = 0.005 ", &format!("element_size = {h} ")),
        );
        let out = rfmlab(&[
            "export-mm",
            f.to_str().unwrap(),
            "--dir",
            d.join(name).to_str().unwrap(),
        ]);
        assert!(
            out.status.success(),
            "export-mm: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    let s = paper_study();
    let (a, b) = (
        s.find("[structure.beam]").unwrap(),
        s.find("[[structure.points]]").unwrap(),
    );
    let import = "[structure.import]\nmass = \"coarse/M.mtx\"\nstiffness = \"ten/K_b.mtx\"\nadhesive_sensitivity = \"ten/S.mtx\"\ndof_map = \"ten/dofmap.csv\"\n\n";
    let text = format!("{}{import}{}", &s[..a], &s[b..]).replacen(
        "source = \"mesher\"",
        "source = \"matrix_market\"",
        1,
    );
    let f = write(d, "mismatch.toml", &text);
    expect_input_error(&f, &["structure.import", "M.mtx", "do not match"]);

    // and the consistent import works (exit 0), so the failure above is the size check
    let good = text.replacen("coarse/M.mtx", "ten/M.mtx", 1);
    let f = write(d, "good_import.toml", &good);
    let out = rfmlab(&["modes", f.to_str().unwrap(), "--count", "2"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}
