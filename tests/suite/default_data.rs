//! The default data set (studies/data/paper_virtual_*.uff) is what `rfmlab simulate` makes from the
//! committed experiment file: regenerate it into a temporary folder and compare value by value.
//! (Values, not bytes: faer picks SIMD kernels at run time, so the last bits may differ between CPUs;
//! the UFF files carry 12 significant digits and the comparison allows 1e-8 of each FRF's peak.)

use rfmlab::data::uff_frf::{frf_set_from_uff, UffImportOptions};
use std::path::PathBuf;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

#[test]
fn regenerating_the_default_data_reproduces_the_committed_files() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("paper_virtual.uff");
    let status = std::process::Command::new(env!("CARGO_BIN_EXE_rfmlab"))
        .args(["--quiet", "simulate"])
        .arg(root().join("studies/data/paper_experiment.toml"))
        .arg("--out")
        .arg(&out)
        .status()
        .expect("run rfmlab simulate");
    assert!(status.success(), "rfmlab simulate failed");
    for level in ["L1", "L2"] {
        let committed = root().join(format!("studies/data/paper_virtual_{level}.uff"));
        let fresh = dir.path().join(format!("paper_virtual_{level}.uff"));
        let opts = UffImportOptions::default();
        let a = frf_set_from_uff(&[(committed.clone(), level.to_string())], &opts).unwrap();
        let b = frf_set_from_uff(&[(fresh.clone(), level.to_string())], &opts).unwrap();
        assert_eq!(a.levels.len(), 1);
        assert_eq!(b.levels.len(), 1);
        let (la, lb) = (&a.levels[0], &b.levels[0]);
        assert_eq!(la.freq_hz, lb.freq_hz, "{level}: frequency grid");
        assert_eq!(la.freq_hz.len(), 500, "{level}: 1-500 Hz at 1 Hz");
        assert_eq!(la.channels.len(), 4, "{level}: points 1-4");
        for (ca, cb) in la.channels.iter().zip(&lb.channels) {
            assert_eq!(
                (ca.response_id, ca.reference_id),
                (cb.response_id, cb.reference_id)
            );
            let peak = ca.values.iter().map(|v| v.norm()).fold(0.0, f64::max);
            let worst = ca
                .values
                .iter()
                .zip(&cb.values)
                .map(|(x, y)| (x - y).norm())
                .fold(0.0, f64::max);
            assert!(
                worst <= 1e-8 * peak,
                "{level} point {}: max difference {worst:e} vs peak {peak:e}",
                ca.response_id
            );
            let (ga, gb) = (
                ca.coherence.as_ref().unwrap(),
                cb.coherence.as_ref().unwrap(),
            );
            let wc = ga
                .iter()
                .zip(gb)
                .map(|(x, y)| (x - y).abs())
                .fold(0.0, f64::max);
            assert!(
                wc <= 1e-8,
                "{level} point {}: coherence differs by {wc:e}",
                ca.response_id
            );
        }
    }
}

#[test]
fn default_data_is_labelled_as_simulated_and_states_its_truth() {
    let text =
        std::fs::read_to_string(root().join("studies/data/paper_virtual.truth.json")).unwrap();
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(v["simulated"], serde_json::json!(true));
    let levels = v["levels"].as_array().unwrap();
    assert_eq!(levels.len(), 2);
    assert_eq!(levels[0]["law"], "model4");
    assert!((levels[0]["params"]["E0"].as_f64().unwrap() - 6.67e6).abs() < 1.0);
    let uff = std::fs::read_to_string(root().join("studies/data/paper_virtual_L1.uff")).unwrap();
    assert!(
        uff.to_ascii_uppercase().contains("SIMULATED"),
        "the UFF id lines must say the data are simulated"
    );
}
