//! The closed loop's fast path: with effects in the forward model,
//! the gradient of the likelihood is one vector-Jacobian product
//! ([`rfmlab::forward::ForwardModel::linearise`]) pulled back through the measurement kernel
//! and the channel factor; it must equal the contraction of the full Jacobian
//! (`Re sum conj(c) J`, itself checked against finite differences in `effects.rs`) for any
//! cotangent, with and without a measurement model, free and fixed effects of every kind.

use crate::spring_model::{measured_engine, Normal};
use rfmlab::common::C64;
use rfmlab::experiment::Window;
use rfmlab::forward::{
    Effect, EffectTerm, Effects, EstimatorSpec, ForwardModel, MeasurementModel, MeasurementParams,
};
use rfmlab::material::Model3;
use std::f64::consts::TAU;

const TRUTH: [f64; 3] = [4.7121e6, 5.5573e6, 6.0491e3];

#[test]
fn vjp_with_effects_equals_the_full_jacobian() {
    let eng = measured_engine();
    let w: Vec<f64> = (0..160).map(|i| TAU * (8.0 + 6.0 * i as f64)).collect();
    let lines_hz: Vec<f64> = w.iter().map(|w| w / TAU).collect();
    let mm = MeasurementModel::new(
        EstimatorSpec {
            window: Window::Hann,
            block_s: 1.0 / 6.0,
            fs_hz: 4096.0,
            force_band_hz: (2.0, 1000.0),
            shaker: None,
        },
        &lines_hz,
        &MeasurementParams::default(),
    )
    .unwrap();
    let term = |effect, value, free| EffectTerm {
        effect,
        value,
        free,
    };
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
