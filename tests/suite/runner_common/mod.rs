//! Shared helpers of tests/runner.rs and tests/cli_errors.rs: noiseless simulated data written
//! as UFF58 and study files in a temporary folder.
#![allow(dead_code)]

use rfmlab::common::C64;
use rfmlab::data::{Channel, FrfLevel, FrfSet, Quantity};
use rfmlab::frf::{FrfEngine, FullModel, FullParams};
use rfmlab::material::ConstitutiveModel;
use std::path::{Path, PathBuf};

/// The paper's structure on a 10 mm mesh (fast; unconverged like the paper's Mesh 1), without
/// its points.
const STRUCTURE_NO_POINTS: &str = r#"
[structure]
name = "paper bonded joint, 10 mm mesh"
source = "mesher"
excitation = 2
[structure.beam]
length = 0.300
thickness = 0.010
width = 0.020
[structure.beam.material]
E = 198e9
nu = 0.3
rho = 7800.0
[structure.adhesive]
length = 0.050
thickness = 0.010
x_start = 0.0
nu = 0.44
rho = 1160.0
[structure.mesh]
element_size = 0.010
refine = false
allowance = false
integration = "full"
point_mapping = "interpolate"
"#;

/// The `[structure]` TOML of the tests: [`STRUCTURE_NO_POINTS`] with points 1-4 at x = 100,
/// 150, 200 and 250 mm on the top face, all "+y" (excitation at point 2).
pub fn structure() -> String {
    let mut s = STRUCTURE_NO_POINTS.to_string();
    for (id, x) in [(1, "0.100"), (2, "0.150"), (3, "0.200"), (4, "0.250")] {
        s.push_str(&format!(
            "[[structure.points]]\nid = {id}\nposition = [{x}, 0.010, 0.010]\ndirection = \"+y\"\n"
        ));
    }
    s
}

/// [`structure`] built as the study runner builds it.
pub fn built_structure() -> rfmlab::study::build::BuiltModel {
    let study = rfmlab::study::parse_str(
        &format!("[study]\nname = \"gen\"\n{}", structure()),
        Path::new("gen.toml"),
    )
    .expect("structure parses");
    rfmlab::study::build::build_model(&study.structure, "gen.toml").expect("model builds")
}

/// The joint specification of [`structure`] (what the mesher meshes: regions, the base face).
pub fn joint_spec() -> rfmlab::fe::joint::JointSpec {
    let study = rfmlab::study::parse_str(
        &format!("[study]\nname = \"gen\"\n{}", structure()),
        Path::new("gen.toml"),
    )
    .expect("structure parses");
    rfmlab::study::build::joint_spec(&study.structure).expect("a mesher structure")
}

