//! The mesh refinement on the joints of independent, mesh-converged references
//! (`studies/data/virtual/converged/*/`, each with its study
//! `studies/virtual_converged_<joint>.toml`): for each joint, the mesh rfmlab's default rule
//! chooses from the study, its DOFs and the refinement's time, the first measured mode's
//! estimated discretisation error, and its actual error against the reference's extrapolated
//! continuum (scikit-fem 27-node graded meshes refined up to about 200 000 DOFs,
//! `scripts/independent_td_joint.py`).
//!
//! `cargo run --release --example mesh_refinement [-- --repeat N]` (docs/performance.md, "The
//! mesh to a tolerance"; `--repeat` times each refinement N times and reports the median).
//! Modes at the reference's 7.2 MPa real modulus.

use rfmlab::discretisation::{self, Meshed, RefineParams};
use rfmlab::study::{StructureSource, Study};
use std::path::Path;
use std::time::Instant;

const MODULUS_PA: f64 = 7.2e6;

/// One refinement of `spec` (a fresh choice each call: the memo is keyed by the tolerance,
/// which is nudged by `k` ulps).
fn refine<S: Meshed>(spec: &S, k: usize) -> (discretisation::Discretisation, f64) {
    let p = RefineParams {
        tolerance: rfmlab::study::MeshRule::DEFAULT_TOLERANCE * (1.0 + 1e-12 * k as f64),
        allowance: false,
        reference_modulus_pa: MODULUS_PA,
    };
    let t0 = Instant::now();
    let r = discretisation::select(spec, &p, &|_| {}).expect("the refinement");
    (r.discretisation, t0.elapsed().as_secs_f64())
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let repeat = args
        .iter()
        .position(|a| a == "--repeat")
        .and_then(|i| args.get(i + 1))
        .and_then(|v| v.parse::<usize>().ok())
        .unwrap_or(1)
        .max(1);
    let repo = Path::new(env!("CARGO_MANIFEST_DIR"));
    let root = repo.join("studies/data/virtual/converged");
    let mut dirs: Vec<_> = std::fs::read_dir(&root)
        .expect("the converged references")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.join("truth.json").exists())
        .collect();
    dirs.sort();
    println!(
        "{:<16} {:>5} {:>8} {:>7} {:>7} {:>7} {:>10} {:>10} {:>9} {:>9} {:>9}",
        "joint",
        "level",
        "edge_mm",
        "dofs",
        "med_s",
        "max_s",
        "f_hz",
        "ref_hz",
        "est_%",
        "actual_%",
        "level0_%"
    );
    let mut medians = Vec::new();
    let mut slowest: f64 = 0.0;
    for dir in dirs {
        let name = dir.file_name().unwrap().to_string_lossy().to_string();
        let study_file = repo.join(format!("studies/virtual_converged_{name}.toml"));
        let Ok(study) = Study::load(&study_file) else {
            eprintln!("{name}: no study {}", study_file.display());
            continue;
        };
        let truth: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(dir.join("truth.json")).expect("truth.json"),
        )
        .expect("truth.json");
        // the reference: the first mode with most of its motion in y, extrapolated
        let modes = truth["model"]["mesh_convergence"]["modes"]
            .as_array()
            .expect("mesh_convergence.modes");
        let Some(ref_mode) = modes
            .iter()
            .find(|m| m["energy_y_finest"].as_f64().unwrap_or(0.0) > 0.5)
        else {
            continue;
        };
        let f_ref = ref_mode["extrapolated"].as_f64().expect("extrapolated");
        let mut runs = Vec::new();
        let mut d = None;
        for k in 0..repeat {
            let (dk, secs) = match &study.structure.source {
                StructureSource::Mesher(_) => {
                    let spec = rfmlab::study::build::joint_spec(&study.structure).expect("a joint");
                    refine(&spec, k)
                }
                StructureSource::Lap(spec, _) => {
                    let mut spec = spec.clone();
                    spec.points = rfmlab::study::build::point_specs(&study.structure);
                    refine(&spec, k)
                }
                StructureSource::MatrixMarket(_) => unreachable!("references are meshed joints"),
            };
            runs.push(secs);
            d = Some(dk);
        }
        let d = d.expect("one run");
        runs.sort_by(f64::total_cmp);
        let (med, max) = (runs[runs.len() / 2], runs[runs.len() - 1]);
        medians.push(med);
        slowest = slowest.max(max);
        // the measured mode nearest the reference's
        let Some(m) = d.measured_mode_near(f_ref) else {
            continue;
        };
        let lvl = &d.levels[d.chosen];
        let f0 = d.levels[0].freqs_hz[m.mode - 1];
        println!(
            "{:<16} {:>5} {:>8.3} {:>7} {:>7.1} {:>7.1} {:>10.4} {:>10.4} {:>+9.3} {:>+9.3} {:>+9.3}",
            name,
            lvl.level,
            1e3 * lvl.edge_m,
            lvl.n_dof,
            med,
            max,
            m.freq_hz,
            f_ref,
            100.0 * m.rel_error,
            100.0 * (m.freq_hz - f_ref) / f_ref,
            100.0 * (f0 - f_ref) / f_ref,
        );
    }
    medians.sort_by(f64::total_cmp);
    if let Some(mid) = medians.get(medians.len() / 2) {
        println!("refinement time over the joints: median {mid:.1} s, slowest {slowest:.1} s");
    }
}
