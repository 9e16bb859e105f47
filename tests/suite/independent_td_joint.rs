//! A joint that is not the paper's, measured in the time domain by code rfmlab did not write
//! (`scripts/independent_td_joint.py`: numpy, scipy and scikit-fem, its own reduced basis and
//! its own Welch H1 chain): a steel beam 400 x 8 x 25 mm on a 3 mm bond line 30 mm long at its
//! end, four points on the upper face, the force at point 2, Model 4 with E0 7.2 MPa, h 1.1 MPa,
//! E1 2.8 MPa, eta1 5 kPa s. The script builds, with its own code, the discretisation a study
//! with rfmlab's default `element_size = 0.005` gets for this joint (20-node hexahedra, two
//! through the bond line). Its output (seed 21) is bundled in `studies/data/independent_td/`
//! (provenance and command in its README). `studies/independent_td_joint.toml` (the study a user
//! would write, with the estimator stated) run in memory through `Study::load -> plan ->
//! pipeline::run`: the two codes' lowest modes agree within 1e-6 and the MAP's Laplace 95 %
//! intervals hold the truth for all four parameters; the results and the report carry the
//! mesh's estimated discretisation error, within a factor of two of what the graded reference
//! shows. The ignored `the_generator_remakes_the_bundled_data` runs the script again (45 s)
//! and checks that it gives the bundled files.
//!
//! What this does not test: the mesh's own convergence. The script's graded 27-node mesh of the
//! same joint (`--mesh graded`) puts the first y mode 1.5 % below the default mesh's, and a fit
//! of its data on the default mesh is outside its intervals; `rfmlab check` warns about it
//! (docs/validation.md, "Other joints").
//!
//! Python (the ignored regeneration only): env RFMLAB_PYTHON (numpy, scipy, scikit-fem, pyuff);
//! skipped with a notice when missing, unless env CI is set.

use crate::python_checks::{python_with, run_script};
use std::path::Path;

/// Model 4 truth (E0, h, E1, eta1), SI, as the script's truth.json states it.
const TRUTH: [f64; 4] = [7.2e6, 1.1e6, 2.8e6, 5.0e3];

/// The bundled data's folder.
fn bundled() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("studies/data/independent_td")
}

/// The generator's truth.json in `dir`.
fn truth_of(dir: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(dir.join("truth.json")).unwrap();
    serde_json::from_str(&text).unwrap()
}

/// Run the generator into `dir` with the bundled data's arguments; None (skip) when Python
/// lacks its packages.
fn generate(dir: &Path, seed: u64, test: &str) -> Option<()> {
    let py = python_with(&["numpy", "scipy", "skfem", "pyuff"], test)?;
    let dir_arg = dir.display().to_string();
    let seed = seed.to_string();
    run_script(
        &py,
        "independent_td_joint.py",
        &[
            &dir_arg, "--mesh", "matched", "--seed", &seed, "--jobs", "1",
        ],
        &[("OMP_NUM_THREADS", "1")],
    );
    Some(())
}

