//! Declared effects at fixed values as an engine for the deterministic analyses
//! (`rfmlab::forward::fixed`): the certified ROM wrapped with two point masses and a beam
//! factor against the full sparse solve of the model with the masses in M and K_b, D_b scaled
//! (receptance, dH/dE' and S H, each within 1e-6 of its peak), and the RFM with a declared
//! mass on data that carry it.

use rfmlab::common::C64;
use rfmlab::forward::fixed::FixedEffectsEngine;
use rfmlab::forward::{Effect, EffectTerm, Effects};
use rfmlab::frf::{FrfEngine, FullModel, FullParams};
use rfmlab::material::{ConstitutiveModel, Model3};
use rfmlab::rom::{build_rom, RomParams};
use std::f64::consts::TAU;

const TRUTH: [f64; 3] = [4.7121e6, 5.5573e6, 6.0491e3];

/// Largest |a - b| over the largest |b|, per (output, input) pair, worst pair.
fn worst(a: &[C64], b: &[C64], n_pairs: usize) -> f64 {
    (0..n_pairs)
        .map(|k| {
            let peak = b
                .iter()
                .skip(k)
                .step_by(n_pairs)
                .map(|z| z.norm())
                .fold(0.0, f64::max);
            a.iter()
                .zip(b)
                .skip(k)
                .step_by(n_pairs)
                .map(|(x, y)| (x - y).norm() / peak)
                .fold(0.0, f64::max)
        })
        .fold(0.0, f64::max)
}

#[test]
fn rom_with_fixed_masses_and_beam_factor_equals_the_full_model_with_them() {
    // No viscous C_b: the beam factor's scaling is exact for K_b + j D_b (as in the forward
    // model's effect).
    let mut model = crate::rom_model::beam_model(60);
    model.c_b = None;
    let inputs = [0, 1, 2, 3];
    let (rom, cert) = build_rom(&model, &inputs, &RomParams::default()).unwrap();
    assert!(cert.passed);
    let (m1, m3, b) = (0.012, 0.006, 0.04);
    let effects = Effects {
        terms: vec![
            EffectTerm {
                effect: Effect::PointMass { point: 1, id: 2 },
                value: m1,
                free: false,
            },
            EffectTerm {
                effect: Effect::PointMass { point: 3, id: 4 },
                value: m3,
                free: false,
            },
            EffectTerm {
                effect: Effect::BeamModulus,
                value: b,
                free: false,
            },
        ],
    };
    let wrapped = FixedEffectsEngine::new(&rom, &effects).unwrap();
    assert!(!wrapped.is_identity());
    let mut truth = model.with_point_masses(&[(1, m1), (3, m3)]).unwrap();
    truth.k_b.val_mut().iter_mut().for_each(|v| *v *= 1.0 + b);
    if let Some(d) = truth.d_b.as_mut() {
        d.val_mut().iter_mut().for_each(|v| *v *= 1.0 + b);
    }
    let full = FullModel::new(&truth, &inputs, FullParams::default()).unwrap();
    // Lines off the certificate's grid, kept below the ROM's band top after the beam scaling.
    let w: Vec<f64> = (0..120)
        .map(|k| TAU * (1.3 + 470.0 * k as f64 / 119.0))
        .collect();
    let e: Vec<C64> = w.iter().map(|&w| Model3.modulus(&TRUTH, w)).collect();
    let a = wrapped.sweep(&w, &e, true).unwrap();
    let r = full.sweep(&w, &e, true).unwrap();
    let pairs = r.n_out * r.n_in;
    assert_eq!((a.sh.len(), r.sh.len()), (a.h.len(), r.h.len()));
    let (eh, ed, es) = (
        worst(&a.h, &r.h, pairs),
        worst(&a.dh_de, &r.dh_de, pairs),
        worst(&a.sh, &r.sh, pairs),
    );
    eprintln!("ROM + fixed effects vs full: H {eh:.2e}, dH/dE' {ed:.2e}, S H {es:.2e}");
    assert!(
        eh < 1e-6 && ed < 1e-6 && es < 1e-6,
        "{eh:.2e} {ed:.2e} {es:.2e}"
    );
    // The masses matter at this size (not a test that cannot fail).
    let bare = rom.sweep(&w, &e, false).unwrap();
    assert!(worst(&bare.h, &r.h, pairs) > 1e-2);
    // A mass at a point that is not an engine input is an error, not a silent skip.
    let (rom1, _) = build_rom(&model, &[1], &RomParams::default()).unwrap();
    assert!(FixedEffectsEngine::new(&rom1, &effects).is_err());
}

