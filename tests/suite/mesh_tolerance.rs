//! The mesh to a stated accuracy, checked against the structure rather than a mesh of it: the
//! references are independent scikit-fem models (27-node hexahedra graded towards the bond
//! line's edges, refined to about 200 000 DOFs, extrapolated; `scripts/independent_td_joint.py
//! --mesh converged`, `studies/data/virtual/converged/`).
//!
//! 1. The estimate's rules (order 1; twice the step where convergence is not monotone; the
//!    stiffness excess fitted over the modes the points see).
//! 2. The paper's block refined by the default rule: its first y mode's estimated error is
//!    conservative against the independent continuum (1-3 times the actual), and the uniform
//!    5 mm mesh the rule replaces is at least 1.5 % stiff.
//! 3. A 5 mm block 40 mm long, 10 mm in from the end of a 250 x 12 x 20 mm beam, on time-domain
//!    data of the independent converged model: with the default mesh rule every Laplace 95 %
//!    interval of Model 4 at both levels holds the truth; the same study on the uniform 5 mm
//!    mesh with no allowance (the behaviour before) puts a parameter more than 3 sd off.
//! 4. A single-lap joint: the refinement's estimate sees the strips' bending and clamp (the
//!    bond line holds 2 % of the first mode's strain energy), conservative against the
//!    independent continuum, and the excess goes to the strips.

use rfmlab::discretisation::{
    extrapolated_error, observed_order, stiffness_excess, ModeError, RefineParams,
};
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).to_path_buf()
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn mode(rel: f64, phi: f64, seen: f64) -> ModeError {
    ModeError {
        mode: 1,
        freq_hz: 100.0,
        freq_refined_hz: 100.0 * (1.0 - rel),
        error_hz: 100.0 * rel,
        rel_error: rel,
        order: 1.0,
        adhesive_share: phi,
        measured_share: seen,
    }
}

#[test]
fn the_estimate_s_rules() {
    // monotone convergence: the last step at order 1
    assert!((observed_order(0.4, 0.2) - 1.0).abs() < 1e-12);
    assert_eq!(extrapolated_error(0.2, 1.0), 0.2);
    // not monotone (a step that grows or changes sign): twice the last step
    assert!(observed_order(0.1, 0.2).is_nan());
    assert!(observed_order(0.1, -0.05).is_nan());
    assert_eq!(extrapolated_error(0.2, f64::NAN), 0.4);
    // one adhesive excess explains 2 e / f = phi delta_a exactly: no scatter, sd half the
    // excess, nothing charged to the adherends
    let x = stiffness_excess(&[mode(0.005, 1.0, 1.0), mode(0.0025, 0.5, 1.0)]);
    assert!(
        (x.adhesive - 0.01).abs() < 1e-9 && (x.adhesive_sd - 0.005).abs() < 1e-9,
        "{x:?}"
    );
    assert!(x.adherend.abs() < 1e-9, "{x:?}");
    // a mode the points do not see does not count
    let x = stiffness_excess(&[mode(0.005, 1.0, 1.0), mode(0.05, 1.0, 0.0)]);
    assert!((x.adhesive - 0.01).abs() < 1e-12, "{x:?}");
    // modes of a lap joint (1-13 % in the bond line) stiff through the strips: the excess is
    // the adherends', not 20-100 times it in the adhesive
    let lap = [mode(0.0015, 0.02, 1.0), mode(0.0014, 0.13, 1.0)];
    let x = stiffness_excess(&lap);
    assert!(
        (x.adherend - 0.003).abs() < 3e-4 && x.adhesive.abs() < 0.003,
        "{x:?}"
    );
    // every mode the adhesive's: the ridge keeps the adherends' part at zero
    let x = stiffness_excess(&[mode(0.004, 0.98, 1.0), mode(0.0039, 0.97, 1.0)]);
    assert!(
        x.adherend.abs() < 5e-4 && (x.adhesive - 0.0082).abs() < 3e-4,
        "{x:?}"
    );
}

