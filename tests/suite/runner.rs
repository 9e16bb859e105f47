//! The study runner end to end on noiseless simulated data (10 mm mesh, full engine):
//! each of Models 1-5 from Table 4's 'Initial' rows recovers its truth (Table 4's identified
//! values) to 1e-6 relative; tables read back with their units; the report has the paper's
//! table layouts; IEM and Model 1 bands on Model 4 data.

use crate::python_checks::{check_parquet, python_for_parquet};
use crate::runner_common::*;

use rfmlab::output::Table;
use rfmlab::report::run_study;
use rfmlab::report::RunOptions;

fn no_progress(_: rfmlab::stage::Event) {}

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
            "full",
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
    let text = study_text(
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
    let opts = RunOptions {
        rom_cache: Some(crate::shared_rom_cache::runs_folder()),
        ..RunOptions::default()
    };
    let summary = run_study(&study, &opts, &no_progress).unwrap();
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
    let Some(py) = python_for_parquet("the Python read-back") else {
        return;
    };
    let (summary, stdout) = check_parquet(&py, dir);
    assert_eq!(
        summary.as_array().map(|a| a.len()),
        Some(n_tables),
        "{stdout}"
    );
}

/// The H1 estimator's leakage, modelled (`[measurements.estimator]`) or not: data are the
/// noiseless expected H1 of the virtual rig (1 s Hann blocks, shaker on a stinger, Model 4 at
/// Level 1, 10 mm mesh) from `simulate_level`'s truth record (its own 1/32 Hz quadrature).
/// Without the model the circle fit reads too much damping and the IEM's E'' misses the truth
/// curve by more than 5 %; with it, Model 1 over the band, the IEM and global Model 4 land on
/// the truth.
#[test]
fn leakage_model_removes_the_h1_estimator_bias() {
    use rfmlab::experiment::plant::EnginePlant;
    use rfmlab::experiment::{simulate_level, ChainParams, Mode, Shaker};
    use rfmlab::frf::{FullModel, FullParams};
    let dir = tempfile::tempdir().unwrap();
    let built = built_structure();
    let engine = FullModel::new(&built.model, &[built.excitation], FullParams::default()).unwrap();
    let law = rfmlab::material::model_from_name("model4", None).unwrap();
    let (truth, _) = rfmlab::material::paper_table4(4);
    let modulus = |w: f64| law.modulus(&truth, w);
    let plant = EnginePlant {
        engine: &engine,
        modulus: &modulus,
        input_col: 0,
        drive_output: built.excitation,
    };
    let shaker = Shaker {
        armature_mass_kg: 0.02,
        stinger_stiffness_n_m: 5.0e5,
    };
    let chain = ChainParams {
        band_hz: (1.0, 100.0),
        lines_hz: lines_hz(1.0, 100.0, 1.0),
        shaker: Some(shaker),
        mode: Mode::FrequencyDomain,
        n_averages: 2,
        ..ChainParams::default()
    };
    let sim = simulate_level(&plant, &chain).unwrap();
    let channels = built
        .model
        .points
        .iter()
        .zip(&sim.truth.channels)
        .map(|(p, c)| rfmlab::data::Channel {
            response_id: p.id,
            response_dir: p.direction,
            reference_id: 2,
            reference_dir: p.direction,
            values: c.expected_h1.clone(),
            coherence: None,
            source: None,
        })
        .collect();
    let set = rfmlab::data::FrfSet {
        levels: vec![rfmlab::data::FrfLevel {
            name: "L1".into(),
            force_rms_n: None,
            n_averages: None,
            quantity: rfmlab::data::Quantity::Accelerance,
            freq_hz: chain.lines_hz.clone(),
            channels,
        }],
    };
    let data = dir.path().join("leaky.uff");
    rfmlab::data::frf_set_to_uff(&set, &data, false).unwrap();
    let analyses = "[analyses]\nper_line = false\nsensitivity = false\nfigures = false\n\
[[analyses.band_constant]]\ncenter_hz = 22.0\nwidth_hz = 10.0\n\
[[analyses.iem]]\ncenter_hz = 22.0\nwidth_hz = 10.0\n";
    let estimator = "[measurements.estimator]\nwindow = \"hann\"\nblock_s = 1.0\nfs_hz = 2048.0\n\
shaker = { armature_mass = 0.02, stinger_stiffness = 5.0e5 }\nforce_band_hz = [1.0, 100.0]\n";
    // (IEM E', E'' rel. error, band E', E'' rel. error, worst Model 4 parameter rel. error)
    let run = |with_model: bool| {
        let out = dir.path().join(format!("out{with_model}"));
        let mut text = study_text(
            "leak",
            &out,
            &data,
            (1.0, 100.0),
            &[("model4", initial_of(4))],
            analyses,
            "rom",
        );
        if with_model {
            text = text.replace(
                "[[measurements.levels]]",
                &format!("{estimator}[[measurements.levels]]"),
            );
        }
        let file = write(&dir.path().join(format!("leak{with_model}.toml")), &text);
        let study = rfmlab::study::load(&file).unwrap();
        // the two runs (and the data-band test's) share the certified ROM of the structure
        let opts = RunOptions {
            rom_cache: Some(crate::shared_rom_cache::runs_folder()),
            ..RunOptions::default()
        };
        let summary = run_study(&study, &opts, &no_progress).unwrap();
        let modal = Table::read_parquet(out.join("modal.parquet")).unwrap();
        let col = |n: &str| modal.column(n).and_then(|c| c.as_f64()).unwrap().to_vec();
        let (st, lo, f) = (col("storage_modulus"), col("loss_modulus"), col("freq_hz"));
        let Some(rfmlab::output::ColumnData::Str(kind)) = modal.column("method") else {
            panic!("modal.method is a string column")
        };
        let iem = kind.iter().position(|k| k == "iem").expect("IEM row");
        let band = kind
            .iter()
            .position(|k| k == "rfm_model1_band")
            .expect("band row");
        // Both against the truth curve at the IEM's mode frequency.
        let e = law.modulus(&truth, 2.0 * std::f64::consts::PI * f[iem]);
        let rel = |k: usize| ((st[k] - e.re) / e.re, (lo[k] - e.im) / e.im);
        let m4 = summary.models.iter().find(|m| m.model == "model4").unwrap();
        let worst = m4
            .identified
            .iter()
            .zip(&truth)
            .map(|(a, b)| ((a - b) / b).abs())
            .fold(0.0, f64::max);
        eprintln!(
            "estimator {with_model}: IEM {:?} band {:?} Model 4 worst {worst:.2e} (f {:?})",
            rel(iem),
            rel(band),
            f
        );
        (rel(iem), rel(band), worst)
    };
    // Measured here: without the model IEM (-1.2 %, +10.2 %), Model 4 worst parameter 32 %;
    // with it IEM (-1.0 %, +2.1 %), band (-0.2 %, -2.1 %), Model 4 5e-4 (the two quadratures
    // differ: 1/32 Hz here, 1/8 Hz in the correction). The IEM's and the band fit's remaining
    // errors are the methods' own (a constant modulus for a frequency-dependent one).
    let (iem0, _, m40) = run(false);
    assert!(
        iem0.1.abs() > 0.05,
        "without the model the IEM E'' should be biased: {iem0:?}"
    );
    assert!(
        m40 > 0.05,
        "without the model Model 4 should be biased: {m40}"
    );
    let (iem, band, m4) = run(true);
    assert!(
        iem.0.abs() < 0.02 && iem.1.abs() < 0.05,
        "IEM with leakage model: {iem:?}"
    );
    assert!(
        band.0.abs() < 0.02 && band.1.abs() < 0.05,
        "band Model 1 with leakage model: {band:?}"
    );
    assert!(
        m4 < 2e-3,
        "Model 4 with leakage model: worst parameter error {m4}"
    );
}

