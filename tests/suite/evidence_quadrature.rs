//! Both sampled evidence estimators against brute-force quadrature on two-parameter models
//! (required: within 0.1 nats): TMCMC with its final importance reweighting
//! (a Student-t fitted to its 1000 particles, 4000 independent draws: the runner's `tmcmc_is`)
//! and the generalized stepping-stone from a reference fitted to TMCMC's particles (the
//! runner's path when NUTS is off), on Model 1 (E0 + j h) and Model 2 (E0 + j w eta0) through the product's likelihood on
//! the small dense chain of `inference_grid` (15 Hz around the 39.5 Hz resonance, coherence
//! noise of 2.3 % per real part, log-uniform priors two to three decades wide: the posterior is
//! about 1000 times narrower than the prior in each coordinate).
//!
//! Reference: `validate::quadrature_log_evidence`, the tensor trapezoid rule on 161 x 161 nodes
//! over +-9 Laplace sd in the samplers' unconstrained coordinates of `Posterior::log_posterior`
//! (prior density with the transform's Jacobian included), converged: 121 x 121 nodes and +-7 sd
//! give the same number to 1e-4 nats (checked here).
//!
//! TMCMC's own product of stage means is printed and held only to 0.5 nats: on the Model 1
//! posterior here, 1000 particles gave errors -0.07, +0.16, +0.19, +0.37 (seeds 11-14, delta-
//! method se 0.10 each, so its real spread is about twice its se) and 2000 particles -0.30
//! (seed 11, se 0.074).

use crate::spring_model::{measured_engine as engine, Normal};
use rfmlab::common::C64;
use rfmlab::forward::ForwardModel;
use rfmlab::inference::likelihood::{
    ErrorLaw, FrfData, FrfLikelihood, FrfPosterior, NoiseModel, Scale,
};
use rfmlab::inference::map::{find_map, MapParams};
use rfmlab::inference::prior::Prior;
use rfmlab::inference::{
    importance_evidence, no_progress, reference_stepping_stone, sample_tmcmc, Reference,
    SteppingStoneParams, TmcmcParams,
};
use rfmlab::material::{ConstitutiveModel, Model1, Model2};
use rfmlab::rfm::DenseEngine;
use rfmlab::validate::quadrature_log_evidence;
use std::f64::consts::TAU;
use std::time::Instant;

const COHERENCE: f64 = 0.95;
const N_AVERAGES: f64 = 50.0;

/// Data from `law` at `truth` with coherence-model noise, and log-uniform `priors`.
fn posterior<'a>(
    eng: &'a DenseEngine,
    law: &'a dyn ConstitutiveModel,
    truth: &[f64],
    priors: Vec<Prior>,
    noise_seed: u64,
) -> FrfPosterior<'a> {
    let freq_hz: Vec<f64> = (0..=30).map(|k| 32.0 + 0.5 * k as f64).collect();
    let omega: Vec<f64> = freq_hz.iter().map(|f| TAU * f).collect();
    let outputs = [0, 1, 2, 3];
    let truth_model = ForwardModel::new(eng, law, &omega, 1, &outputs, None).unwrap();
    let h = truth_model.exact(truth, false).unwrap().values;
    let mut rng = Normal(noise_seed);
    let rel = ((1.0 - COHERENCE) / (2.0 * N_AVERAGES * COHERENCE)).sqrt();
    let values: Vec<C64> = h
        .iter()
        .map(|v| v + C64::new(rng.next(), rng.next()) * (rel * v.norm()))
        .collect();
    let data = FrfData {
        freq_hz,
        n_out: 4,
        coherence: Some(vec![COHERENCE; values.len()]),
        values,
    };
    let fm = ForwardModel::new(eng, law, &omega, 1, &outputs, None).unwrap();
    let noise = NoiseModel {
        scale: Scale::Coherence {
            n_averages: N_AVERAGES,
            floor: 1e-4,
        },
        errors: ErrorLaw::Gaussian,
        model_error: 0.0,
    };
    let lik = FrfLikelihood::new(fm, data, noise, &[1, 2, 3, 4]).unwrap();
    FrfPosterior::new(lik, priors).unwrap()
}