#[test]
fn wrapped_rom_modes_equal_the_full_model_modes_with_the_masses() {
    let mut model = crate::rom_model::beam_model(60);
    model.c_b = None;
    let inputs = [0, 1, 2, 3];
    let (rom, _) = build_rom(&model, &inputs, &RomParams::default()).unwrap();
    let effects = Effects {
        terms: vec![
            EffectTerm {
                effect: Effect::PointMass { point: 3, id: 4 },
                value: 0.012,
                free: false,
            },
            EffectTerm {
                effect: Effect::BeamModulus,
                value: 0.04,
                free: false,
            },
        ],
    };
    let wrapped = FixedEffectsEngine::new(&rom, &effects).unwrap();
    let e = C64::new(5e6, 1.5e6);
    let a = wrapped.complex_modes(e, 3).unwrap().unwrap();
    let mut truth = model.with_point_masses(&[(3, 0.012)]).unwrap();
    truth.k_b.val_mut().iter_mut().for_each(|v| *v *= 1.04);
    if let Some(d) = truth.d_b.as_mut() {
        d.val_mut().iter_mut().for_each(|v| *v *= 1.04);
    }
    let r = rfmlab::modes::complex_modes(&truth, e, 3, None, &Default::default()).unwrap();
    let plain = rom.complex_modes(e, 3).unwrap();
    for k in 0..3 {
        let rel = (a[k].lambda - r[k].lambda).norm() / r[k].lambda.norm();
        let sens = (a[k].phi_s_phi - r[k].phi_s_phi).norm() / r[k].phi_s_phi.norm();
        eprintln!(
            "mode {k}: {:.3} Hz (bare {:.3} Hz), lambda rel err {rel:.1e}, phi^T S phi {sens:.1e}",
            r[k].lambda.re.sqrt() / TAU,
            plain[k].freq_hz()
        );
        assert!(rel < 1e-6 && sens < 1e-4, "mode {k}: {rel:.2e} {sens:.2e}");
        assert!((plain[k].lambda - r[k].lambda).norm() / r[k].lambda.norm() > 1e-3);
    }
}

/// The study's global RFM on frequency-domain data with a 12 g mass at point 4 (the closed
/// loop's example data): with the mass declared the identified Model 4 is the truth's; the
/// same study without it is biased (what the closed loop exists to catch).
#[test]
fn declared_mass_brings_the_deterministic_rfm_back_to_the_truth() {
    use rfmlab::report::run_study;
    use rfmlab::report::RunOptions;
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(root.join("studies/closed_loop_mass.toml")).unwrap();
    // Deterministic part only, level L1, Model 4.
    let text = &text[..text.find("[inference]").unwrap()];
    let data = root.join("studies/data/closed_loop").display().to_string();
    let text = text.replace("data/closed_loop", &data);
    let l2 = text.find("[[measurements.levels]]\nname = \"L2\"").unwrap();
    let models = text.find("[[models]]").unwrap();
    let text = format!("{}{}", &text[..l2], &text[models..]);
    let truth = [6.67e6, 944e3, 3.1487e6, 4181.0];
    let dir = tempfile::tempdir().unwrap();
    let mut worst = Vec::new();
    for declare in [false, true] {
        let mut t = text.clone();
        if declare {
            t.push_str(
                "\n[[structure.effects]]\ntype = \"point_mass\"\npoint = 4\nvalue = 0.012\n",
            );
        }
        let f = dir.path().join(format!("mass_{declare}.toml"));
        std::fs::write(&f, &t).unwrap();
        let study = rfmlab::study::load(&f).unwrap();
        let opts = RunOptions {
            no_figures: true,
            output_dir: Some(dir.path().join(format!("out_{declare}"))),
            rom_cache: Some(crate::shared_rom_cache::runs_folder()),
        };
        let s = run_study(&study, &opts, &|_| {}).unwrap();
        let m4 = s
            .models
            .iter()
            .find(|m| m.level == "L1" && m.model == "model4")
            .unwrap();
        let err = m4
            .identified
            .iter()
            .zip(&truth)
            .map(|(a, b)| ((a - b) / b).abs())
            .fold(0.0, f64::max);
        eprintln!(
            "declared {declare}: Model 4 {:?}, worst relative error {err:.3}, FRAC {:?}",
            m4.identified, m4.frac
        );
        if declare {
            let report = std::fs::read_to_string(s.output_dir.join("report.md")).unwrap();
            assert!(report.contains("structure.effects[0] (point masses, beam modulus) are in the deterministic analyses"));
        }
        worst.push(err);
    }
    assert!(worst[0] > 0.2, "undeclared mass: {:.3}", worst[0]);
    assert!(worst[1] < 0.03, "declared mass: {:.3}", worst[1]);
}

