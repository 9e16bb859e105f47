//! The single-lap joint (`structure.joint = "single_lap"`): the first modes of a 1 mm bond line
//! converge under refinement (the paper's Table 1 for this joint), the graded mesh keeps the
//! bond line's elements near the set aspect ratio, and a seeded design-space check over lap
//! geometries (bond lines 0.5-3 mm): the mesh builds, the lowest modes of the full model and of
//! the ROM agree, the study's ROM is certified, and Model 4 is identified within 0.5 % from
//! noise-free frequency-domain data simulated with known parameters.

use rfmlab::common::C64;
use rfmlab::fe::lap::{adhesive_aspect_ratio, build_lap_model, lap_mesh, LapSpec};
use rfmlab::modes::{complex_modes, ModesParams};
use rfmlab::report::run_study;
use rfmlab::report::RunOptions;
use std::path::Path;
use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_rfmlab");
/// Model 4 truth (E0, h, E1, eta1), SI.
const TRUTH: [f64; 4] = [7.2e6, 1.1e6, 2.8e6, 5.0e3];

/// First `n` mode frequencies (Hz) of the reference lap joint (1 mm bond line) at element
/// size `h` and E* = 7 + 1.5 j MPa.
fn first_modes(h: f64, n: usize) -> (Vec<f64>, usize) {
    let mut spec = LapSpec::reference();
    spec.mesh.element_size_m = h;
    spec.mesh.z = Some(2);
    let (model, info) = build_lap_model(&spec).unwrap();
    let modes = complex_modes(
        &model,
        C64::new(7.0e6, 1.5e6),
        n,
        None,
        &ModesParams::default(),
    )
    .unwrap();
    (modes.iter().map(|m| m.freq_hz).collect(), info.n_dof)
}

/// The paper's Table 1 for the lap joint: 10, 5 and 2.5 mm elements (2 through the 1 mm bond
/// line, graded to 2 mm at the overlap ends). Each halving must shrink the change, and the
/// 5 mm mesh must be within 0.5 % of the 2.5 mm one for the first three modes.
#[test]
fn lap_joint_modes_converge_for_a_1mm_bond_line() {
    let sizes = [0.010, 0.005, 0.0025];
    let runs: Vec<(Vec<f64>, usize)> = sizes.iter().map(|&h| first_modes(h, 3)).collect();
    for (h, (f, n)) in sizes.iter().zip(&runs) {
        eprintln!(
            "lap 1 mm bond line, h = {:.1} mm: {n} DOFs, modes {:.3} {:.3} {:.3} Hz",
            h * 1e3,
            f[0],
            f[1],
            f[2]
        );
    }
    for k in 0..3 {
        let (a, b, c) = (runs[0].0[k], runs[1].0[k], runs[2].0[k]);
        let d1 = (a - b).abs();
        let d2 = (b - c).abs();
        eprintln!(
            "mode {}: change 10->5 mm {:.3e}, 5->2.5 mm {:.3e} (relative {:.2e})",
            k + 1,
            d1 / c,
            d2 / c,
            d2 / c
        );
        assert!(
            d2 <= d1 + 1e-9 * c,
            "mode {}: not converging ({d1} then {d2})",
            k + 1
        );
        assert!(
            d2 / c < 5e-3,
            "mode {}: 5 mm mesh {:.3} % off",
            k + 1,
            100.0 * d2 / c
        );
    }
}

#[test]
fn lap_mesh_grades_thin_bond_lines() {
    for ta in [0.0005, 0.001, 0.003] {
        let mut spec = LapSpec::reference();
        spec.geometry.adhesive_thickness_m = ta;
        spec.mesh.z = Some(2);
        let mesh = lap_mesh(&spec).unwrap();
        let g = &mesh.grid;
        // smallest x cell at an overlap end: end_aspect * ta / y_adhesive (capped by 5 mm)
        let x0 = spec.geometry.strip_length_m - spec.geometry.overlap_m;
        let i =
            g.xs.iter()
                .position(|&x| (x - x0).abs() < 1e-12)
                .expect("overlap start on the grid");
        let dx = g.xs[i + 1] - g.xs[i];
        let want = (4.0 * ta / 2.0).min(0.005);
        eprintln!(
            "bond line {:.1} mm: end element {:.3} mm (target {:.3}), x cells {}, \
             adhesive aspect x:y {:.1}, longest:shortest {:.1}",
            ta * 1e3,
            dx * 1e3,
            want * 1e3,
            g.xs.len() - 1,
            adhesive_aspect_ratio(&mesh).0,
            adhesive_aspect_ratio(&mesh).1
        );
        assert!((dx - want).abs() < 0.35 * want, "{dx} vs {want}");
        // x : y of the adhesive elements at the ends within [2, 6] (the target 4)
        let r = dx / (ta / 2.0);
        assert!((2.0..=6.0).contains(&r), "end aspect {r}");
        assert!(adhesive_aspect_ratio(&mesh).0 <= 10.5);
    }
}

