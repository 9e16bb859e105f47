//! The effect library (src/forward/effects.rs) against independent solves and finite
//! differences, on the small dense chain:
//! * a point mass through the engine's point receptances (Sherman-Morrison-Woodbury) equals
//!   the dense solve with `M + m b b^T` (relative error <= 1e-9 at every line);
//! * the beam modulus factor by the scaling identity equals the dense solve with
//!   `(1 + b) K_b` (<= 1e-9);
//! * gain and delay act as `(1 + g) exp(-j w tau)` on one channel only;
//! * the forward model's Jacobian in the law's and the effects' parameters matches central
//!   differences, with and without a measurement model;
//! * no effects: predictions are bit-identical to the model without the field.

use crate::spring_model::{chain, hann_measurement, measured_engine, MEASURED};
use rfmlab::common::C64;
use rfmlab::forward::{Effect, EffectTerm, Effects, ForwardModel};
use rfmlab::material::Model3;
use rfmlab::rfm::DenseEngine;
use std::f64::consts::TAU;

const TRUTH: [f64; 3] = [4.7121e6, 5.5573e6, 6.0491e3];

fn lines() -> Vec<f64> {
    (0..160).map(|i| TAU * (8.0 + 6.0 * i as f64)).collect()
}

fn engine_with(mass: Option<(usize, f64)>, beam: f64) -> DenseEngine {
    let (mut m, mut k, s) = chain();
    if let Some((p, v)) = mass {
        let d = MEASURED[p];
        m[(d, d)] += v;
    }
    let n = k.nrows();
    for i in 0..n {
        for j in 0..n {
            k[(i, j)] *= 1.0 + beam;
        }
    }
    DenseEngine::new(
        m,
        k,
        s,
        MEASURED.iter().map(|&d| vec![(d, 1.0)]).collect(),
        (0..MEASURED.len()).collect(),
    )
    .unwrap()
}

fn rel_err(a: &[C64], b: &[C64]) -> f64 {
    let peak = b.iter().map(|z| z.norm()).fold(0.0, f64::max);
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).norm() / peak)
        .fold(0.0, f64::max)
}

fn fixed(effect: Effect, value: f64) -> EffectTerm {
    EffectTerm {
        effect,
        value,
        free: false,
    }
}

#[test]
fn structural_effects_equal_the_modified_dense_solve() {
    let eng = measured_engine();
    let w = lines();
    for (mass, beam) in [
        (Some((3, 0.012)), 0.0),
        (None, 0.04),
        (Some((2, 0.006)), -0.03),
    ] {
        let truth_eng = engine_with(mass, beam);
        let reference = ForwardModel::new(&truth_eng, &Model3, &w, 1, &[0, 1, 2, 3], None)
            .unwrap()
            .exact(&TRUTH, false)
            .unwrap()
            .values;
        let mut fm = ForwardModel::new(&eng, &Model3, &w, 1, &[0, 1, 2, 3], None).unwrap();
        let mut terms = Vec::new();
        if let Some((p, v)) = mass {
            terms.push(fixed(
                Effect::PointMass {
                    point: p,
                    id: p as u32 + 1,
                },
                v,
            ));
        }
        if beam != 0.0 {
            terms.push(fixed(Effect::BeamModulus, beam));
        }
        fm.set_effects(Effects { terms }).unwrap();
        let got = fm.exact(&TRUTH, false).unwrap().values;
        let e = rel_err(&got, &reference);
        assert!(e < 1e-9, "mass {mass:?} beam {beam}: relative error {e:e}");
        // And the effect is not negligible (the test can fail).
        let plain = ForwardModel::new(&eng, &Model3, &w, 1, &[0, 1, 2, 3], None)
            .unwrap()
            .exact(&TRUTH, false)
            .unwrap()
            .values;
        assert!(rel_err(&plain, &reference) > 1e-2);
    }
}