/// The paper's joint as the mesher builds it (the reference's geometry and materials).
fn paper_spec() -> rfmlab::fe::joint::JointSpec {
    rfmlab::fe::joint::JointSpec::paper()
}

#[test]
fn the_paper_block_s_refined_mesh_against_the_independent_continuum() {
    let truth = json(&root().join("studies/data/virtual/converged/paper_block/truth.json"));
    let modes = truth["model"]["mesh_convergence"]["modes"]
        .as_array()
        .unwrap();
    let y = modes
        .iter()
        .find(|m| m["energy_y_finest"].as_f64().unwrap() > 0.5)
        .expect("a y mode in the reference");
    let f_ref = y["extrapolated"].as_f64().unwrap();
    let p = RefineParams {
        tolerance: rfmlab::study::MeshRule::DEFAULT_TOLERANCE,
        allowance: false,
        reference_modulus_pa: 7.2e6,
    };
    let r = rfmlab::discretisation::select(&paper_spec(), &p, &|l| eprintln!("{l}")).unwrap();
    let d = &r.discretisation;
    assert!(
        d.reached,
        "the default tolerance is reached on the paper's block"
    );
    let m = d.measured_mode_near(f_ref).unwrap();
    let actual = (m.freq_hz - f_ref) / f_ref;
    let level0 = (d.levels[0].freqs_hz[m.mode - 1] - f_ref) / f_ref;
    eprintln!(
        "first y mode: {:.4} Hz on level {} ({} DOFs), reference {f_ref:.4} Hz: estimated {:+.3} %, actual {:+.3} %, uniform 5 mm {:+.3} %",
        m.freq_hz,
        d.chosen,
        d.levels[d.chosen].n_dof,
        100.0 * m.rel_error,
        100.0 * actual,
        100.0 * level0
    );
    assert!(
        actual > 0.0 && m.rel_error >= actual && m.rel_error <= 3.0 * actual,
        "the estimate {:.3} % is not conservative within a factor 3 of the actual {:.3} %",
        100.0 * m.rel_error,
        100.0 * actual
    );
    assert!(level0 > 0.015, "the uniform 5 mm mesh is {level0:.4} stiff");
}

/// The study of the converged block5 joint with Laplace only, with `mesh` replacing its mesh
/// section's element size line; the Laplace z-scores of Model 4 at both levels.
fn z_scores(dir: &Path, mesh: &str) -> Vec<(String, f64)> {
    let studies = root().join("studies");
    let text = std::fs::read_to_string(studies.join("virtual_converged_block5_off_end.toml"))
        .unwrap()
        .replace("\"data/", &format!("\"{}/", studies.join("data").display()))
        .replace("samplers = [\"nuts\", \"tmcmc\"]", "samplers = []");
    let line = text
        .lines()
        .find(|l| l.starts_with("element_size"))
        .expect("the study's element_size line")
        .to_string();
    let text = text.replace(&line, mesh);
    let file = dir.join("study.toml");
    std::fs::write(&file, text).unwrap();
    let study = rfmlab::Study::load(&file).unwrap_or_else(|e| panic!("{e}"));
    let mut plan = study.plan().unwrap();
    plan.figures = false;
    let results = rfmlab::pipeline::run(&plan, &mut crate::shared_rom_cache::executor())
        .unwrap_or_else(|e| panic!("{e}"));
    let truth = json(&root().join("studies/data/virtual/converged/block5_off_end/truth.json"));
    let mut out = Vec::new();
    for post in results.posteriors() {
        let level = truth["levels"]
            .as_array()
            .unwrap()
            .iter()
            .find(|l| l["name"] == post.level.as_str())
            .unwrap();
        let lap = &post.map.laplace;
        let sd = lap.sd_physical();
        for (i, name) in post.names.iter().enumerate().take(4) {
            let t = level["params"][name].as_f64().unwrap();
            let z = (lap.physical[i] - t) / sd[i];
            eprintln!(
                "{} {name}: {:.5e} (truth {t:.5e}, {:+.2} %, sd {:.2} %), z {z:+.2}",
                post.level,
                lap.physical[i],
                100.0 * (lap.physical[i] / t - 1.0),
                100.0 * sd[i] / lap.physical[i]
            );
            out.push((format!("{} {name}", post.level), z));
        }
    }
    out
}

