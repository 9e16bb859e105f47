//! Output module: parquet round trips, atomic writes, manifest, results folder, report, and
//! the Python readers (scripts/check_parquet.py).

use crate::python_checks::{check_parquet, python_for_parquet, script};
use std::path::{Path, PathBuf};
use std::process::Command;

use rfmlab::common::C64;
use rfmlab::output::{
    sha256_file, sha256_hex, write_atomic, write_atomic_bytes, ColumnData, Manifest, OutputError,
    Report, ResultsDir, Table,
};

fn full_table() -> Table {
    let mut t = Table::new("all_types");
    t.push_f64(
        "freq_hz",
        "Hz",
        vec![0.0, -0.0, 1.5, 5e-324, f64::MAX, -1e300, f64::INFINITY],
    )
    .unwrap()
    .push_i64("iteration", "", vec![i64::MIN, -1, 0, 1, 2, 3, i64::MAX])
    .unwrap()
    .push_u32("line", "", vec![0, 1, 2, 3, 4, 5, u32::MAX])
    .unwrap()
    .push_str(
        "model",
        ["m1", "", "Modèle 4 (SLS+h)", "a|b", "é", "x\ny", "last"]
            .map(String::from)
            .to_vec(),
    )
    .unwrap()
    .push_bool(
        "converged",
        vec![true, false, true, true, false, false, true],
    )
    .unwrap()
    .push_opt_f64(
        "frac",
        "1",
        vec![
            Some(0.99),
            None,
            Some(0.5),
            None,
            Some(-0.0),
            Some(1.0),
            None,
        ],
    )
    .unwrap();
    let h: Vec<C64> = (0..7)
        .map(|k| C64::new(k as f64 * 0.25, -1.0 / (k as f64 + 1.0)))
        .collect();
    t.push_c64("h", "(m/s^2)/N", &h).unwrap();
    t
}

#[test]
fn table_with_every_column_type_reads_back_equal() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("all_types.parquet");
    let t = full_table();
    t.write_parquet(&path).unwrap();
    let back = Table::read_parquet(&path).unwrap();
    // Exact equality: names, order, units, kinds and every value bit for bit (f64 via ==,
    // which also checks signed zeros below).
    assert_eq!(back, t);
    let f = back.column("freq_hz").unwrap().as_f64().unwrap();
    assert!(f[1].is_sign_negative() && f[1] == 0.0, "-0.0 survives");
    assert_eq!(f[3].to_bits(), 1, "subnormal survives");
    assert_eq!(back.unit("h_re"), Some("(m/s^2)/N"));
    assert_eq!(back.unit("freq_hz"), Some("Hz"));
    assert_eq!(back.name(), "all_types");
    let h = back.c64_column("h").unwrap();
    assert_eq!(h[2], C64::new(0.5, -1.0 / 3.0));
    // An OptF64 column without any missing value keeps its kind.
    let mut t2 = Table::new("opt");
    t2.push_opt_f64("x", "Pa", vec![Some(1.0), Some(2.0)])
        .unwrap();
    let p2 = dir.path().join("opt.parquet");
    t2.write_parquet(&p2).unwrap();
    assert_eq!(Table::read_parquet(&p2).unwrap(), t2);
}

#[test]
fn nan_values_survive_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("nan.parquet");
    let nan = f64::from_bits(0x7ff8_0000_0000_0001);
    let mut t = Table::new("nan");
    t.push_f64("x", "1", vec![1.0, nan, f64::NEG_INFINITY])
        .unwrap();
    t.write_parquet(&path).unwrap();
    let back = Table::read_parquet(&path).unwrap();
    let x = back.column("x").unwrap().as_f64().unwrap();
    assert_eq!(x[0], 1.0);
    assert!(x[1].is_nan());
    assert_eq!(x[2], f64::NEG_INFINITY);
}