/// xorshift64*: a tiny seeded generator for reproducible geometries.
struct Rng(u64);
impl Rng {
    fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        let u = (self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 / (1u64 << 53) as f64;
        lo + (hi - lo) * u
    }
}

/// A drawn lap joint: (strip length, thickness, width, overlap, bond line), m.
fn draw(rng: &mut Rng) -> [f64; 5] {
    let mm = |x: f64| (x * 1e4).round() / 1e4; // 0.1 mm grid
    [
        mm(rng.uniform(0.08, 0.15)),
        mm(rng.uniform(0.002, 0.005)),
        mm(rng.uniform(0.015, 0.030)),
        mm(rng.uniform(0.0125, 0.030)),
        mm(rng.uniform(0.0005, 0.003)),
    ]
}

fn structure(g: &[f64; 5]) -> String {
    let [l, t, w, lo, ta] = *g;
    let top = 2.0 * t + ta;
    let xs = [
        0.4 * (l - lo),
        0.8 * (l - lo),
        l + 0.3 * (l - lo),
        2.0 * l - lo - 0.1 * (l - lo),
    ];
    let ys = [t, t, top, top];
    let mut s = format!(
        r#"[structure]
name = "lap joint"
joint = "single_lap"
excitation = 3

[structure.lap]
length = {l}
thickness = {t}
width = {w}
overlap = {lo}
support = "clamped"
material = {{ E = 70e9, nu = 0.33, rho = 2700.0 }}
adhesive = {{ thickness = {ta}, nu = 0.44, rho = 1160.0 }}
mesh = {{ element_size = 0.006, z = 2, refine = false, allowance = false }}
"#
    );
    for (k, (x, y)) in xs.iter().zip(ys).enumerate() {
        s += &format!(
            "\n[[structure.points]]\nid = {}\nposition = [{x}, {y}, {}]\ndirection = \"+y\"\n",
            k + 1,
            w / 2.0
        );
    }
    s
}

