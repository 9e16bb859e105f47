//! `rfmlab rom`: the certified ROM of a study's structure for all points as inputs (the n x n
//! FRF matrix `rfmlab run` builds) or for the excitation point only, as JSON.

use std::process::Command;

/// studies/paper_geometry.toml with 10 mm elements (fast), in `dir`.
fn study_10mm(dir: &std::path::Path) -> std::path::PathBuf {
    let src = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/studies/paper_geometry.toml"
    ))
    .expect("paper_geometry.toml");
    let text = src.replace("element_size = 0.005", "element_size = 0.010");
    assert_ne!(
        text, src,
        "the study's element_size line changed; update this test"
    );
    let file = dir.join("joint_10mm.toml");
    std::fs::write(&file, text).unwrap();
    file
}

fn rom(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_rfmlab"))
        .arg("rom")
        .args(args)
        .env("CI", "true")
        .output()
        .expect("run rfmlab rom")
}

fn json(out: &std::process::Output) -> serde_json::Value {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("JSON on stdout")
}

#[test]
fn rom_certifies_all_inputs_or_the_excitation_point() {
    let dir = tempfile::tempdir().unwrap();
    let file = study_10mm(dir.path());
    let f = file.to_str().unwrap();
    let all = json(&rom(&[f, "--json"]));
    let exc = json(&rom(&[f, "--json", "--inputs", "excitation"]));
    assert_eq!(all["inputs"], serde_json::json!([1, 2, 3, 4]));
    assert_eq!(exc["inputs"], serde_json::json!([2])); // excitation = 2 in the study
    for v in [&all, &exc] {
        let c = &v["certificate"];
        assert_eq!(c["passed"], true);
        // (a model of at most 40,000 DOFs: the shifted Krylov reference, as `rfmlab run` chooses)
        assert_eq!(c["reference"], "shifted Krylov");
        assert!(c["max_rel_error"].as_f64().unwrap() <= 1e-6);
        assert!(c["reference_residual"].as_f64().unwrap() <= 1e-10);
        assert_eq!(c["n_moduli"], 9);
        assert_eq!(c["n_lines"], 25);
    }
    // the basis holds unit loads at every point either way; only the validated FRFs differ
    assert_eq!(
        all["certificate"]["basis_size"],
        exc["certificate"]["basis_size"]
    );
    let bad = rom(&[f, "--inputs", "some"]);
    assert_eq!(bad.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&bad.stderr).contains("--inputs"));
}

/// With eight inputs the certificate's reference is the one `rfmlab run` and `rfmlab diagnose`
/// choose for the same structure and inputs (`rfmlab::rom::Reference::suited`): on a model of
/// at most 40,000 DOFs the shifted Krylov solver, one sparse LU per validation modulus for
/// every input and line at once.
#[test]
fn rom_of_many_inputs_uses_the_reference_run_chooses() {
    let dir = tempfile::tempdir().unwrap();
    let file = study_10mm(dir.path());
    let mut text = std::fs::read_to_string(&file).unwrap();
    // the x direction at each of the four points: eight inputs
    for (id, x) in [(11, 0.100), (12, 0.150), (13, 0.200), (14, 0.250)] {
        text.push_str(&format!(
            "\n[[structure.points]]\nid = {id}\nposition = [{x}, 0.010, 0.010]\ndirection = \"+x\"\n"
        ));
    }
    std::fs::write(&file, text).unwrap();
    let eight = json(&rom(&[file.to_str().unwrap(), "--json"]));
    assert_eq!(
        eight["inputs"],
        serde_json::json!([1, 2, 3, 4, 11, 12, 13, 14])
    );
    assert!(eight["n_dof"].as_u64().unwrap() <= rfmlab::rom::SHIFTED_REFERENCE_MAX_DOF as u64);
    let c = &eight["certificate"];
    assert_eq!(c["reference"], "shifted Krylov");
    assert_eq!(c["reference_direct_points"], 0);
    assert_eq!(c["passed"], true);
    assert!(c["max_rel_error"].as_f64().unwrap() <= 1e-6);
}
