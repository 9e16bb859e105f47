//! The mesh refinement on the joints of independent, mesh-converged references
//! (`studies/data/virtual/converged/*/`): for each joint, the mesh rfmlab's default rule
//! chooses, its DOFs and time, the first y mode's estimated discretisation error, and its
//! actual error against the reference's extrapolated continuum (scikit-fem 27-node graded
//! meshes refined up to about 200 000 DOFs, `scripts/independent_td_joint.py`).
//!
//! `cargo run --release --example mesh_refinement` (docs/performance.md, "The mesh to a
//! tolerance"). Modes at the reference's 7.2 MPa real modulus.

use rfmlab::common::Direction;
use rfmlab::discretisation::{self, RefineParams};
use rfmlab::fe::joint::{JointGeometry, JointSpec, PointSpec};
use std::path::Path;
use std::time::Instant;

const MODULUS_PA: f64 = 7.2e6;

fn spec_of(joint: &serde_json::Value) -> JointSpec {
    let f = |v: &serde_json::Value| v.as_f64().expect("a number");
    let (b, a) = (&joint["beam"], &joint["adhesive"]);
    let mut s = JointSpec::paper();
    s.geometry = JointGeometry {
        beam_length_m: f(&b["length"]),
        beam_thickness_m: f(&b["thickness"]),
        beam_width_m: f(&b["width"]),
        adhesive_length_m: f(&a["length"]),
        adhesive_thickness_m: f(&a["thickness"]),
        adhesive_x_start_m: f(&a["x_start"]),
    };
    s.beam.e_pa = f(&b["E"]);
    s.beam.nu = f(&b["nu"]);
    s.beam.rho_kg_m3 = f(&b["rho"]);
    s.adhesive_nu = f(&a["nu"]);
    s.adhesive_rho_kg_m3 = f(&a["rho"]);
    s.points = joint["points_x"]
        .as_array()
        .expect("points_x")
        .iter()
        .enumerate()
        .map(|(i, x)| PointSpec {
            id: i as u32 + 1,
            position_m: [
                f(x),
                s.geometry.beam_thickness_m,
                0.5 * s.geometry.beam_width_m,
            ],
            direction: Direction::PY,
        })
        .collect();
    s
}

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("studies/data/virtual/converged");
    let mut dirs: Vec<_> = std::fs::read_dir(&root)
        .expect("the converged references")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.join("truth.json").exists())
        .collect();
    dirs.sort();
    println!(
        "{:<16} {:>5} {:>8} {:>7} {:>7} {:>10} {:>10} {:>9} {:>9} {:>9}",
        "joint",
        "level",
        "edge_mm",
        "dofs",
        "time_s",
        "f_y_hz",
        "ref_hz",
        "est_%",
        "actual_%",
        "level0_%"
    );
    let mut times = Vec::new();
    for dir in dirs {
        let read = |name: &str| -> serde_json::Value {
            serde_json::from_str(&std::fs::read_to_string(dir.join(name)).expect(name)).expect(name)
        };
        let (joint, truth) = (read("joint.json"), read("truth.json"));
        let spec = spec_of(&joint);
        // the reference: the first symmetric mode with most of its motion in y, extrapolated
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
        let p = RefineParams {
            tolerance: rfmlab::study::MeshRule::DEFAULT_TOLERANCE,
            allowance: false,
            reference_modulus_pa: MODULUS_PA,
        };
        let t0 = Instant::now();
        let r = discretisation::select(&spec, &p, &|_| {}).expect("the refinement");
        let secs = t0.elapsed().as_secs_f64();
        times.push(secs);
        let d = &r.discretisation;
        // the y mode nearest the reference's
        let Some(m) = d.measured_mode_near(f_ref) else {
            continue;
        };
        let lvl = &d.levels[d.chosen];
        let f0 = d.levels[0].freqs_hz[m.mode - 1];
        println!(
            "{:<16} {:>5} {:>8.3} {:>7} {:>7.1} {:>10.4} {:>10.4} {:>+9.3} {:>+9.3} {:>+9.3}",
            dir.file_name().unwrap().to_string_lossy(),
            lvl.level,
            1e3 * lvl.edge_m,
            lvl.n_dof,
            secs,
            m.freq_hz,
            f_ref,
            100.0 * m.rel_error,
            100.0 * (m.freq_hz - f_ref) / f_ref,
            100.0 * (f0 - f_ref) / f_ref,
        );
    }
    times.sort_by(f64::total_cmp);
    if let (Some(mid), Some(max)) = (times.get(times.len() / 2), times.last()) {
        println!("refinement time: median {mid:.1} s, slowest {max:.1} s");
    }
}
