//! Bad study files give an error naming the file and key, exit code 2, and leave earlier
//! results intact (the binary is run as a user would).

use crate::runner_common::*;

use std::path::Path;

fn rfmlab(args: &[&str]) -> (i32, String, String) {
    let (code, out, err) = rfmlab_cli(args);
    (code.unwrap_or(-1), out, err)
}

fn good(s: &Setup) -> String {
    study_text(
        "s",
        &s.out,
        &s.data,
        (10.0, 100.0),
        &[("model1", initial_of(1))],
        ANALYSES,
        "full",
    )
}

/// Writes `text` as a study, runs `rfmlab run`, expects exit code 2 with the file and all
/// `needles` in the message.
fn expect_input_error(s: &Setup, name: &str, text: &str, needles: &[&str]) {
    let file = write(&s.root.join(format!("{name}.toml")), text);
    for cmd in ["run", "check"] {
        let (code, _, err) = rfmlab(&["--quiet", cmd, file.to_str().unwrap()]);
        assert_eq!(code, 2, "{name} ({cmd}): exit code {code}, stderr:\n{err}");
        assert!(
            err.contains(&format!("{name}.toml")),
            "{name} ({cmd}): file not named:\n{err}"
        );
        for n in needles {
            assert!(err.contains(n), "{name} ({cmd}): {n:?} not in:\n{err}");
        }
    }
}

fn snapshot(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut v: Vec<(String, Vec<u8>)> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .map(|p| {
            (
                p.file_name().unwrap().to_string_lossy().into_owned(),
                std::fs::read(&p).unwrap(),
            )
        })
        .collect();
    v.sort();
    v
}

#[test]
fn bad_study_files_exit_2_naming_file_and_key_and_keep_earlier_results() {
    let s = setup();
    // A good run first.
    let file = write(&s.root.join("good.toml"), &good(&s));
    let (code, _, err) = rfmlab(&["--quiet", "run", file.to_str().unwrap()]);
    assert_eq!(code, 0, "good run failed:\n{err}");
    let (code, out, err) = rfmlab(&["check", file.to_str().unwrap(), "--json"]);
    assert_eq!(code, 0, "check failed:\n{err}");
    assert!(out.contains("\"n_dof\""), "{out}");
    let before = snapshot(&s.out);
    assert!(before.iter().any(|(n, _)| n == "parameters.parquet"));
    assert!(before.iter().any(|(n, _)| n == "manifest.json"));

    let g = good(&s);
    expect_input_error(
        &s,
        "unknown_key",
        &g.replace("[solver]\n", "[solver]\nmax_iteration = 3\n"),
        &["max_iteration"],
    );
    expect_input_error(
        &s,
        "missing_file",
        &g.replace(
            &s.data.display().to_string(),
            &s.root.join("nope.uff").display().to_string(),
        ),
        &["nope.uff", "files"],
    );
    expect_input_error(
        &s,
        "band_outside",
        &g.replace("band_hz = [10, 100]", "band_hz = [10, 600]"),
        &["band"],
    );
    expect_input_error(
        &s,
        "missing_param",
        &g.replace("h = 1.5e6\n", ""),
        &["models[0].initial.h"],
    );
    expect_input_error(
        &s,
        "out_of_range",
        &g.replace("E0 = 8e6", "E0 = -8e6"),
        &["E0"],
    );
    // Admissible (positive) but absurd: E0 = 1e30 Pa makes Z numerically singular.
    expect_input_error(
        &s,
        "singular",
        &g.replace("E0 = 8e6", "E0 = 1e30"),
        &["models[0].initial", "singular"],
    );
    // The measurement model and the truth sidecar.
    let with_meas = |extra: &str| {
        g.replace(
            "[[measurements.levels]]",
            &format!("{extra}[[measurements.levels]]"),
        )
    };
    expect_input_error(
        &s,
        "bad_window",
        &with_meas("[measurements.estimator]\nwindow = \"hanning\"\nblock_s = 1.0\n"),
        &["measurements.estimator.window", "\"hann\""],
    );
    expect_input_error(
        &s,
        "bad_block",
        &with_meas("[measurements.estimator]\nwindow = \"hann\"\nblock_s = -1.0\n"),
        &["measurements.estimator.block_s"],
    );
    expect_input_error(
        &s,
        "bad_samples",
        &with_meas("[measurements.estimator]\nwindow = \"hann\"\nblock_s = 1.0\nfs_hz = 1000.5\n"),
        &["measurements.estimator.fs_hz", "whole number of samples"],
    );
    for (name, band, words) in [
        ("force_band_len", "[500.0]", "is not a band"),
        ("force_band_order", "[500.0, 1.0]", "0 <= f_low < f_high"),
        ("force_band_nyquist", "[0.0, 1024.0]", "fs_hz / 2"),
        (
            "force_band_grid",
            "[0.5, 500.0]",
            "multiples of the line spacing",
        ),
    ] {
        expect_input_error(
            &s,
            name,
            &with_meas(&format!(
                "[measurements.estimator]\nwindow = \"hann\"\nblock_s = 1.0\nforce_band_hz = {band}\n"
            )),
            &["measurements.estimator.force_band_hz", words],
        );
    }
    expect_input_error(
        &s,
        "missing_truth",
        &g.replace(
            "[[measurements.levels]]",
            "truth = \"nope.truth.json\"\n[[measurements.levels]]",
        ),
        &["measurements.truth", "nope.truth.json"],
    );
    // The results of the good run are untouched by the failed runs.
    assert_eq!(snapshot(&s.out), before);
    // No stray temporary folders either.
    let stray: Vec<_> = std::fs::read_dir(&s.root)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().contains(".tmp-"))
        .collect();
    assert!(stray.is_empty());
}

/// `rfmlab diagnose` on a study without `[inference]`, or with a bad threshold: exit 2 naming
/// the file and the key.
#[test]
fn diagnose_bad_input_exits_2() {
    let s = setup();
    let file = write(&s.root.join("noinf.toml"), &good(&s));
    let (code, _, err) = rfmlab(&["--quiet", "diagnose", file.to_str().unwrap()]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("noinf.toml") && err.contains("inference"),
        "{err}"
    );
    let (code, _, err) = rfmlab(&[
        "--quiet",
        "diagnose",
        file.to_str().unwrap(),
        "--threshold-nats=-1",
    ]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("--threshold-nats"), "{err}");
}
