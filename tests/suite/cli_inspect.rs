//! `rfmlab inspect`: the table and `--json` on real files, and a clear error on a bad one.

use crate::common_data::*;
use std::process::Command;

fn inspect(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_rfmlab"))
        .arg("inspect")
        .args(args)
        .output()
        .expect("run rfmlab inspect")
}

#[test]
fn inspect_json_lists_the_beam_frfs() {
    let beam = data("beam/beam_accelerance_3frf.uff");
    let out = inspect(&[beam.to_str().unwrap(), "--json"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON");
    let rows = v.as_array().expect("an array of datasets");
    assert_eq!(rows.len(), 3);
    for (k, r) in rows.iter().enumerate() {
        assert_eq!(r["kind"], "FRF");
        assert_eq!(r["number"], 58);
        assert_eq!(r["dataset"], k as u64);
        assert_eq!(r["n"], 1001);
        assert_eq!(r["f0"], 0.0);
        assert_eq!(r["f1"], 1000.0);
        assert_eq!(r["quantity"], "accelerance");
        assert_eq!(r["response"], "1+x");
        assert_eq!(r["reference"], format!("{}+x", k + 1));
    }
}

#[test]
fn inspect_table_covers_several_files_and_skipped_datasets() {
    let a = data("uff/ufffiles_jl/dataset151_164_58_55.unv");
    let b = data("uff/ufffiles_jl/dataset58_case3_binary.unv");
    let out = inspect(&[a.to_str().unwrap(), b.to_str().unwrap()]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("dataset151_164_58_55.unv"), "{text}");
    assert!(text.contains("dataset58_case3_binary.unv"), "{text}");
    assert!(text.contains("58"), "{text}");
}

#[test]
fn inspect_names_a_missing_or_broken_file() {
    let out = inspect(&["/nonexistent/file.uff"]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("/nonexistent/file.uff"), "{err}");

    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("broken.uff");
    let mut text =
        std::fs::read_to_string(data("uff/ufffiles_jl/dataset58_nospacing.uff")).unwrap();
    text.truncate(text.len() / 2);
    std::fs::write(&bad, text).unwrap();
    let out = inspect(&[bad.to_str().unwrap()]);
    assert_eq!(
        out.status.code(),
        Some(2),
        "{}",
        String::from_utf8_lossy(&out.stdout)
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("broken.uff") && err.contains("dataset 0"),
        "{err}"
    );
}
