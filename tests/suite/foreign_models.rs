//! Models from other FE programs: a joint rfmlab did not make (scripts/foreign_joint.py,
//! scikit-fem: a steel beam 200 x 12 x 25 mm on a 2 mm bond line 40 mm long away from the
//! beam's end, 27-node hexahedra) written as Abaqus `*MATRIX OUTPUT` files (FORMAT=MATRIX
//! INPUT, the adherends' and the adhesive's stiffness from separate element sets, the base's
//! DOFs marked with 1e36) and as Harwell-Boeing files (RSA and RUA, with an ANSYS-style mapping
//! file). rfmlab imports both through study files; the imported modes agree with the
//! script's own (scipy eigsh) within 1e-6; Model 4 is identified within 0.1 % from the imported
//! model's exact accelerances (written as UFF); on Welch H1 estimates at the default noise,
//! with the estimator stated in the study, the MAP's Laplace 95 % intervals hold the truth. Plus the readers' error paths.
//!
//! Python: env RFMLAB_PYTHON (numpy, scipy, scikit-fem); skipped with a notice when missing,
//! unless env CI is set.

use crate::python_checks::{python_with, run_script};
use rfmlab::common::C64;
use rfmlab::fe::foreign::{import_model_files, ImportFiles, ImportFormat, Units};
use rfmlab::fe::harwell_boeing::{format_hb, parse_hb};
use rfmlab::fe::model::StructuralModel;
use rfmlab::report::run_study;
use rfmlab::report::RunOptions;
use std::path::{Path, PathBuf};
use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_rfmlab");

/// Model 4 truth (E0, h, E1, eta1), SI.
const TRUTH: [f64; 4] = [7.2e6, 1.1e6, 2.8e6, 5.0e3];

/// Run scripts/foreign_joint.py into `dir`; None (skip) when Python with scikit-fem is absent.
fn generate(dir: &Path, test: &str) -> Option<serde_json::Value> {
    let py = python_with(&["numpy", "scipy", "skfem"], test)?;
    run_script(&py, "foreign_joint.py", &[dir], &[]);
    let text = std::fs::read_to_string(dir.join("modes.json")).unwrap();
    Some(serde_json::from_str(&text).unwrap())
}

/// The [structure] section of the script's joint, imported in `format`.
fn structure(dir: &Path, format: &str) -> String {
    let d = dir.display();
    let import = match format {
        "abaqus" => format!(
            r#"mass = "{d}/abaqus/joint_MASS1.mtx"
stiffness = "{d}/abaqus/joint_STIF1.mtx"
adhesive_sensitivity = "{d}/abaqus/joint_STIF2.mtx"
dof_map = "{d}/abaqus/points.csv""#
        ),
        "harwell_boeing" => format!(
            r#"mass = "{d}/hb/M.hb"
stiffness = "{d}/hb/K_b.hb"
adhesive_sensitivity = "{d}/hb/S.hb"
dof_map = "{d}/hb/points.csv"
mapping = "{d}/hb/joint.mapping""#
        ),
        f => panic!("{f}"),
    };
    let mut s = format!(
        "[structure]\nname = \"foreign joint\"\nsource = \"{format}\"\nexcitation = 2\n\n[structure.import]\n{import}\n"
    );
    for (id, x) in [(1, 0.100), (2, 0.130), (3, 0.160), (4, 0.190)] {
        s += &format!(
            "\n[[structure.points]]\nid = {id}\nposition = [{x}, 0.012, 0.0125]\ndirection = \"+y\"\n"
        );
    }
    s
}

fn build(dir: &Path, format: &str) -> StructuralModel {
    let study = format!(
        "[study]\nname = \"import_{format}\"\n\n{}",
        structure(dir, format)
    );
    let file = dir.join(format!("import_{format}.toml"));
    std::fs::write(&file, study).unwrap();
    let s = rfmlab::study::load(&file).unwrap_or_else(|e| panic!("{e}"));
    rfmlab::study::build::build_model(&s.structure, &file.display().to_string())
        .unwrap_or_else(|e| panic!("{e}"))
        .model
}