#[test]
fn channel_effects_act_on_one_channel() {
    let eng = measured_engine();
    let w = lines();
    let base = ForwardModel::new(&eng, &Model3, &w, 1, &[0, 1, 2, 3], None)
        .unwrap()
        .exact(&TRUTH, false)
        .unwrap()
        .values;
    let mut fm = ForwardModel::new(&eng, &Model3, &w, 1, &[0, 1, 2, 3], None).unwrap();
    fm.set_effects(Effects {
        terms: vec![
            fixed(Effect::Gain { channel: 2, id: 3 }, 0.04),
            fixed(Effect::Delay { channel: 0, id: 1 }, 50e-6),
        ],
    })
    .unwrap();
    let got = fm.predict(&TRUTH, false).unwrap().values;
    for (o, (g, b)) in got.iter().zip(&base).enumerate() {
        let (l, k) = (o / 4, o % 4);
        let want = match k {
            2 => b * 1.04,
            0 => b * C64::from_polar(1.0, -w[l] * 50e-6),
            _ => *b,
        };
        assert!(
            (g - want).norm() <= 1e-14 * b.norm(),
            "line {l} channel {k}"
        );
    }
}

fn check_jacobian(fm: &ForwardModel<'_>, p: &[f64]) {
    let pred = fm.predict(p, true).unwrap();
    let peak = pred.values.iter().map(|z| z.norm()).fold(0.0, f64::max);
    for q in 0..p.len() {
        let h = if p[q].abs() > 0.0 {
            1e-5 * p[q].abs()
        } else {
            1e-6
        };
        let mut pp = p.to_vec();
        pp[q] += h;
        let a = fm.predict(&pp, false).unwrap().values;
        pp[q] -= 2.0 * h;
        let b = fm.predict(&pp, false).unwrap().values;
        let col_peak = pred.jac[q].iter().map(|z| z.norm()).fold(0.0, f64::max);
        assert!(col_peak * h > 1e-8 * peak, "column {q} is zero");
        let err = pred.jac[q]
            .iter()
            .zip(a.iter().zip(&b))
            .map(|(j, (x, y))| (j - (x - y) / (2.0 * h)).norm())
            .fold(0.0, f64::max);
        assert!(
            err < 1e-5 * col_peak,
            "column {q}: error {err:e} of {col_peak:e}"
        );
    }
}

#[test]
fn jacobian_with_effects_matches_finite_differences() {
    let eng = measured_engine();
    let w = lines();
    let lines_hz: Vec<f64> = w.iter().map(|w| w / TAU).collect();
    let mm = hann_measurement(&lines_hz);
    for measurement in [None, Some(mm)] {
        let mut fm = ForwardModel::new(&eng, &Model3, &w, 1, &[0, 1, 2, 3], measurement).unwrap();
        let free = |effect| EffectTerm {
            effect,
            value: 0.0,
            free: true,
        };
        fm.set_effects(Effects {
            terms: vec![
                free(Effect::PointMass { point: 3, id: 4 }),
                free(Effect::Gain { channel: 1, id: 2 }),
                fixed(Effect::PointMass { point: 0, id: 1 }, 0.005),
                free(Effect::Delay { channel: 3, id: 4 }),
                free(Effect::BeamModulus),
            ],
        })
        .unwrap();
        assert_eq!(fm.n_params(), 7);
        let mut p = TRUTH.to_vec();
        p.extend([0.011, 0.03, 40e-6, 0.02]);
        check_jacobian(&fm, &p);
    }
}

#[test]
fn no_effects_leave_predictions_unchanged() {
    let eng = measured_engine();
    let w = lines();
    let a = ForwardModel::new(&eng, &Model3, &w, 1, &[0, 1, 2, 3], None).unwrap();
    let mut b = ForwardModel::new(&eng, &Model3, &w, 1, &[0, 1, 2, 3], None).unwrap();
    b.set_effects(Effects::default()).unwrap();
    let (x, y) = (
        a.predict(&TRUTH, true).unwrap(),
        b.predict(&TRUTH, true).unwrap(),
    );
    assert_eq!(x.values, y.values);
    assert_eq!(x.jac, y.jac);
}

