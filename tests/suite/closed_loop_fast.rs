//! The closed loop's fast path: with effects in the forward model,
//! the gradient of the likelihood is one vector-Jacobian product
//! ([`rfmlab::forward::ForwardModel::linearise`]) pulled back through the measurement kernel
//! and the channel factor; it must equal the contraction of the full Jacobian
//! (`Re sum conj(c) J`, itself checked against finite differences in `effects.rs`) for any
//! cotangent, with and without a measurement model, free and fixed effects of every kind.

use crate::spring_model::{hann_measurement, measured_engine, Normal};
use rfmlab::common::C64;
use rfmlab::forward::{Effect, EffectTerm, Effects, ForwardModel};
use rfmlab::material::Model3;
use std::f64::consts::TAU;

const TRUTH: [f64; 3] = [4.7121e6, 5.5573e6, 6.0491e3];

/// The tests' lines (rad/s): 8 to 962 Hz every 6 Hz.
fn lines() -> Vec<f64> {
    (0..160).map(|i| TAU * (8.0 + 6.0 * i as f64)).collect()
}

fn term(effect: Effect, value: f64, free: bool) -> EffectTerm {
    EffectTerm {
        effect,
        value,
        free,
    }
}

#[test]
fn vjp_with_effects_equals_the_full_jacobian() {
    let eng = measured_engine();
    let w = lines();
    let lines_hz: Vec<f64> = w.iter().map(|w| w / TAU).collect();
    let mm = hann_measurement(&lines_hz);
    for measurement in [None, Some(mm)] {
        let mut fm = ForwardModel::new(&eng, &Model3, &w, 1, &[0, 1, 2, 3], measurement).unwrap();
        fm.set_effects(Effects {
            terms: vec![
                term(Effect::PointMass { point: 3, id: 4 }, 0.0, true),
                term(Effect::Gain { channel: 1, id: 2 }, 0.0, true),
                term(Effect::PointMass { point: 0, id: 1 }, 0.005, false),
                term(Effect::Delay { channel: 3, id: 4 }, 0.0, true),
                term(Effect::Gain { channel: 2, id: 3 }, 0.03, false),
                term(Effect::BeamModulus, 0.0, true),
            ],
        })
        .unwrap();
        let mut p = TRUTH.to_vec();
        p.extend([0.011, 0.03, 40e-6, 0.02]);
        let pred = fm.predict(&p, true).unwrap();
        let lin = fm.linearise(&p).unwrap();
        let peak = pred.values.iter().map(|z| z.norm()).fold(0.0, f64::max);
        let dv = lin
            .values
            .iter()
            .zip(&pred.values)
            .map(|(a, b)| (a - b).norm())
            .fold(0.0, f64::max);
        assert!(dv <= 1e-12 * peak, "values differ by {dv:e} of {peak:e}");
        let mut rng = Normal(7);
        for _ in 0..3 {
            let c: Vec<C64> = (0..pred.values.len())
                .map(|_| C64::new(rng.next(), rng.next()))
                .collect();
            let g = lin.vjp(&c);
            assert_eq!(g.len(), p.len());
            for (q, col) in pred.jac.iter().enumerate() {
                let reference: f64 = col.iter().zip(&c).map(|(j, z)| (z.conj() * j).re).sum();
                let scale: f64 = col.iter().zip(&c).map(|(j, z)| (z.conj() * j).norm()).sum();
                assert!(
                    (g[q] - reference).abs() <= 1e-10 * scale,
                    "parameter {q}: vjp {} against {reference} (scale {scale:e})",
                    g[q]
                );
            }
        }
    }
}