#[test]
fn empty_table_round_trips() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("empty.parquet");
    let mut t = Table::new("empty");
    t.push_f64("freq_hz", "Hz", vec![]).unwrap();
    t.push_str("model", vec![]).unwrap();
    t.write_parquet(&path).unwrap();
    assert_eq!(Table::read_parquet(&path).unwrap(), t);
}

#[test]
fn bad_columns_are_rejected_and_leave_the_table_unchanged() {
    let mut t = Table::new("t");
    t.push_f64("freq_hz", "Hz", vec![1.0, 2.0]).unwrap();
    let before = t.clone();
    let e = t.push_f64("x", "", vec![1.0]).unwrap_err();
    assert!(matches!(e, OutputError::BadColumn { .. }));
    assert!(
        e.to_string().contains("1 rows but column 'freq_hz' has 2"),
        "{e}"
    );
    assert!(t.push_f64("freq_hz", "Hz", vec![1.0, 2.0]).is_err());
    assert!(t.push_f64("FreqHz", "Hz", vec![1.0, 2.0]).is_err());
    assert!(t.push_f64("1x", "", vec![1.0, 2.0]).is_err());
    assert!(t.push_f64("a-b", "", vec![1.0, 2.0]).is_err());
    assert!(t.push_f64("", "", vec![1.0, 2.0]).is_err());
    // push_c64 adds both parts or neither.
    t.push_f64("h_im", "", vec![0.0, 0.0]).unwrap();
    let before_c = t.clone();
    assert!(t.push_c64("h", "", &[C64::new(1.0, 1.0); 2]).is_err());
    assert_eq!(t, before_c);
    assert_eq!(before.n_cols() + 1, t.n_cols());
}

#[test]
fn reading_a_missing_or_corrupt_file_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let e = Table::read_parquet(dir.path().join("nope.parquet")).unwrap_err();
    assert!(e.to_string().contains("nope.parquet"), "{e}");
    let bad = dir.path().join("bad.parquet");
    std::fs::write(&bad, b"PAR1 this is not parquet").unwrap();
    let e = Table::read_parquet(&bad).unwrap_err();
    assert!(e.to_string().contains("bad.parquet"), "{e}");
}

fn leftovers(dir: &Path) -> Vec<PathBuf> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.file_name().unwrap().to_string_lossy().contains(".tmp-"))
        .collect()
}

#[test]
fn failed_atomic_write_leaves_the_old_file_intact() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("result.txt");
    write_atomic_bytes(&path, b"earlier results\n").unwrap();
    // The writer produces part of the new file, then fails.
    let e = write_atomic(&path, |w| {
        w.write_all(&[b'x'; 100_000])?;
        Err(std::io::Error::other("simulated failure mid-way"))
    })
    .unwrap_err();
    assert!(e.to_string().contains("simulated failure mid-way"), "{e}");
    assert!(e.to_string().contains("result.txt"), "{e}");
    assert_eq!(std::fs::read(&path).unwrap(), b"earlier results\n");
    assert!(leftovers(dir.path()).is_empty(), "temporary file removed");
    // A successful write replaces the file completely.
    write_atomic(&path, |w| w.write_all(b"new")).unwrap();
    assert_eq!(std::fs::read(&path).unwrap(), b"new");
    assert!(leftovers(dir.path()).is_empty());
}

#[test]
fn failed_table_write_keeps_the_previous_parquet() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("frf.parquet");
    let t = full_table();
    t.write_parquet(&path).unwrap();
    let before = std::fs::read(&path).unwrap();
    // Writing into a folder that does not exist fails cleanly.
    let e = t
        .write_parquet(dir.path().join("missing").join("frf.parquet"))
        .unwrap_err();
    assert!(matches!(e, OutputError::MissingParent { .. }), "{e}");
    assert!(e.to_string().contains("folder does not exist"), "{e}");
    assert_eq!(std::fs::read(&path).unwrap(), before);
}