fn check(name: &str, post: &FrfPosterior<'_>, start: &[f64], seed: u64) {
    let t = Instant::now();
    let map = find_map(
        post,
        Some(&post.unconstrained(start)),
        &MapParams {
            n_starts: 4,
            ..MapParams::default()
        },
        &|| {},
    )
    .unwrap();
    assert!(map.laplace.positive_definite);
    let (quad, _) = quadrature_log_evidence(post, &map, 161, 9.0).unwrap();
    let (coarse, _) = quadrature_log_evidence(post, &map, 121, 7.0).unwrap();
    assert!(
        (quad - coarse).abs() < 1e-4,
        "{name}: quadrature not converged: {quad} vs {coarse}"
    );
    let tm = sample_tmcmc(
        post,
        &TmcmcParams {
            particles: 1000,
            seed,
            ..TmcmcParams::default()
        },
        None,
        &no_progress,
    )
    .unwrap();
    let q = Reference::from_draws(&tm.x, 1.5, 5.0).unwrap();
    let is = importance_evidence(post, &q, 4000, seed).unwrap();
    let g = reference_stepping_stone(
        post,
        &q,
        &SteppingStoneParams {
            particles: 250,
            replicas: 8,
            seed,
            ..SteppingStoneParams::default()
        },
        &no_progress,
    )
    .unwrap();
    eprintln!(
        "{name}: log Z quadrature {quad:.4} (121 nodes, 7 sd: {coarse:.4}) | Laplace {:+.4} | TMCMC {:+.4} +- {:.4} ({} calls) | TMCMC reweighted {:+.4} +- {:.4} (ESS {:.2}) | reference stepping-stone {:+.4} +- {:.4} ({} calls, rungs {:?}) ({:.1} s)",
        map.laplace.log_evidence - quad,
        tm.log_evidence - quad,
        tm.log_evidence_se,
        tm.n_loglik(),
        is.log_evidence - quad,
        is.log_evidence_se,
        is.ess,
        g.log_evidence - quad,
        g.log_evidence_se,
        g.n_loglik,
        g.replicas.iter().map(|r| r.rungs.len()).collect::<Vec<_>>(),
        t.elapsed().as_secs_f64()
    );
    assert!(
        (tm.log_evidence - quad).abs() < 0.5,
        "{name}: TMCMC {} vs quadrature {quad}",
        tm.log_evidence
    );
    for (what, v, se) in [
        ("TMCMC reweighted", is.log_evidence, is.log_evidence_se),
        ("stepping-stone", g.log_evidence, g.log_evidence_se),
    ] {
        assert!(
            (v - quad).abs() < 0.1,
            "{name}: {what} {v} vs quadrature {quad}"
        );
        assert!(
            (v - quad).abs() < 3.5 * se,
            "{name}: {what} {v} +- {se} vs quadrature {quad}: the error bar is dishonest"
        );
    }
}

#[test]
fn reweighted_tmcmc_and_reference_stepping_stone_match_quadrature_on_two_parameter_models() {
    let eng = engine();
    // Model 1: E0 5 MPa, h 0.5 MPa (loss factor 0.1).
    let post = posterior(
        &eng,
        &Model1,
        &[5.0e6, 5.0e5],
        vec![
            Prior::LogUniform { lo: 1e6, hi: 3e7 },
            Prior::LogUniform { lo: 1e4, hi: 1e7 },
        ],
        2024,
    );
    check("model1", &post, &[6.5e6, 3.5e5], 11);
    // Model 2: E0 5 MPa, eta0 2 kPa s (loss factor 0.1 at 39.8 Hz).
    let post = posterior(
        &eng,
        &Model2,
        &[5.0e6, 2.0e3],
        vec![
            Prior::LogUniform { lo: 1e6, hi: 3e7 },
            Prior::LogUniform { lo: 1e1, hi: 1e5 },
        ],
        77,
    );
    check("model2", &post, &[6.5e6, 1.4e3], 12);
}