/// The measurement bias linearised at `p0` with effects in the model (the law's parameters in
/// `ln p`, the effects' in `p`; what the loop's refits with a term ROM run on): equal to the
/// exact kernel in value and Jacobian at `p0`, second order in the step around it, and its
/// vector-Jacobian product equal to its Jacobian's contraction.
#[test]
fn linearised_bias_with_effects_is_exact_at_p0_and_second_order_around_it() {
    let eng = measured_engine();
    let w = lines();
    let lines_hz: Vec<f64> = w.iter().map(|w| w / TAU).collect();
    let mm = hann_measurement(&lines_hz);
    let effects = Effects {
        terms: vec![
            term(Effect::PointMass { point: 3, id: 4 }, 0.0, true),
            term(Effect::Gain { channel: 1, id: 2 }, 0.0, true),
            term(Effect::BeamModulus, 0.0, true),
        ],
    };
    let model = |linearise_at: Option<&[f64]>| {
        let mut fm =
            ForwardModel::new(&eng, &Model3, &w, 1, &[0, 1, 2, 3], Some(mm.clone())).unwrap();
        fm.set_effects(effects.clone()).unwrap();
        if let Some(p0) = linearise_at {
            fm.linearise_model_measurement(p0).unwrap();
            assert!(fm.linear_bias.is_some());
        }
        fm
    };
    let mut p0 = TRUTH.to_vec();
    p0.extend([0.004, 0.01, 0.0]);
    let exact = model(None);
    let lin = model(Some(&p0));
    let a = exact.predict(&p0, true).unwrap();
    let b = lin.predict(&p0, true).unwrap();
    let peak = a.values.iter().map(|z| z.norm()).fold(0.0, f64::max);
    let max_diff = |x: &[C64], y: &[C64]| {
        x.iter()
            .zip(y)
            .map(|(u, v)| (u - v).norm())
            .fold(0.0, f64::max)
    };
    assert!(max_diff(&a.values, &b.values) <= 1e-12 * peak);
    for (q, (ca, cb)) in a.jac.iter().zip(&b.jac).enumerate() {
        let scale = ca.iter().map(|z| z.norm()).fold(0.0, f64::max);
        let d = max_diff(ca, cb);
        assert!(d <= 1e-9 * scale, "column {q}: {d:e} of {scale:e}");
    }
    // Around p0 the error is second order: doubling the step quadruples it.
    let step = |h: f64| -> Vec<f64> {
        let mut p = p0.clone();
        for x in &mut p[..3] {
            *x *= 1.0 + h;
        }
        p[3] += 0.05 * h;
        p[4] += 0.1 * h;
        p[5] += 0.2 * h;
        p
    };
    let err = |h: f64| {
        let p = step(h);
        max_diff(
            &exact.predict(&p, false).unwrap().values,
            &lin.predict(&p, false).unwrap().values,
        ) / peak
    };
    // (On this test chain's 6 Hz lines the bias is large and its curvature too: 2e-4 of the
    // peak at h = 1e-4, 2e-2 at 1e-3.)
    let (e1, e2) = (err(1e-4), err(2e-4));
    eprintln!("linearised bias error: {e1:.2e} at h = 1e-4, {e2:.2e} at h = 2e-4");
    assert!(e1 > 0.0 && e1 < 1e-3, "{e1:e}");
    assert!(e2 / e1 > 3.0 && e2 / e1 < 5.0, "ratio {}", e2 / e1);
    // Its vector-Jacobian product away from p0.
    let p = step(0.01);
    let pred = lin.predict(&p, true).unwrap();
    let l = lin.linearise(&p).unwrap();
    assert!(max_diff(&l.values, &pred.values) <= 1e-12 * peak);
    let mut rng = Normal(11);
    let c: Vec<C64> = (0..pred.values.len())
        .map(|_| C64::new(rng.next(), rng.next()))
        .collect();
    let g = l.vjp(&c);
    for (q, col) in pred.jac.iter().enumerate() {
        let reference: f64 = col.iter().zip(&c).map(|(j, z)| (z.conj() * j).re).sum();
        let scale: f64 = col.iter().zip(&c).map(|(j, z)| (z.conj() * j).norm()).sum();
        assert!(
            (g[q] - reference).abs() <= 1e-10 * scale,
            "parameter {q}: vjp {} against {reference}",
            g[q]
        );
    }
}