#[test]
fn a_5_mm_block_off_the_beam_s_end_holds_the_continuum_s_truth() {
    let dir = tempfile::tempdir().unwrap();
    // the default rule: refined to the tolerance, the remaining error in the posterior
    let z = z_scores(dir.path(), "element_size = 0.005");
    assert_eq!(z.len(), 8, "Model 4 at two levels");
    let outside: Vec<_> = z.iter().filter(|(_, z)| z.abs() > 1.96).collect();
    assert!(
        outside.is_empty(),
        "95 % intervals that miss the truth: {outside:?}"
    );
    // before: the uniform 5 mm mesh (one element through the block), trusted as exact
    let z = z_scores(
        dir.path(),
        "element_size = 0.005\nrefine = false\nallowance = false",
    );
    let worst = z.iter().map(|(_, z)| z.abs()).fold(0.0, f64::max);
    assert!(
        worst > 3.0,
        "the uniform mesh without allowance should miss the continuum by more than 3 sd (worst {worst:.2})"
    );
}

/// The single-lap joint of `studies/virtual_converged_lap1.toml` (aluminium strips 100 x 3 x 25
/// mm, 25 mm overlap, a 1 mm bond line, clamped) refined by the default rule: its first y mode's
/// estimate sees the strips' error (the bond line holds 2 % of that mode's strain energy) and is
/// conservative against the independent continuum, and the excess is charged to the strips,
/// not 50 times over to the adhesive.
#[test]
fn a_lap_joint_s_estimate_sees_the_strips() {
    let study = rfmlab::Study::load(root().join("studies/virtual_converged_lap1.toml"))
        .unwrap_or_else(|e| panic!("{e}"));
    let rfmlab::study::StructureSource::Lap(spec, _) = &study.structure.source else {
        panic!("a lap joint");
    };
    let mut spec = spec.clone();
    spec.points = rfmlab::study::build::point_specs(&study.structure);
    let truth = json(&root().join("studies/data/virtual/converged/lap1/truth.json"));
    let f_ref = truth["model"]["mesh_convergence"]["modes"][0]["extrapolated"]
        .as_f64()
        .unwrap();
    let p = RefineParams {
        tolerance: rfmlab::study::MeshRule::DEFAULT_TOLERANCE,
        allowance: true,
        reference_modulus_pa: 7.2e6,
    };
    let r = rfmlab::discretisation::select(&spec, &p, &|l| eprintln!("{l}")).unwrap();
    let d = &r.discretisation;
    let m = d.measured_mode_near(f_ref).unwrap();
    let actual = (m.freq_hz - f_ref) / f_ref;
    eprintln!(
        "lap first y mode: {:.4} Hz ({} DOFs), reference {f_ref:.4} Hz: estimated {:+.3} %, actual {:+.3} %; excess adhesive {:+.3} %, strips {:+.3} %",
        m.freq_hz,
        d.levels[d.chosen].n_dof,
        100.0 * m.rel_error,
        100.0 * actual,
        100.0 * d.stiffness_excess,
        100.0 * d.adherend_excess
    );
    assert!(m.adhesive_share < 0.05, "share {}", m.adhesive_share);
    assert!(
        actual > 0.0 && m.rel_error >= actual,
        "the estimate {:.3} % is not conservative against the actual {:.3} %",
        100.0 * m.rel_error,
        100.0 * actual
    );
    assert!(
        d.adherend_excess > 0.0 && d.stiffness_excess.abs() < 0.1,
        "the strips' excess {:.4}, the adhesive's {:.4}",
        d.adherend_excess,
        d.stiffness_excess
    );
}