/// One design-space lap geometry end to end; returns the worst Model 4 error.
fn check_geometry(dir: &Path, k: usize, g: &[f64; 5]) -> f64 {
    let t0 = std::time::Instant::now();
    let st = structure(g);
    // mesh and modes: full model vs ROM basis at the truth's modulus near the first mode
    let file = dir.join(format!("lap{k}_structure.toml"));
    std::fs::write(&file, format!("[study]\nname = \"lap{k}\"\n\n{st}")).unwrap();
    let study = rfmlab::study::load(&file).unwrap_or_else(|e| panic!("{e}"));
    let b = rfmlab::study::build::build_model(&study.structure, "lap")
        .unwrap_or_else(|e| panic!("geometry {k} {g:?}: {e}"));
    let e = C64::new(7.0e6, 1.5e6);
    let full = complex_modes(
        &b.model,
        e,
        4,
        b.dof_axes.as_deref(),
        &ModesParams::default(),
    )
    .unwrap_or_else(|er| panic!("geometry {k} {g:?}: modes: {er}"));
    let inputs: Vec<usize> = (0..b.model.points.len()).collect();
    let params = rfmlab::rom::RomParams {
        range: rfmlab::rom::ModulusRange {
            e_storage_pa: (e.re, e.re),
            e_loss_pa: (e.im, e.im),
        },
        ..rfmlab::rom::RomParams::default()
    };
    let rom =
        rfmlab::rom::build_basis_only(&b.model, &inputs, &params, b.dof_axes.as_deref()).unwrap();
    let rm = rom.complex_modes(e, 8).unwrap();
    // every full-model mode the points see (|b^T phi| not tiny) is a ROM mode
    let mut worst_mode: f64 = 0.0;
    for m in &full {
        let seen = m.at_points.iter().map(|v| v.norm()).fold(0.0, f64::max);
        if seen < 1e-6 {
            continue;
        }
        let best = rm
            .iter()
            .map(|r| (r.freq_hz() - m.freq_hz).abs() / m.freq_hz)
            .fold(f64::INFINITY, f64::min);
        worst_mode = worst_mode.max(best);
    }
    assert!(
        worst_mode < 1e-6,
        "geometry {k} {g:?}: ROM modes off the full model's by {worst_mode:.1e}"
    );
    let f1 = full[0].freq_hz;
    let f3 = full[full.len().min(3) - 1].freq_hz;
    let (lo, hi) = ((0.5 * f1).max(1.0).round(), (1.15 * f3).round());
    let step = ((hi - lo) / 60.0).max(0.5).round();
    let hi = lo + step * ((hi - lo) / step).floor();
    // noise-free data: the exact accelerances of the simulated experiment (its sidecar)
    let exp = format!(
        r#"[experiment]
name = "lap{k}"
description = "Model 4 on a lap joint (SIMULATED)"
mode = "frequency"
seed = {k}
output = "lap{k}.uff"
engine = "rom"

{st}
[chain]
band_hz = [{lo}, {hi}]
lines_hz = [{lo}, {hi}, {step}]
force_noise_fraction = 0.0
response_noise_fraction = 0.0

[[levels]]
name = "L1"
force_rms_n = 3.3
law = "model4"
params = {{ E0 = {}, h = {}, E1 = {}, eta1 = {} }}
"#,
        TRUTH[0], TRUTH[1], TRUTH[2], TRUTH[3]
    );
    let ef = dir.join(format!("lap{k}_exp.toml"));
    std::fs::write(&ef, exp).unwrap();
    let out = Command::new(BIN)
        .args(["simulate", ef.to_str().unwrap(), "--quiet"])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "geometry {k}: simulate: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let exact = dir.join(format!("lap{k}_exact.uff"));
    crate::common_data::exact_uff(
        &dir.join(format!("lap{k}_L1.uff")),
        &dir.join(format!("lap{k}.truth.json")),
        &exact,
    );
    let study_text = format!(
        r#"[study]
name = "lap{k}_fit"
seed = 1

{st}
[measurements]
band_hz = [{lo}, {hi}]

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
"#,
        exact.display()
    );
    let sf = dir.join(format!("lap{k}_fit.toml"));
    std::fs::write(&sf, study_text).unwrap();
    let study = rfmlab::study::load(&sf).unwrap_or_else(|e| panic!("{e}"));
    let opts = RunOptions {
        no_figures: true,
        output_dir: Some(dir.join(format!("lap{k}_out"))),
        rom_cache: Some(crate::shared_rom_cache::runs_folder()),
    };
    let s = run_study(&study, &opts, &|_| {})
        .unwrap_or_else(|e| panic!("geometry {k} {g:?}: run: {e}"));
    let m = s.models.iter().find(|m| m.model == "model4").unwrap();
    let worst = (0..4)
        .map(|i| ((m.identified[i] - TRUTH[i]) / TRUTH[i]).abs())
        .fold(0.0, f64::max);
    eprintln!(
        "lap geometry {k}: L {:.1} t {:.1} w {:.1} overlap {:.1} bond {:.2} mm, {} DOFs, modes \
         {:.1} {:.1} Hz, band [{lo}, {hi}] step {step}, ROM/full modes {worst_mode:.1e}, Model 4 \
         worst {:.4} % ({} iterations), {:.1} s",
        g[0] * 1e3,
        g[1] * 1e3,
        g[2] * 1e3,
        g[3] * 1e3,
        g[4] * 1e3,
        b.model.n_dof(),
        f1,
        f3,
        100.0 * worst,
        m.iterations,
        t0.elapsed().as_secs_f64()
    );
    assert!(
        worst < 5e-3,
        "geometry {k} {g:?}: Model 4 off by {:.3} % ({:?})",
        100.0 * worst,
        m.identified
    );
    worst
}

/// The first `n` seeded lap geometries end to end.
fn lap_design_space(n: usize) {
    let dir = tempfile::tempdir().unwrap();
    let mut rng = Rng(0x05ee_d1a9);
    let mut worst: f64 = 0.0;
    for k in 0..n {
        let g = draw(&mut rng);
        worst = worst.max(check_geometry(dir.path(), k, &g));
    }
    eprintln!(
        "lap design space: {n} geometries pass, worst Model 4 error {:.4} %",
        100.0 * worst
    );
}

/// Two seeded lap geometries.
#[test]
fn lap_joint_design_space() {
    lap_design_space(2);
}

/// Twelve seeded lap geometries (the first two are the default test's).
#[test]
#[ignore = "slow: 12 lap geometries, 121 s in release beside other work; run with --ignored"]
fn lap_joint_design_space_12_geometries() {
    lap_design_space(12);
}