/// The mass effect acts in the measured direction only. A real sensor's mass also acts in x
/// and z; on this rig (points on the beam's top face and centreline, excitation in y) the
/// cross-axis inertia changes the measured y FRFs by a small fraction of what the y inertia
/// does: measured here on the full model of the default rig with a 12 g mass at point 4 in
/// y alone and in x, y and z.
#[test]
fn cross_axis_inertia_of_a_sensor_is_small_beside_its_measured_axis_inertia() {
    use rfmlab::common::Direction;
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let study = rfmlab::study::load(&root.join("studies/default.toml")).unwrap();
    let mut structure = study.structure.clone();
    let p4 = structure.points.iter().find(|p| p.id == 4).unwrap().clone();
    for d in [Direction::PX, Direction::PZ] {
        let mut q = p4.clone();
        q.direction = d;
        structure.points.push(q);
    }
    let built = rfmlab::study::build::build_model(&structure, "default.toml").unwrap();
    let idx = |dir: Direction| {
        built
            .model
            .points
            .iter()
            .position(|p| p.id == 4 && p.direction == dir)
            .unwrap()
    };
    let (iy, ix, iz) = (idx(Direction::PY), idx(Direction::PX), idx(Direction::PZ));
    let m = 0.012;
    let y_only = built.model.with_point_masses(&[(iy, m)]).unwrap();
    let xyz = built
        .model
        .with_point_masses(&[(iy, m), (ix, m), (iz, m)])
        .unwrap();
    // 50 lines over 2-489 Hz: the full model's LU per line and model is this test's cost.
    let w: Vec<f64> = (0..50).map(|k| TAU * (2.0 + 9.94 * k as f64)).collect();
    let e: Vec<C64> = w
        .iter()
        .map(|&w| rfmlab::material::Model4.modulus(&[6.67e6, 944e3, 3.1487e6, 4181.0], w))
        .collect();
    let sweep = |m: &rfmlab::fe::model::StructuralModel| {
        FullModel::new(m, &[built.excitation], FullParams::default())
            .unwrap()
            .sweep(&w, &e, false)
            .unwrap()
    };
    let (bare, a, b) = (sweep(&built.model), sweep(&y_only), sweep(&xyz));
    // The y responses (the study's 4 points) only.
    let ys: Vec<usize> = (0..built.model.points.len())
        .filter(|&k| built.model.points[k].direction == Direction::PY)
        .collect();
    let pick = |s: &rfmlab::frf::Sweep| -> Vec<C64> {
        (0..s.n_lines)
            .flat_map(|l| ys.iter().map(move |&o| s.h[s.idx(l, o, 0)]))
            .collect()
    };
    let (hb, ha, hx) = (pick(&bare), pick(&a), pick(&b));
    let in_axis = worst(&ha, &hb, ys.len());
    let cross = worst(&hx, &ha, ys.len());
    eprintln!("12 g at point 4: y inertia changes H by {in_axis:.2e} of the peak, x and z inertia by {cross:.2e} more");
    assert!(in_axis > 0.05);
    assert!(cross < 0.02 * in_axis, "{cross:.2e} vs {in_axis:.2e}");
}