fn dense_diff(a: &rfmlab::fe::model::SpMat, b: &rfmlab::fe::model::SpMat) -> f64 {
    // max |a - b| / max |a| over the stored entries of both
    let mut map = std::collections::HashMap::new();
    for t in a.triplet_iter() {
        *map.entry((t.row, t.col)).or_insert(0.0) += *t.val;
    }
    let scale = map.values().fold(0.0f64, |m, v: &f64| m.max(v.abs()));
    for t in b.triplet_iter() {
        *map.entry((t.row, t.col)).or_insert(0.0) -= *t.val;
    }
    map.values().fold(0.0f64, |m, v| m.max(v.abs())) / scale
}

#[test]
fn foreign_joint_modes_match_the_scripts_own_in_both_formats() {
    let dir = tempfile::tempdir().unwrap();
    let Some(info) = generate(dir.path(), "foreign_joint_modes") else {
        return;
    };
    let n_free = info["n_dof_free"].as_u64().unwrap() as usize;
    let e = info["modulus_pa"].as_f64().unwrap();
    let want: Vec<f64> = info["freq_hz"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    let abq = build(dir.path(), "abaqus");
    let hb = build(dir.path(), "harwell_boeing");
    eprintln!("abaqus: {}", abq.description);
    eprintln!("harwell_boeing: {}", hb.description);
    assert_eq!(abq.n_dof(), n_free);
    assert_eq!(hb.n_dof(), n_free);
    // same equations in the same order: the two imports are the same matrices
    for (a, b, name) in [
        (&abq.m, &hb.m, "M"),
        (&abq.k_b, &hb.k_b, "K_b"),
        (&abq.s, &hb.s, "S"),
    ] {
        let d = dense_diff(a, b);
        assert!(
            d < 1e-15,
            "{name}: Abaqus and Harwell-Boeing differ by {d:.1e}"
        );
    }
    assert_eq!(abq.points, {
        let mut p = hb.points.clone();
        for (q, r) in p.iter_mut().zip(&abq.points) {
            q.note = r.note.clone();
        }
        p
    });
    // the equation form of the map gives the same points as the node form with the mapping
    let eq = import_model_files(&ImportFiles {
        format: ImportFormat::HarwellBoeing,
        mass: dir.path().join("hb/M.hb"),
        stiffness: dir.path().join("hb/K_b.hb"),
        adhesive_sensitivity: dir.path().join("hb/S.hb"),
        viscous_damping: None,
        structural_damping: None,
        dof_map: Some(dir.path().join("hb/dofmap_eq.csv")),
        mapping: None,
        units: Units::Si,
    })
    .unwrap();
    for (p, q) in eq.points.iter().zip(&hb.points) {
        assert_eq!((p.id, p.direction, &p.dofs), (q.id, q.direction, &q.dofs));
    }
    for (name, model) in [("abaqus", &abq), ("harwell_boeing", &hb)] {
        let params = rfmlab::modes::ModesParams::default();
        let modes =
            rfmlab::modes::complex_modes(model, C64::new(e, 0.0), want.len(), None, &params)
                .unwrap();
        for (k, (m, w)) in modes.iter().zip(&want).enumerate() {
            let rel = (m.freq_hz - w).abs() / w;
            eprintln!(
                "{name} mode {}: rfmlab {:.9} Hz, script {w:.9} Hz, relative {rel:.1e}",
                k + 1,
                m.freq_hz
            );
            assert!(rel < 1e-6, "{name} mode {}: {} vs {w} Hz", k + 1, m.freq_hz);
        }
    }
}

/// A virtual experiment on the imported joint: frequency-domain mode, Model 4 at `TRUTH`.
fn experiment(dir: &Path, format: &str, noise: &str) -> String {
    format!(
        r#"[experiment]
name = "foreign_{format}"
description = "Model 4 on an imported joint (SIMULATED)"
mode = "frequency"
seed = 11
output = "{format}.uff"
engine = "rom"

{}
[chain]
band_hz = [20.0, 400.0]
lines_hz = [20.0, 400.0, 2.0]
{noise}

[[levels]]
name = "L1"
force_rms_n = 3.3
law = "model4"
params = {{ E0 = {}, h = {}, E1 = {}, eta1 = {} }}
"#,
        structure(dir, format),
        TRUTH[0],
        TRUTH[1],
        TRUTH[2],
        TRUTH[3]
    )
}

fn simulate(dir: &Path, format: &str, noise: &str) -> PathBuf {
    let f = dir.join(format!("exp_{format}.toml"));
    std::fs::write(&f, experiment(dir, format, noise)).unwrap();
    let out = Command::new(BIN)
        .args(["simulate", f.to_str().unwrap(), "--quiet"])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "simulate: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    dir.join(format!("{format}_L1.uff"))
}

/// Noise-free data: the experiment's UFF with every channel replaced by the exact accelerance
/// of the imported model at the truth ([`crate::common_data::exact_uff`]).
fn exact_data(dir: &Path, format: &str) -> PathBuf {
    let uff = simulate(
        dir,
        format,
        "force_noise_fraction = 0.0\nresponse_noise_fraction = 0.0",
    );
    let out = dir.join(format!("{format}_exact.uff"));
    crate::common_data::exact_uff(&uff, &dir.join(format!("{format}.truth.json")), &out);
    out
}

fn study(dir: &Path, format: &str, data: &Path, name: &str, inference: &str) -> String {
    format!(
        r#"[study]
name = "{name}"
seed = 1

{}
[measurements]
band_hz = [20.0, 400.0]

[[measurements.levels]]
name = "L1"
files = ["{}"]
force_rms_n = 3.3

[[models]]
name = "model4"
[models.initial]
E0 = 6.0e6
h = 1.0e6
E1 = 3.0e6
eta1 = 3.0e3

[solver]
engine = "rom"
max_iterations = 100
tolerance = 1e-10

[analyses]
per_line = false
correlation = false
sensitivity = false
figures = false
{inference}"#,
        structure(dir, format),
        data.display()
    )
}

fn run(dir: &Path, name: &str, text: &str) -> rfmlab::report::RunSummary {
    let file = dir.join(format!("{name}.toml"));
    std::fs::write(&file, text).unwrap();
    let study = rfmlab::study::load(&file).unwrap_or_else(|e| panic!("{e}"));
    let opts = RunOptions {
        no_figures: true,
        output_dir: Some(dir.join(name)),
        rom_cache: Some(crate::shared_rom_cache::runs_folder()),
    };
    run_study(&study, &opts, &|_| {}).unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn foreign_joint_model4_identified_from_noise_free_data() {
    let dir = tempfile::tempdir().unwrap();
    if generate(dir.path(), "foreign_joint_model4").is_none() {
        return;
    }
    // data made on the Abaqus import, identified on the Harwell-Boeing import, and back
    for (make, fit) in [("abaqus", "harwell_boeing"), ("harwell_boeing", "abaqus")] {
        let data = exact_data(dir.path(), make);
        let name = format!("fit_{fit}");
        let s = run(dir.path(), &name, &study(dir.path(), fit, &data, &name, ""));
        let m = s.models.iter().find(|m| m.model == "model4").unwrap();
        assert_eq!(m.param_names, ["E0", "h", "E1", "eta1"]);
        let err: Vec<f64> = (0..4)
            .map(|k| (m.identified[k] - TRUTH[k]) / TRUTH[k])
            .collect();
        eprintln!(
            "data from {make}, fit on {fit}: E0 {:+.4} %, h {:+.4} %, E1 {:+.4} %, eta1 {:+.4} % ({} iterations)",
            100.0 * err[0],
            100.0 * err[1],
            100.0 * err[2],
            100.0 * err[3],
            m.iterations
        );
        for (k, e) in err.iter().enumerate() {
            assert!(
                e.abs() < 1e-3,
                "{fit}: {} off by {:.3} %",
                m.param_names[k],
                100.0 * e
            );
        }
    }
}

#[test]
fn foreign_joint_posterior_holds_the_truth_at_the_default_noise() {
    use rfmlab::output::{ColumnData, Table};
    let dir = tempfile::tempdir().unwrap();
    if generate(dir.path(), "foreign_joint_posterior").is_none() {
        return;
    }
    let data = simulate(dir.path(), "abaqus", "");
    // the data are Welch H1 estimates (Hann, 1 s blocks at 2048 Hz, force in 20-400 Hz, 200
    // blocks at 50 % overlap: 189.5 independent averages): the study states that estimator, so
    // the fit models the window's leakage, and the leakage's common error across channels
    let inference = r#"
[measurements.estimator]
window = "hann"
block_s = 1.0
fs_hz = 2048.0
force_band_hz = [20.0, 400.0]

[inference]
models = ["model4"]
samplers = []

[inference.noise]
model = "coherence"
n_averages = 189.5
channel_correlation = "leakage"

[inference.map]
starts = 2
"#;
    let name = "posterior_abaqus";
    run(
        dir.path(),
        name,
        &study(dir.path(), "abaqus", &data, name, inference),
    );
    let lap = Table::read_parquet(dir.path().join(name).join("laplace.parquet")).unwrap();
    let strs = |c: &str| match lap.column(c) {
        Some(ColumnData::Str(v)) => v.clone(),
        _ => panic!("laplace.{c} is not a string column"),
    };
    let param = strs("parameter");
    let map = lap.column("map").and_then(|c| c.as_f64()).unwrap();
    let sd = lap.column("sd").and_then(|c| c.as_f64()).unwrap();
    let names = ["E0", "h", "E1", "eta1"];
    let mut zs = Vec::new();
    for i in 0..lap.n_rows() {
        let Some(k) = names.iter().position(|n| *n == param[i]) else {
            continue;
        };
        let z = (map[i] - TRUTH[k]) / sd[i];
        eprintln!(
            "{}: MAP {:+.4} % from the truth, Laplace sd {:.4} %, z {z:+.2}",
            param[i],
            100.0 * (map[i] / TRUTH[k] - 1.0),
            100.0 * sd[i] / TRUTH[k]
        );
        zs.push((param[i].clone(), z));
    }
    assert_eq!(zs.len(), 4);
    for (p, z) in &zs {
        assert!(z.abs() < 1.96, "{p}: z = {z:.2}");
    }
}

// ---------------------------------------------------------------- readers' error paths

#[test]
fn harwell_boeing_round_trip_is_exact_for_symmetric_and_unsymmetric() {
    use faer::sparse::Triplet;
    let t = vec![
        Triplet::new(0usize, 0usize, 4.0),
        Triplet::new(1, 0, -1.0 / 3.0),
        Triplet::new(0, 1, -1.0 / 3.0),
        Triplet::new(1, 1, 2.5e300),
        Triplet::new(2, 2, 1e-300),
        Triplet::new(2, 1, 7.0),
        Triplet::new(1, 2, 7.0),
    ];
    let a = rfmlab::fe::model::SpMat::try_new_from_triplets(3, 3, &t).unwrap();
    let text = format_hb(&a, "sym", "A");
    assert!(text.lines().nth(2).unwrap().starts_with("RSA"));
    let b = parse_hb(&text, Path::new("a.hb")).unwrap();
    assert_eq!(dense_diff(&a, &b), 0.0);
    let mut t2 = t.clone();
    t2.push(Triplet::new(0, 2, 1.0));
    let u = rfmlab::fe::model::SpMat::try_new_from_triplets(3, 3, &t2).unwrap();
    let text = format_hb(&u, "unsym", "U");
    assert!(text.lines().nth(2).unwrap().starts_with("RUA"));
    assert_eq!(
        dense_diff(&u, &parse_hb(&text, Path::new("u.hb")).unwrap()),
        0.0
    );
}

#[test]
fn harwell_boeing_errors_name_file_and_line() {
    let err = |text: &str| parse_hb(text, Path::new("K.hb")).unwrap_err().to_string();
    let head = "title\n 3 1 1 1 0\n";
    let e = err(&format!("{head}PSA 2 2 2 0\n(3I5) (2I5) (2E20.10)\n"));
    assert!(e.contains("K.hb, line 3") && e.contains("pattern"), "{e}");
    let e = err(&format!("{head}CUA 2 2 2 0\n(3I5) (2I5) (2E20.10)\n"));
    assert!(e.contains("line 3") && e.contains("complex"), "{e}");
    let e = err(&format!("{head}RUE 2 2 2 0\n(3I5) (2I5) (2E20.10)\n"));
    assert!(e.contains("line 3") && e.contains("assembled"), "{e}");
    let e = err(&format!("{head}RUA 2 3 2 0\n(3I5) (2I5) (2E20.10)\n"));
    assert!(e.contains("line 3") && e.contains("square"), "{e}");
    let e = err(&format!("{head}RUA 2 2 2 0\n(3Q5) (2I5) (2E20.10)\n"));
    assert!(e.contains("line 4") && e.contains("pointer format"), "{e}");
    let body = "    1    2    3\n    1    3\n    1.0                 2.0\n";
    let e = err(&format!("{head}RUA 2 2 2 0\n(3I5) (2I5) (2E20.10)\n{body}"));
    assert!(e.contains("line 6") && e.contains("row index 3"), "{e}");
    let body = "    1    2    3\n    1    2\n    1.0                 x.0\n";
    let e = err(&format!("{head}RUA 2 2 2 0\n(3I5) (2I5) (2E20.10)\n{body}"));
    assert!(e.contains("line 7") && e.contains("'x.0'"), "{e}");
    // a symmetric file storing both triangles
    let body = "    1    3    4\n    1    2    1\n    1.0                 2.0\n    2.0\n";
    let e = err(&format!("{head}RSA 2 2 3 0\n(3I5) (3I5) (2E20.10)\n{body}"));
    assert!(e.contains("twice"), "{e}");
    let e = err("only one line\n");
    assert!(
        e.contains("K.hb, line 1") && e.contains("4 header lines"),
        "{e}"
    );
}

/// A 4-DOF chain in Abaqus FORMAT=MATRIX INPUT: node 1 held (1e36), node 9 uncoupled.
fn tiny_abaqus(dir: &Path) -> ImportFiles {
    let k = "1,2, 1,2, 1.0e36\n2,2, 1,2, -1.0e3\n2,2, 2,2, 2.0e3\n3,2, 2,2, -1.0e3\n3,2, 3,2, 1.0e3\n9,1, 9,1, 1.0\n";
    let s = "2,2, 2,2, 1.0\n3,2, 3,2, 1.0\n3,2, 2,2, -0.5\n";
    let m = "2,2, 2,2, 1.0\n3,2, 3,2, 1.0\n1,2, 1,2, 1.0\n";
    std::fs::write(dir.join("K.mtx"), k).unwrap();
    std::fs::write(dir.join("S.mtx"), s).unwrap();
    std::fs::write(dir.join("M.mtx"), m).unwrap();
    std::fs::write(
        dir.join("pts.csv"),
        "id,direction,node,weight\n1,+y,3\n2,-y,2,0.5\n",
    )
    .unwrap();
    ImportFiles {
        format: ImportFormat::Abaqus,
        mass: dir.join("M.mtx"),
        stiffness: dir.join("K.mtx"),
        adhesive_sensitivity: dir.join("S.mtx"),
        viscous_damping: None,
        structural_damping: None,
        dof_map: Some(dir.join("pts.csv")),
        mapping: None,
        units: Units::Si,
    }
}

#[test]
fn abaqus_constraints_units_and_node_map() {
    let dir = tempfile::tempdir().unwrap();
    let f = tiny_abaqus(dir.path());
    let m = import_model_files(&f).unwrap();
    // nodes 1 (held) and 9 (uncoupled) removed: free DOFs (2,2), (3,2)
    assert_eq!(m.n_dof(), 2, "{}", m.description);
    let k = rfmlab::fe::synthetic::to_dense(&m.k_b);
    assert_eq!(
        (k[(0, 0)], k[(0, 1)], k[(1, 0)], k[(1, 1)]),
        (2e3, -1e3, -1e3, 1e3)
    );
    let s = rfmlab::fe::synthetic::to_dense(&m.s);
    assert_eq!((s[(0, 1)], s[(1, 0)]), (-0.5, -0.5));
    assert_eq!(m.points[0].dofs, vec![(1, 1.0)]);
    assert_eq!(m.points[1].dofs, vec![(0, -0.5)]);
    // mm-t-s: M and K_b times 1e3, S times 1e-3
    let mm = import_model_files(&ImportFiles {
        units: Units::MmTonneS,
        ..f.clone()
    })
    .unwrap();
    let k2 = rfmlab::fe::synthetic::to_dense(&mm.k_b);
    let s2 = rfmlab::fe::synthetic::to_dense(&mm.s);
    let m2 = rfmlab::fe::synthetic::to_dense(&mm.m);
    assert_eq!((k2[(0, 0)], s2[(0, 0)], m2[(0, 0)]), (2e6, 1e-3, 1e3));
    // a point on the held node, on a missing node
    std::fs::write(dir.path().join("pts.csv"), "id,direction,node\n1,+y,1\n").unwrap();
    let e = import_model_files(&f).unwrap_err().to_string();
    assert!(
        e.contains("pts.csv, line 2") && e.contains("node 1, DOF 2") && e.contains("constrained"),
        "{e}"
    );
    std::fs::write(dir.path().join("pts.csv"), "id,direction,node\n1,+y,77\n").unwrap();
    let e = import_model_files(&f).unwrap_err().to_string();
    assert!(
        e.contains("pts.csv, line 2") && e.contains("node 77"),
        "{e}"
    );
    // coordinate and node-keyed files mixed
    std::fs::write(dir.path().join("S.mtx"), "1 1 1.0\n").unwrap();
    let e = import_model_files(&f).unwrap_err().to_string();
    assert!(e.contains("S.mtx") && e.contains("one format"), "{e}");
}

#[test]
fn study_keys_choose_the_format_and_refuse_bad_values() {
    let dir = tempfile::tempdir().unwrap();
    tiny_abaqus(dir.path());
    let base = |source: &str, extra: &str| {
        format!(
            "[study]\nname = \"t\"\n\n[structure]\nsource = \"{source}\"\nexcitation = 1\n\n[structure.import]\nmass = \"M.mtx\"\nstiffness = \"K.mtx\"\nadhesive_sensitivity = \"S.mtx\"\ndof_map = \"pts.csv\"\n{extra}\n[[structure.points]]\nid = 1\nposition = [0.0, 0.0, 0.0]\ndirection = \"+y\"\n"
        )
    };
    let load = |text: String| {
        let f = dir.path().join("s.toml");
        std::fs::write(&f, text).unwrap();
        rfmlab::study::load(&f)
    };
    let s = load(base("abaqus", "units = \"mm-t-s\"\n")).unwrap();
    let b = rfmlab::study::build::build_model(&s.structure, "s.toml").unwrap();
    assert_eq!(b.model.n_dof(), 2);
    let e = load(base("abaqus", "units = \"inch\"\n"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("structure.import.units") && e.contains("mm-t-s"),
        "{e}"
    );
    let e = load(base("abaqus", "mapping = \"pts.csv\"\n"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("structure.import.mapping"), "{e}");
    let e = load(base("nastran", "")).unwrap_err().to_string();
    assert!(
        e.contains("structure.source") && e.contains("harwell_boeing"),
        "{e}"
    );
    // a Harwell-Boeing study on Abaqus files: the reader names the file and line
    let s = load(base("harwell_boeing", "")).unwrap();
    let e = rfmlab::study::build::build_model(&s.structure, "s.toml")
        .err()
        .unwrap()
        .to_string();
    assert!(
        e.contains("structure.import") && e.contains("M.mtx, line"),
        "{e}"
    );
}