#[test]
fn parquet_output_is_deterministic() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("a.parquet"), dir.path().join("b.parquet"));
    full_table().write_parquet(&a).unwrap();
    full_table().write_parquet(&b).unwrap();
    assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
}

#[test]
fn manifest_records_hashes_and_round_trips() {
    let dir = tempfile::tempdir().unwrap();
    let study = dir.path().join("study.toml");
    std::fs::write(&study, b"[structure]\nname = \"x\"\n").unwrap();
    let mut m = Manifest::new(&study, Some(42));
    assert_eq!(
        m.study_sha256.as_deref(),
        Some(sha256_hex(b"[structure]\nname = \"x\"\n").as_str())
    );
    assert_eq!(m.version, env!("CARGO_PKG_VERSION"));
    assert_eq!(m.started_utc.len(), 20);
    assert!(m.started_utc.ends_with('Z'));
    let slept = m.time("step_a", || 7);
    assert_eq!(slept, 7);
    m.add_timing("step_b", 1.25);
    m.add_note("simulated data");
    // The crate root is a git checkout here: expect a 40-hex revision (maybe "-dirty").
    let has_git = Command::new("git").arg("--version").output().is_ok()
        && Path::new(env!("CARGO_MANIFEST_DIR")).join(".git").exists();
    if has_git {
        let rev = m.git_revision.clone().expect("git revision");
        assert!(rev[..40].chars().all(|c| c.is_ascii_hexdigit()), "{rev}");
    }
    let path = dir.path().join("manifest.json");
    m.write(&path).unwrap();
    let back = Manifest::read(&path).unwrap();
    assert_eq!(back, m);
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    assert_eq!(json["seed"], 42);
    assert_eq!(json["timings"][1]["step"], "step_b");
    assert_eq!(json["timings"][1]["seconds"], 1.25);

    // A missing study file is not fatal: no hash, and a note says why.
    let m2 = Manifest::new(dir.path().join("missing.toml"), None);
    assert!(m2.study_sha256.is_none());
    assert!(m2.notes[0].contains("missing.toml"));
}

#[test]
fn results_dir_writes_files_and_lists_them_in_the_manifest() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("results");
    assert!(ResultsDir::create(&root, "../escape").is_err());
    assert!(ResultsDir::create(&root, "").is_err());
    let mut rd = ResultsDir::create(&root, "paper_case1").unwrap();
    assert_eq!(rd.path(), root.join("paper_case1"));
    let tp = rd.write_table(&full_table()).unwrap();
    assert_eq!(tp, root.join("paper_case1/all_types.parquet"));
    let mut rep = Report::new();
    rep.heading(1, "Case 1").paragraph("Done.");
    rd.write_report(&rep).unwrap();
    rd.write_json("extra.json", &serde_json::json!({"a": 1}))
        .unwrap();
    assert!(rd.write_bytes("a/b", b"x").is_err());
    let study = dir.path().join("s.toml");
    std::fs::write(&study, "x = 1").unwrap();
    let mut m = Manifest::new(&study, None);
    let mp = rd.write_manifest(&mut m).unwrap();
    let back = Manifest::read(&mp).unwrap();
    let names: Vec<&str> = back.files.iter().map(|f| f.name.as_str()).collect();
    assert_eq!(names, ["all_types.parquet", "report.md", "extra.json"]);
    for f in &back.files {
        assert_eq!(
            f.sha256.as_deref(),
            Some(sha256_file(rd.file_path(&f.name)).unwrap().as_str())
        );
    }
    // A second run into the same folder keeps the folder and replaces files.
    let rd2 = ResultsDir::create(&root, "paper_case1").unwrap();
    assert!(rd2.file_path("report.md").exists());
}

