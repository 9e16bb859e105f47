//! Acceptance on the independent virtual experiment (studies/data/virtual/, made by separate
//! Python/scikit-fem code, not rfmlab): global Model 4 at both levels of `model4_td` (Welch H1
//! with real Hann leakage, white force over (0, 500] Hz) with the estimator declared as the data
//! were made (`studies/virtual_td.toml`) is within 1.5 % of the truth for every parameter and
//! closer to it than without the estimator; the old assumption (force only from the first line,
//! `force_band_hz = [1, 500]`) is not; on `model4_fd` (exact FRF at the lines, no leakage,
//! `studies/virtual_fd.toml`) within 0.1 %.

use rfmlab::report::run_study;
use rfmlab::report::RunOptions;
use std::path::Path;

/// Truth per level in Model 4's parameter order (E0, h, E1, eta1), SI.
fn truth(level: &str) -> [f64; 4] {
    match level {
        "L1" => [7.2e6, 1.1e6, 2.8e6, 5.0e3],
        "L2" => [5.6e6, 0.85e6, 3.5e6, 4.2e3],
        l => panic!("level {l}"),
    }
}

/// Relative errors of Model 4 per level (L1, L2), from a study file's text written to `dir`
/// (paths to the bundled data made absolute).
fn fit(dir: &Path, name: &str, text: &str) -> Vec<(String, [f64; 4])> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("studies");
    let text = text.replace(
        "\"data/virtual/",
        &format!("\"{}/data/virtual/", root.display()),
    );
    let file = dir.join(format!("{name}.toml"));
    std::fs::write(&file, text).unwrap();
    let study = rfmlab::study::load(&file).unwrap();
    let opts = RunOptions {
        no_figures: true,
        output_dir: Some(dir.join(name)),
        rom_cache: Some(crate::shared_rom_cache::runs_folder()),
    };
    let summary = run_study(&study, &opts, &|_| {}).unwrap();
    summary
        .models
        .iter()
        .filter(|m| m.model == "model4")
        .map(|m| {
            assert_eq!(m.param_names, ["E0", "h", "E1", "eta1"]);
            let t = truth(&m.level);
            let mut e = [0.0; 4];
            for k in 0..4 {
                e[k] = (m.identified[k] - t[k]) / t[k];
            }
            eprintln!(
                "{name} {}: E0 {:+.3} %, h {:+.3} %, E1 {:+.3} %, eta1 {:+.3} % ({} iterations)",
                m.level,
                100.0 * e[0],
                100.0 * e[1],
                100.0 * e[2],
                100.0 * e[3],
                m.iterations
            );
            (m.level.clone(), e)
        })
        .collect()
}

fn worst(e: &[f64; 4]) -> f64 {
    e.iter().fold(0.0, |a: f64, b| a.max(b.abs()))
}

#[test]
fn independent_virtual_experiment_model4_meets_its_targets() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("studies");
    let td = std::fs::read_to_string(root.join("virtual_td.toml")).unwrap();
    let fd = std::fs::read_to_string(root.join("virtual_fd.toml")).unwrap();
    let dir = tempfile::tempdir().unwrap();

    // The estimator section as the data were made, without it, and with the old band.
    let start = td.find("[measurements.estimator]").unwrap();
    let end = start + td[start..].find("[[measurements.levels]]").unwrap();
    let none = format!("{}{}", &td[..start], &td[end..]);
    let old = td.replace(
        "force_band_hz = [0.0, 500.0]",
        "force_band_hz = [1.0, 500.0]",
    );
    assert_ne!(old, td);

    // Measured: with (max 0.74 %, eta1 at L1), without (5.0 %), old band (9.2 %).
    let with = fit(dir.path(), "td_with", &td);
    let without = fit(dir.path(), "td_without", &none);
    let old = fit(dir.path(), "td_old_band", &old);
    assert_eq!(with.len(), 2);
    for (((level, w), (_, n)), (_, o)) in with.iter().zip(&without).zip(&old) {
        assert!(
            worst(w) < 0.015,
            "{level}: with the estimator {w:?} (target 1.5 %)"
        );
        assert!(
            worst(w) < worst(n),
            "{level}: with {w:?} not closer than without {n:?}"
        );
        assert!(
            worst(o) > 0.03,
            "{level}: the old band (1, 500] should miss: {o:?}"
        );
    }

    // Measured: max 0.05 % (eta1 at L1).
    for (level, e) in fit(dir.path(), "fd", &fd) {
        assert!(worst(&e) < 1e-3, "{level}: fd {e:?} (target 0.1 %)");
    }
}

/// On the time-domain set, "the posterior 95 % intervals contain the
/// truth": `studies/bayes_virtual_td.toml` as shipped (coherence noise model, the channels'
/// errors as the Welch leakage jitter, `channel_correlation = "leakage"`) without its samplers,
/// the MAP and its Laplace sd (the samplers' sds are within 4 % of it there). Measured: |z| <=
/// 1.6 for every parameter at both levels (the full run with NUTS and TMCMC: |z| <= 1.60, all 16
/// intervals hold the truth); with independent channels Level 2's eta1 was at z = 2.01 (NUTS).
#[test]
fn posterior_intervals_on_the_time_domain_set_hold_the_truth() {
    use rfmlab::output::{ColumnData, Table};
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("studies");
    let text = std::fs::read_to_string(root.join("bayes_virtual_td.toml"))
        .unwrap()
        .replace("samplers = [\"nuts\", \"tmcmc\"]", "samplers = []");
    assert!(text.contains("samplers = []") && text.contains("channel_correlation = \"leakage\""));
    let dir = tempfile::tempdir().unwrap();
    fit(dir.path(), "td_posterior", &text);
    let lap = Table::read_parquet(dir.path().join("td_posterior").join("laplace.parquet")).unwrap();
    let strs = |name: &str| match lap.column(name) {
        Some(ColumnData::Str(v)) => v.clone(),
        _ => panic!("laplace.{name} is not a string column"),
    };
    let (level, param) = (strs("level"), strs("parameter"));
    let map = lap.column("map").and_then(|c| c.as_f64()).unwrap();
    let sd = lap.column("sd").and_then(|c| c.as_f64()).unwrap();
    let names = ["E0", "h", "E1", "eta1"];
    let mut checked = 0;
    for i in 0..lap.n_rows() {
        let Some(k) = names.iter().position(|n| *n == param[i]) else {
            continue;
        };
        let t = truth(&level[i])[k];
        let z = (map[i] - t) / sd[i];
        eprintln!(
            "{} {}: MAP {:+.4} % from the truth, Laplace sd {:.4} %, z {z:+.2}",
            level[i],
            param[i],
            100.0 * (map[i] / t - 1.0),
            100.0 * sd[i] / t
        );
        assert!(z.abs() < 1.96, "{} {}: z = {z:.2}", level[i], param[i]);
        checked += 1;
    }
    assert_eq!(checked, 8);
}