/// The bundled study, written into `dir`, with its data path pointed at the bundled
/// `level1.uff`.
fn study_file(dir: &Path) -> std::path::PathBuf {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(root.join("studies/independent_td_joint.toml")).unwrap();
    let from = r#"files = ["data/independent_td/level1.uff"]"#;
    assert!(text.contains(from), "the study's files line changed");
    let uff = bundled().join("level1.uff");
    let text = text.replace(from, &format!("files = [{:?}]", uff.display().to_string()));
    let path = dir.join("study.toml");
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn independent_time_domain_joint_posterior_holds_the_truth() {
    let dir = tempfile::tempdir().unwrap();
    let truth = truth_of(&bundled());
    let study = rfmlab::Study::load(study_file(dir.path())).unwrap_or_else(|e| panic!("{e}"));

    // the same discretisation built by two codes: the whole joint's modes at 7.2 MPa (real)
    let built = rfmlab::study::build::build_model(&study.structure, "study.toml").unwrap();
    let ours = rfmlab::modes::complex_modes(
        &built.model,
        rfmlab::common::C64::new(7.2e6, 0.0),
        6,
        built.dof_axes.as_deref(),
        &rfmlab::modes::ModesParams::default(),
    )
    .unwrap();
    let theirs = truth["modes"]["real_modulus_7.2MPa"].as_array().unwrap();
    for (k, (a, b)) in ours.iter().zip(theirs).enumerate() {
        let b = b["f_hz"].as_f64().unwrap();
        let rel = (a.freq_hz - b) / b;
        eprintln!(
            "mode {}: rfmlab {:.6} Hz, script {b:.6} Hz ({rel:+.1e})",
            k + 1,
            a.freq_hz
        );
        assert!(rel.abs() < 1e-6, "mode {}: {rel:.2e}", k + 1);
    }

    // in memory: Study::load -> plan -> pipeline::run
    let mut plan = study.plan().unwrap();
    plan.figures = false;
    let mut ex = crate::shared_rom_cache::executor();
    let results = rfmlab::pipeline::run(&plan, &mut ex).unwrap_or_else(|e| panic!("{e}"));
    // the mesh's own error, which these data cannot show (they share the discretisation): the
    // first y mode (mode 2) of the default mesh is 1.8 % above the script's converged graded
    // reference (docs/validation.md); the estimate must say so within a factor of two and warn
    let mesh = results.mesh_error();
    assert_eq!(mesh.len(), 6, "six modes in the mesh-error estimate");
    let y1 = &mesh[1];
    eprintln!(
        "mesh error: mode 2 at {:.4} Hz, estimated {:+.3} % (order {})",
        y1.freq_hz,
        100.0 * y1.rel_error,
        y1.order
    );
    assert!(
        (0.009..0.036).contains(&y1.rel_error),
        "mode 2's estimated mesh error {:.3} % is not within a factor of two of the 1.8 % the converged reference shows",
        100.0 * y1.rel_error
    );
    let out = tempfile::tempdir().unwrap();
    let res_dir = out.path().join("results");
    rfmlab::report::write(&results, &res_dir).unwrap();
    let report = std::fs::read_to_string(res_dir.join("report.md")).unwrap();
    assert!(
        report.contains("## Mesh discretisation error")
            && report.contains("the results do not include it"),
        "the report shows the mesh error and its warning"
    );

    let post = results
        .posteriors()
        .find(|p| p.level == "L1" && p.model == "model4")
        .expect("model4's posterior at L1");
    assert_eq!(post.names, ["E0", "h", "E1", "eta1"]);
    let lap = &post.map.laplace;
    assert!(
        lap.positive_definite,
        "the Laplace covariance is not usable"
    );
    let d = post.names.len();
    for k in 0..d {
        let map = post.map.map_physical[k];
        let sd = lap.cov_physical[k * d + k].sqrt();
        let z = (map - TRUTH[k]) / sd;
        eprintln!(
            "{}: MAP {:+.4} % from the truth, Laplace sd {:.4} %, z {z:+.2}",
            post.names[k],
            100.0 * (map / TRUTH[k] - 1.0),
            100.0 * sd / TRUTH[k]
        );
        assert!(z.abs() < 1.96, "{}: z = {z:.2}", post.names[k]);
        assert!(
            ((map - TRUTH[k]) / TRUTH[k]).abs() < 2e-3,
            "{}: {:.3} % off",
            post.names[k],
            100.0 * (map / TRUTH[k] - 1.0)
        );
    }
}

#[test]
#[ignore = "slow: runs the scikit-fem generator again (45 s, one thread) to check the bundled data; run with --ignored"]
fn the_generator_remakes_the_bundled_data() {
    let dir = tempfile::tempdir().unwrap();
    if generate(dir.path(), 21, "the_generator_remakes_the_bundled_data").is_none() {
        return;
    }
    // the same FRFs and coherences, value by value, to the UFF's printed precision
    let ours = rfmlab::data::read_uff(bundled().join("level1.uff")).unwrap();
    let again = rfmlab::data::read_uff(dir.path().join("level1.uff")).unwrap();
    assert_eq!(ours.datasets.len(), again.datasets.len());
    for (a, b) in ours.datasets.iter().zip(&again.datasets) {
        assert_eq!(a.ids, b.ids);
        let (va, vb) = (a.values.to_complex(), b.values.to_complex());
        assert_eq!(va.len(), vb.len(), "{:?}", a.ids);
        let peak = va.iter().fold(0.0f64, |m, v| m.max(v.norm()));
        let worst = va
            .iter()
            .zip(&vb)
            .fold(0.0f64, |m, (x, y)| m.max((x - y).norm()));
        assert!(
            worst <= 1e-6 * peak,
            "{:?}: {:.2e} of the peak",
            a.ids,
            worst / peak
        );
    }
    // the same truth and the same modes
    let (t0, t1) = (truth_of(&bundled()), truth_of(dir.path()));
    assert_eq!(t0["geometry"], t1["geometry"], "truth.json's geometry");
    assert_eq!(t0["law"]["params"], t1["law"]["params"], "truth.json's law");
    for key in ["name", "force_rms_N", "params", "seed"] {
        assert_eq!(
            t0["levels"][0][key], t1["levels"][0][key],
            "truth.json's level {key}"
        );
    }
    let modes = |t: &serde_json::Value| -> Vec<f64> {
        t["modes"]["real_modulus_7.2MPa"]
            .as_array()
            .unwrap()
            .iter()
            .map(|m| m["f_hz"].as_f64().unwrap())
            .collect()
    };
    let (m0, m1) = (modes(&t0), modes(&t1));
    assert_eq!(m0.len(), m1.len());
    for (a, b) in m0.iter().zip(&m1) {
        assert!(((a - b) / a).abs() < 1e-9, "mode {a} Hz against {b} Hz");
    }
}