#[test]
fn bad_effects_are_refused() {
    let eng = measured_engine();
    let w = lines();
    let mut fm = ForwardModel::new(&eng, &Model3, &w, 1, &[0, 1, 2, 3], None).unwrap();
    for terms in [
        vec![fixed(Effect::Gain { channel: 4, id: 9 }, 0.0)],
        vec![fixed(Effect::PointMass { point: 7, id: 8 }, 0.01)],
        vec![fixed(Effect::PointMass { point: 1, id: 2 }, -0.01)],
        vec![
            fixed(Effect::BeamModulus, 0.0),
            fixed(Effect::BeamModulus, 0.1),
        ],
    ] {
        assert!(fm.set_effects(Effects { terms }).is_err());
    }
}

/// `a` scaled by `f` (same pattern).
fn scaled(a: &rfmlab::fe::model::SpMat, f: f64) -> rfmlab::fe::model::SpMat {
    use faer::sparse::Triplet;
    let n = a.nrows();
    let sym = a.symbolic();
    let (cp, ri) = (sym.col_ptr(), sym.row_idx());
    let mut t = Vec::new();
    for j in 0..n {
        for p in cp[j]..cp[j + 1] {
            t.push(Triplet::new(ri[p], j, f * a.val()[p]));
        }
    }
    rfmlab::fe::model::SpMat::try_new_from_triplets(n, n, &t).unwrap()
}

/// The certified ROM with a point mass and a beam modulus factor against the full sparse
/// solve of the modified model (`M + m w w^T`, `(1 + b) K_b`): relative error <= 1e-6 of each
/// FRF's peak at lines off the certificate's grid.
#[test]
fn rom_with_structural_effects_matches_the_full_sparse_solve() {
    use rfmlab::frf::{FullModel, FullParams};
    use rfmlab::rom::{build_rom, RomParams};
    // The beam factor's exact scaling needs an adherend without viscous damping.
    let mut model = crate::rom_model::beam_model(60);
    model.c_b = None;
    let inputs = [0, 1, 2, 3];
    let (rom, cert) = build_rom(&model, &inputs, &RomParams::default()).unwrap();
    assert!(cert.passed);
    let w: Vec<f64> = (0..150)
        .map(|k| TAU * (1.0 + 478.0 * k as f64 / 149.0 + 0.37))
        .collect();
    for (mass, beam) in [(0.012, 0.0), (0.0, 0.04), (0.006, -0.03)] {
        let mut truth = model.with_point_masses(&[(3, mass)]).unwrap();
        truth.k_b = scaled(&truth.k_b, 1.0 + beam);
        if let Some(d) = &truth.d_b {
            truth.d_b = Some(scaled(d, 1.0 + beam));
        }
        assert!(truth.c_b.is_none());
        let full = FullModel::new(&truth, &inputs, FullParams::default()).unwrap();
        let reference = ForwardModel::new(&full, &Model3, &w, 1, &[0, 1, 2, 3], None)
            .unwrap()
            .exact(&TRUTH, false)
            .unwrap()
            .values;
        let mut fm = ForwardModel::new(&rom, &Model3, &w, 1, &[0, 1, 2, 3], None).unwrap();
        fm.set_effects(Effects {
            terms: vec![
                fixed(Effect::PointMass { point: 3, id: 4 }, mass),
                fixed(Effect::BeamModulus, beam),
            ],
        })
        .unwrap();
        let got = fm.exact(&TRUTH, false).unwrap().values;
        for k in 0..4 {
            let a: Vec<C64> = got.iter().skip(k).step_by(4).copied().collect();
            let b: Vec<C64> = reference.iter().skip(k).step_by(4).copied().collect();
            let e = rel_err(&a, &b);
            eprintln!("mass {mass} beam {beam} channel {k}: {e:.2e}");
            assert!(e <= 1e-6, "mass {mass} beam {beam} channel {k}: {e:e}");
        }
    }
}