/// A certified ROM is reused from the cache on the second run (same key), with the same
/// results to the bit; a different tolerance is a different key and builds anew.
#[test]
fn rom_cache_is_reused_and_keyed() {
    let dir = tempfile::tempdir().unwrap();
    let freq = lines_hz(1.0, 60.0, 1.0);
    let law = rfmlab::material::model_from_name("model1", None).unwrap();
    let (truth, _) = rfmlab::material::paper_table4(1);
    let data = dir.path().join("m1.uff");
    write_data(&data, "L1", law.as_ref(), &truth, &freq);
    let cache = dir.path().join("cache");
    let analyses = "[analyses]\nper_line = false\nsensitivity = false\nfigures = false\n";
    let run = |tol: &str| {
        let out = dir.path().join("out");
        let text = study_text(
            "cache",
            &out,
            &data,
            (1.0, 60.0),
            &[("model1", initial_of(1))],
            analyses,
            "rom",
        )
        .replace(
            "tolerance = 1e-9\n",
            &format!("tolerance = 1e-9\nrom_tolerance = {tol}\n"),
        );
        let file = write(&dir.path().join("cache.toml"), &text);
        let study = rfmlab::study::load(&file).unwrap();
        let opts = RunOptions {
            rom_cache: Some(cache.clone()),
            ..RunOptions::default()
        };
        let s = run_study(&study, &opts, &no_progress).unwrap();
        let report = std::fs::read_to_string(out.join("report.md")).unwrap();
        (
            s.models[0].identified.clone(),
            report.contains("loaded from the ROM cache"),
        )
    };
    // The cached ROMs (beside each, the lock a run holds while it builds that entry).
    let roms = || {
        std::fs::read_dir(&cache)
            .unwrap()
            .filter(|e| e.as_ref().unwrap().path().extension() == Some("json".as_ref()))
            .count()
    };
    let (p1, cached1) = run("1e-6");
    assert!(!cached1, "first run builds the ROM");
    assert_eq!(roms(), 1);
    let (p2, cached2) = run("1e-6");
    assert!(cached2, "second run loads the ROM");
    assert_eq!(
        p1.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
        p2.iter().map(|x| x.to_bits()).collect::<Vec<_>>()
    );
    let (_, cached3) = run("2e-6");
    assert!(!cached3, "another tolerance is another ROM");
    assert_eq!(roms(), 2);
}