/// Runs the binary as a user would (`CI` set: no progress bars): the exit code (None when a
/// signal ended it), stdout and stderr.
pub fn rfmlab_cli(args: &[&str]) -> (Option<i32>, String, String) {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_rfmlab"))
        .args(args)
        .env("CI", "1")
        .output()
        .expect("run rfmlab");
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// The small data set of the command-line tests, written as UFF58 level L1 to `path`: Model 1
/// at E* = 7 + 1.5j MPa, 10-100 Hz every 10 Hz.
pub fn write_small_data(path: &Path) {
    let law = rfmlab::material::model_from_name("model1", None).expect("model1");
    write_data(
        path,
        "L1",
        law.as_ref(),
        &[7e6, 1.5e6],
        &lines_hz(10.0, 100.0, 10.0),
    );
}

/// A temporary folder with the small data set ([`write_small_data`]) for the command-line
/// tests: `root`, the data file and a results folder inside it (not created).
pub struct Setup {
    _dir: tempfile::TempDir,
    pub root: PathBuf,
    pub data: PathBuf,
    pub out: PathBuf,
}

/// A fresh [`Setup`].
pub fn setup() -> Setup {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().to_path_buf();
    let data = root.join("d.uff");
    write_small_data(&data);
    let out = root.join("results");
    Setup {
        _dir: dir,
        root,
        data,
        out,
    }
}

/// The `[analyses]` of the command-line tests' studies: global fits only, no figures.
pub const ANALYSES: &str = "[analyses]\nper_line = false\nsensitivity = false\nfigures = false\n";

/// Frequency lines of the test data (Hz).
pub fn lines_hz(lo: f64, hi: f64, step: f64) -> Vec<f64> {
    let n = ((hi - lo) / step).round() as usize;
    (0..=n).map(|k| lo + step * k as f64).collect()
}

/// Noiseless accelerance H'_i2 of points 1-4 at the truth of `law` (full model), written as
/// UFF58 level `level` to `path`.
pub fn write_data(
    path: &Path,
    level: &str,
    law: &dyn ConstitutiveModel,
    truth: &[f64],
    freq_hz: &[f64],
) {
    let built = built_structure();
    let engine =
        FullModel::new(&built.model, &[built.excitation], FullParams::default()).expect("engine");
    let omega: Vec<f64> = freq_hz
        .iter()
        .map(|f| 2.0 * std::f64::consts::PI * f)
        .collect();
    let moduli: Vec<C64> = omega.iter().map(|&w| law.modulus(truth, w)).collect();
    let sw = engine.sweep(&omega, &moduli, false).expect("sweep");
    let mut channels = Vec::new();
    for (k, p) in built.model.points.iter().enumerate() {
        let values: Vec<C64> = omega
            .iter()
            .enumerate()
            .map(|(l, &w)| -w * w * sw.h[sw.idx(l, k, 0)])
            .collect();
        channels.push(Channel {
            response_id: p.id,
            response_dir: p.direction,
            reference_id: 2,
            reference_dir: p.direction,
            values,
            coherence: None,
            source: None,
        });
    }
    let set = FrfSet {
        levels: vec![FrfLevel {
            name: level.to_string(),
            force_rms_n: None,
            n_averages: None,
            quantity: Quantity::Accelerance,
            freq_hz: freq_hz.to_vec(),
            channels,
        }],
    };
    rfmlab::data::frf_set_to_uff(&set, path, false).expect("write UFF");
}

/// A study file text: structure + one level + models (name, [(param, initial)]) + settings,
/// solved with the engine `engine` ("full" or "rom").
pub fn study_text(
    name: &str,
    out: &Path,
    data: &Path,
    band: (f64, f64),
    models: &[(&str, Vec<(String, f64)>)],
    analyses: &str,
    engine: &str,
) -> String {
    let mut s = format!(
        "[study]\nname = \"{name}\"\noutput_dir = \"{}\"\n{}\n[measurements]\nband_hz = [{}, {}]\n[[measurements.levels]]\nname = \"L1\"\nfiles = [\"{}\"]\n",
        out.display(),
        structure(),
        band.0,
        band.1,
        data.display()
    );
    for (m, init) in models {
        s.push_str(&format!("[[models]]\nname = \"{m}\"\n[models.initial]\n"));
        for (p, v) in init {
            s.push_str(&format!("{p} = {v:e}\n"));
        }
    }
    s.push_str(&format!(
        "[solver]\nengine = \"{engine}\"\nmax_iterations = 60\ntolerance = 1e-9\n"
    ));
    s.push_str(analyses);
    s
}

/// Initial values of Table 4's model k by parameter name.
pub fn initial_of(k: usize) -> Vec<(String, f64)> {
    let law = rfmlab::material::model_from_name(&format!("model{k}"), None).unwrap();
    let (_, init) = rfmlab::material::paper_table4(k);
    law.param_names().into_iter().zip(init).collect()
}

pub fn write(path: &Path, text: &str) -> PathBuf {
    std::fs::write(path, text).expect("write study");
    path.to_path_buf()
}
