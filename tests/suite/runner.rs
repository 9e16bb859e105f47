//! The study runner end to end on noiseless simulated data (10 mm mesh, full engine):
//! each of Models 1-5 from Table 4's 'Initial' rows recovers its truth (Table 4's identified
//! values) to 1e-6 relative; tables read back with their units; the report has the paper's
//! table layouts; IEM and Model 1 bands on Model 4 data.

use crate::runner_common::*;

use rfmlab::output::Table;
use rfmlab::runner::{run_study, RunOptions};

fn no_progress(_: rfmlab::runner::Event) {}

#[test]
fn each_model_recovers_its_truth_from_table4_initial_rows() {
    let dir = tempfile::tempdir().unwrap();
    let freq = lines_hz(10.0, 490.0, 20.0);
    for k in 1..=5 {
        let law = rfmlab::material::model_from_name(&format!("model{k}"), None).unwrap();
        let (truth, _) = rfmlab::material::paper_table4(k);
        let data = dir.path().join(format!("m{k}.uff"));
        write_data(&data, "L1", law.as_ref(), &truth, &freq);
        let out = dir.path().join(format!("out{k}"));
        let text = study_text(
            &format!("m{k}"),
            &out,
            &data,
            (10.0, 490.0),
            &[(&format!("model{k}"), initial_of(k))],
            "[analyses]\nper_line = false\nsensitivity = false\nfigures = false\n",
        );
        let file = write(&dir.path().join(format!("m{k}.toml")), &text);
        let study = rfmlab::study::load(&file).unwrap();
        let summary = run_study(&study, &RunOptions::default(), &no_progress).unwrap();
        assert_eq!(summary.models.len(), 1);
        let m = &summary.models[0];
        for (p, (&got, &want)) in m.identified.iter().zip(&truth).enumerate() {
            let rel = (got - want).abs() / want.abs();
            assert!(
                rel < 1e-6,
                "model{k} {}: identified {got}, truth {want}, rel {rel:e} ({})",
                m.param_names[p],
                m.stop_reason
            );
        }
        for f in &m.frac {
            assert!(*f > 1.0 - 1e-9, "model{k}: FRAC {f}");
        }
        // The parameters table reads back with units and the same numbers.
        let t = Table::read_parquet(out.join("parameters.parquet")).unwrap();
        let ident = t
            .column("identified")
            .and_then(|c| c.as_f64())
            .unwrap()
            .to_vec();
        assert_eq!(ident, m.identified);
        assert_eq!(t.unit("frac_updated_3"), Some("1"));
    }
}

#[test]
fn model4_data_band_iem_tables_and_report() {
    let dir = tempfile::tempdir().unwrap();
    let freq = lines_hz(1.0, 100.0, 1.0);
    let law = rfmlab::material::model_from_name("model4", None).unwrap();
    let (truth, _) = rfmlab::material::paper_table4(4);
    let data = dir.path().join("m4.uff");
    write_data(&data, "L1", law.as_ref(), &truth, &freq);
    let out = dir.path().join("out");
    let analyses = "[analyses]\nper_line = true\nsensitivity = true\nfigures = true\n\
[[analyses.band_constant]]\ncenter_hz = 22.0\nwidth_hz = 10.0\n\
[[analyses.iem]]\ncenter_hz = 22.0\nwidth_hz = 10.0\n";
    let text = study_text_engine(
        "m4",
        &out,
        &data,
        (1.0, 100.0),
        &[("model4", initial_of(4)), ("model1", initial_of(1))],
        analyses,
        "rom",
    );
    let file = write(&dir.path().join("m4.toml"), &text);
    let study = rfmlab::study::load(&file).unwrap();
    let summary = run_study(&study, &RunOptions::default(), &no_progress).unwrap();
    for name in [
        "frf",
        "parameters",
        "iterations",
        "correlation",
        "correlation_curves",
        "modulus",
        "svd",
        "modal",
        "sensitivity",
    ] {
        let t = Table::read_parquet(out.join(format!("{name}.parquet"))).unwrap();
        assert!(t.n_rows() > 0, "{name} is empty");
    }
    // Model 1 band around the first resonance and the IEM agree with the truth curve there.
    let modal = Table::read_parquet(out.join("modal.parquet")).unwrap();
    assert_eq!(modal.unit("storage_modulus"), Some("Pa"));
    let e_true = law.modulus(&truth, 2.0 * std::f64::consts::PI * 22.0);
    let st = modal
        .column("storage_modulus")
        .and_then(|c| c.as_f64())
        .unwrap();
    let finite: Vec<f64> = st.iter().copied().filter(|v| v.is_finite()).collect();
    // The band RFM row always; the IEM row when the complex-mode solver succeeded (an IEM
    // failure is reported as a warning in report.md, not as a failed run).
    let report = std::fs::read_to_string(out.join("report.md")).unwrap();
    let iem_failed = report.contains("**Warning:** IEM");
    assert_eq!(
        finite.len(),
        if iem_failed { 1 } else { 2 },
        "IEM and band RFM rows"
    );
    if iem_failed {
        eprintln!("WARNING: the IEM failed (complex modes); only the band RFM row was checked");
    }
    for v in finite {
        assert!(
            (v - e_true.re).abs() / e_true.re < 0.05,
            "E' {v} vs truth {}",
            e_true.re
        );
    }
    for h in [
        "Table 2",
        "Table 3",
        "Table 4",
        "FRAC 1",
        "paper",
        "fig_frf_L1_22.png",
    ] {
        assert!(report.contains(h), "report lacks {h}:\n{report}");
    }
    assert!(out.join("fig_modulus_L1.svg").is_file());
    assert!(out.join("manifest.json").is_file());
    python_reads_tables(&out, 9);
    let m4 = summary.models.iter().find(|m| m.model == "model4").unwrap();
    assert!(m4.frac.iter().all(|&f| f > 0.99));
}

/// The output module's pattern: scripts/check_parquet.py reads every table with polars and
/// pandas and checks the units metadata (skipped without Python, unless CI is set).
fn python_reads_tables(dir: &std::path::Path, n_tables: usize) {
    use std::path::{Path, PathBuf};
    let py: PathBuf = std::env::var_os("RFMLAB_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join(".venv/bin/python"));
    let ok = std::process::Command::new(&py)
        .args(["-c", "import polars, pandas, pyarrow"])
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false);
    if !ok {
        let msg = format!(
            "Python with polars, pandas and pyarrow not found at '{}' (set RFMLAB_PYTHON)",
            py.display()
        );
        if std::env::var_os("CI").is_some() {
            panic!("{msg}");
        }
        eprintln!("SKIPPED the Python read-back: {msg}");
        return;
    }
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/check_parquet.py");
    let out = std::process::Command::new(&py)
        .arg(&script)
        .arg(dir)
        .arg("--json")
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "check_parquet failed:\n{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let summary: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(
        summary.as_array().map(|a| a.len()),
        Some(n_tables),
        "{stdout}"
    );
}