#[test]
fn report_markdown_layout() {
    let mut r = Report::new();
    r.heading(2, "Table 2: modal parameters")
        .paragraph("Identified with **Model 4**.")
        .table(
            &["mode", "f (Hz)", "eta"],
            &[
                vec!["1".to_string(), "22.26".to_string(), "0.2044".to_string()],
                vec!["2|x".to_string()],
            ],
        )
        .image("figures/frf_1.png", "FRF 1");
    let md = r.to_markdown();
    let expected = "## Table 2: modal parameters\n\nIdentified with **Model 4**.\n\n\
| mode | f (Hz) | eta |\n|---|---|---|\n| 1 | 22.26 | 0.2044 |\n| 2\\|x |  |  |\n\n\
![FRF 1](figures/frf_1.png)\n";
    assert_eq!(md, expected);
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("report.md");
    r.write(&p).unwrap();
    assert_eq!(std::fs::read_to_string(&p).unwrap(), expected);
}

#[test]
fn python_polars_and_pandas_read_the_tables() {
    let Some(py) = python_for_parquet("python_polars_and_pandas_read_the_tables") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let mut rd = ResultsDir::create(dir.path(), "study").unwrap();
    rd.write_table(&full_table()).unwrap();
    let mut t = Table::new("modulus");
    t.push_f64("freq_hz", "Hz", (1..=5).map(f64::from).collect())
        .unwrap()
        .push_f64("e_storage", "Pa", vec![7e6; 5])
        .unwrap();
    rd.write_table(&t).unwrap();
    let (summary, _) = check_parquet(&py, rd.path());
    let files = summary.as_array().unwrap();
    assert_eq!(files.len(), 2);
    let all = files.iter().find(|f| f["table"] == "all_types").unwrap();
    assert_eq!(all["rows"], 7);
    let cols = all["columns"].as_array().unwrap();
    let names: Vec<&str> = cols.iter().map(|c| c["name"].as_str().unwrap()).collect();
    assert_eq!(
        names,
        [
            "freq_hz",
            "iteration",
            "line",
            "model",
            "converged",
            "frac",
            "h_re",
            "h_im"
        ]
    );
    let dtypes: Vec<&str> = cols
        .iter()
        .map(|c| c["polars_dtype"].as_str().unwrap())
        .collect();
    assert_eq!(
        dtypes,
        ["Float64", "Int64", "UInt32", "String", "Boolean", "Float64", "Float64", "Float64"]
    );
    assert_eq!(cols[0]["unit"], "Hz");
    assert_eq!(cols[6]["unit"], "(m/s^2)/N");
    // The documented ways to get the units from Python work.
    let out = Command::new(&py)
        .args([
            "-c",
            "import json, sys, polars as pl, pyarrow.parquet as pq\n\
             a = json.loads(pl.read_parquet_metadata(sys.argv[1])['rfmlab.units'])\n\
             b = json.loads(pq.ParquetFile(sys.argv[1]).metadata.metadata[b'rfmlab.units'])\n\
             assert a == b, (a, b)\n\
             print(a['freq_hz'], a['frac'])",
        ])
        .arg(rd.file_path("all_types.parquet"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(String::from_utf8_lossy(&out.stdout).trim(), "Hz 1");

    // A file without units metadata is reported as a failure.
    let mut df_bad = dir.path().join("study");
    df_bad.push("no_units.parquet");
    let status = Command::new(&py)
        .args([
            "-c",
            "import polars as pl, sys; pl.DataFrame({'x': [1.0]}).write_parquet(sys.argv[1])",
        ])
        .arg(&df_bad)
        .status()
        .unwrap();
    assert!(status.success());
    let out = Command::new(&py)
        .arg(script("check_parquet.py"))
        .arg(rd.path())
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stdout).contains("no 'rfmlab.units' metadata"));
    // And rfmlab reads the foreign file (no units, name from the file stem).
    let t = Table::read_parquet(&df_bad).unwrap();
    assert_eq!(t.name(), "no_units");
    assert_eq!(t.column("x"), Some(&ColumnData::F64(vec![1.0])));
    assert_eq!(t.unit("x"), Some(""));
}
