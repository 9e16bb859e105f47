//! The MCMC diagnostics and predictive criteria (src/inference/diagnostics.rs, loo.rs) against
//! ArviZ (scripts/arviz_reference.py) on seeded draw sets: iid normal, AR(1) with phi = 0.95,
//! Student-t(3), chains with shifted means, odd and short chains, a single chain, constant
//! chains; LOO/WAIC of a normal model over 50 observations with one outlier.
//! R-hat, ESS, MCSE, quantiles and HDI agree to 1e-8 (relative), LOO/WAIC to 1e-6 (relative),
//! Pareto k to 1e-6 (absolute).

use crate::python_checks::{arviz_reference, python_for_arviz};
use rand::rngs::Xoshiro256PlusPlus;
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal, StudentT};
use rfmlab::inference::diagnostics::{self as diag, Summary};
use rfmlab::inference::loo::{self, PARETO_K_THRESHOLD};
use serde_json::{json, Value};

type Draws = Vec<Vec<f64>>;

fn rng(seed: u64) -> Xoshiro256PlusPlus {
    Xoshiro256PlusPlus::seed_from_u64(seed)
}

fn normal(r: &mut Xoshiro256PlusPlus) -> f64 {
    StandardNormal.sample(r)
}

/// `m` chains of `n` draws; chain `j` is AR(1) with coefficient `phi`, unit stationary variance
/// and mean `shift * j`.
fn ar1(m: usize, n: usize, phi: f64, shift: f64, seed: u64) -> Draws {
    let mut r = rng(seed);
    (0..m)
        .map(|j| {
            let mut x = normal(&mut r);
            (0..n)
                .map(|_| {
                    x = phi * x + (1.0 - phi * phi).sqrt() * normal(&mut r);
                    x + shift * j as f64
                })
                .collect()
        })
        .collect()
}

fn student_t(m: usize, n: usize, seed: u64) -> Draws {
    let mut r = rng(seed);
    let t = StudentT::new(3.0).unwrap();
    (0..m)
        .map(|_| (0..n).map(|_| t.sample(&mut r)).collect())
        .collect()
}

/// A number of the report: null is NaN, "inf"/"-inf" infinities.
fn num(v: &Value) -> f64 {
    match v {
        Value::Null => f64::NAN,
        Value::String(s) if s == "inf" => f64::INFINITY,
        Value::String(s) if s == "-inf" => f64::NEG_INFINITY,
        _ => v.as_f64().unwrap_or_else(|| panic!("not a number: {v}")),
    }
}

fn nums(v: &Value) -> Vec<f64> {
    v.as_array().unwrap().iter().map(num).collect()
}

/// `ours` equals `theirs` to `rel` relative (both NaN, or equal infinities, also count).
fn close(what: &str, ours: f64, theirs: f64, rel: f64) {
    let ok = (ours.is_nan() && theirs.is_nan())
        || ours == theirs
        || (ours - theirs).abs() <= rel * theirs.abs();
    assert!(
        ok,
        "{what}: ours {ours:e}, ArviZ {theirs:e} (rel. diff {:e})",
        ((ours - theirs) / theirs).abs()
    );
}

/// Every per-parameter diagnostic of `params` against ArviZ's `report`.
fn check_params(params: &[(&str, Draws)], report: &Value, hdi_prob: f64) {
    for (name, d) in params {
        let r = &report["params"][*name];
        let w = |k: &str| num(&r[k]);
        let tol = 1e-8;
        let id = |k: &str| format!("{name} {k}");
        close(&id("rhat"), diag::rhat(d).unwrap(), w("rhat"), tol);
        close(
            &id("ess_bulk"),
            diag::ess_bulk(d).unwrap(),
            w("ess_bulk"),
            tol,
        );
        close(
            &id("ess_tail"),
            diag::ess_tail(d).unwrap(),
            w("ess_tail"),
            tol,
        );
        close(
            &id("ess_mean"),
            diag::ess_mean(d).unwrap(),
            w("ess_mean"),
            tol,
        );
        close(
            &id("ess_q05"),
            diag::ess_quantile(d, 0.05).unwrap(),
            w("ess_q05"),
            tol,
        );
        close(
            &id("mcse_mean"),
            diag::mcse_mean(d).unwrap(),
            w("mcse_mean"),
            tol,
        );
        close(&id("mcse_sd"), diag::mcse_sd(d).unwrap(), w("mcse_sd"), tol);
        close(
            &id("mcse_q05"),
            diag::mcse_quantile(d, 0.05).unwrap(),
            w("mcse_q05"),
            tol,
        );
        close(
            &id("mcse_q95"),
            diag::mcse_quantile(d, 0.95).unwrap(),
            w("mcse_q95"),
            tol,
        );
        let s: Summary = diag::summary(d, hdi_prob).unwrap();
        let hdi = nums(&r["hdi"]);
        close(&id("hdi lower"), s.hdi_lower, hdi[0], tol);
        close(&id("hdi upper"), s.hdi_upper, hdi[1], tol);
        close(&id("mean"), s.mean, w("mean"), tol);
        close(&id("sd"), s.sd, w("sd"), tol);
        let q = nums(&r["quantiles"]);
        for (k, (ours, theirs)) in [s.median, s.q2_5, s.q97_5, s.q5, s.q95]
            .iter()
            .zip(&q)
            .enumerate()
        {
            close(&id(&format!("quantile {k}")), *ours, *theirs, tol);
        }
        close(&id("summary rhat"), s.r_hat, w("rhat"), tol);
        close(&id("summary ess_bulk"), s.ess_bulk, w("ess_bulk"), tol);
        close(&id("summary ess_tail"), s.ess_tail, w("ess_tail"), tol);
        close(&id("summary mcse_mean"), s.mcse_mean, w("mcse_mean"), tol);
        close(&id("summary mcse_sd"), s.mcse_sd, w("mcse_sd"), tol);
    }
}

fn input(params: &[(&str, Draws)], hdi_prob: f64) -> Value {
    let p: serde_json::Map<String, Value> = params
        .iter()
        .map(|(n, d)| (n.to_string(), json!(d)))
        .collect();
    json!({ "params": p, "hdi_prob": hdi_prob })
}

/// Posterior draws of (mu, sigma) of a normal model with AR(1)-correlated chains, the data
/// (50 observations, the last an outlier 8 sd out) and the pointwise log likelihood
/// `[chain][draw][obs]`.
fn normal_model(m: usize, n: usize, seed: u64) -> (Draws, Draws, Vec<Vec<Vec<f64>>>) {
    let mut r = rng(seed);
    let mut y: Vec<f64> = (0..49).map(|_| 1.0 + 0.5 * normal(&mut r)).collect();
    y.push(5.0);
    let nf = y.len() as f64;
    let ybar = y.iter().sum::<f64>() / nf;
    let s = (y.iter().map(|v| (v - ybar).powi(2)).sum::<f64>() / (nf - 1.0)).sqrt();
    let z_mu = ar1(m, n, 0.6, 0.0, seed + 1);
    let z_ls = ar1(m, n, 0.3, 0.0, seed + 2);
    let mu: Draws = z_mu
        .iter()
        .map(|c| c.iter().map(|z| ybar + s / nf.sqrt() * z).collect())
        .collect();
    let sigma: Draws = z_ls
        .iter()
        .map(|c| {
            c.iter()
                .map(|z| s * (z / (2.0 * nf).sqrt()).exp())
                .collect()
        })
        .collect();
    let ll = (0..m)
        .map(|j| {
            (0..n)
                .map(|k| {
                    let (mu, sg) = (mu[j][k], sigma[j][k]);
                    y.iter()
                        .map(|yi| {
                            -0.5 * (2.0 * std::f64::consts::PI).ln()
                                - sg.ln()
                                - (yi - mu).powi(2) / (2.0 * sg * sg)
                        })
                        .collect()
                })
                .collect()
        })
        .collect();
    (mu, sigma, ll)
}

/// LOO and WAIC against ArviZ's, whose default relative efficiency comes from all the
/// posterior's quantities (`params`).
fn check_loo_waic(params: &[(&str, Draws)], ll: &[Vec<Vec<f64>>], report: &Value) -> loo::Loo {
    let all: Vec<Draws> = params.iter().map(|(_, d)| d.clone()).collect();
    let r_eff = loo::relative_eff(&all).unwrap();
    let l = loo::loo(ll, r_eff).unwrap();
    let a = &report["loo"];
    assert_eq!(a["scale"], "log");
    let tol = 1e-6;
    let k = nums(&a["pareto_k"]);
    let pw = nums(&a["pointwise"]);
    assert_eq!(l.pareto_k.len(), k.len());
    for (i, (ours, theirs)) in l.pareto_k.iter().zip(&k).enumerate() {
        assert!(
            (ours - theirs).abs() <= 1e-6 || ours == theirs,
            "pareto k[{i}]: ours {ours}, ArviZ {theirs}"
        );
    }
    for (i, (ours, theirs)) in l.pointwise.iter().zip(&pw).enumerate() {
        close(&format!("loo_i[{i}]"), *ours, *theirs, tol);
    }
    close("elpd_loo", l.elpd, num(&a["elpd"]), tol);
    close("loo se", l.se, num(&a["se"]), tol);
    close("p_loo", l.p_loo, num(&a["p_loo"]), tol);
    close("good_k", l.good_k, num(&a["good_k"]), 1e-12);
    assert_eq!(l.warning, a["warning"].as_bool().unwrap());
    let w = loo::waic(ll).unwrap();
    let a = &report["waic"];
    close("elpd_waic", w.elpd, num(&a["elpd"]), tol);
    close("waic se", w.se, num(&a["se"]), tol);
    close("p_waic", w.p_waic, num(&a["p_waic"]), tol);
    assert_eq!(w.warning, a["warning"].as_bool().unwrap());
    for (i, (ours, theirs)) in w.pointwise.iter().zip(&nums(&a["pointwise"])).enumerate() {
        close(&format!("waic_i[{i}]"), *ours, *theirs, tol);
    }
    l
}

#[test]
fn four_chains_of_1000_match_arviz() {
    let Some(py) = python_for_arviz("four_chains_of_1000_match_arviz") else {
        return;
    };
    let (m, n) = (4, 1000);
    let (mu, sigma, ll) = normal_model(m, n, 40);
    let params = [
        ("mu", mu.clone()),
        ("sigma", sigma.clone()),
        ("iid", ar1(m, n, 0.0, 0.0, 1)),
        ("ar1", ar1(m, n, 0.95, 0.0, 2)),
        ("student_t", student_t(m, n, 3)),
        ("shifted", ar1(m, n, 0.5, 0.4, 4)),
    ];
    // NUTS-like energies: a well-mixed chain, and a sticky one (low E-BFMI).
    let energy: Draws = [0.0, 0.5, 0.9, 0.99]
        .iter()
        .enumerate()
        .map(|(j, &phi)| ar1(1, n, phi, 0.0, 10 + j as u64).remove(0))
        .collect();
    let mut inp = input(&params, 0.94);
    inp["energy"] = json!(energy);
    inp["log_lik"] = json!(ll);
    let report = arviz_reference(&py, &inp);
    eprintln!("ArviZ {}", report["arviz"]);
    check_params(&params, &report, 0.94);

    let b = diag::bfmi(&energy).unwrap();
    for (j, (ours, theirs)) in b.iter().zip(nums(&report["bfmi"])).enumerate() {
        close(&format!("bfmi[{j}]"), *ours, theirs, 1e-8);
    }
    assert!(b[3] < 0.3 && b[0] > 1.5, "bfmi {b:?}");

    // The shifted chains are flagged, the iid ones are not.
    let r_shift = diag::rhat(&params[5].1).unwrap();
    assert!(r_shift > 1.1, "shifted rhat {r_shift}");
    assert!(diag::rhat(&params[2].1).unwrap() < 1.01);

    let l = check_loo_waic(&params, &ll, &report);
    // The outlier has the largest k and is flagged.
    let k_out = l.pareto_k[49];
    assert!(
        l.pareto_k.iter().all(|&k| k <= k_out),
        "outlier k {k_out} is not the largest"
    );
    assert!(
        k_out > PARETO_K_THRESHOLD && l.high_k[49],
        "outlier k {k_out}"
    );
}

#[test]
fn two_chains_of_101_match_arviz() {
    let Some(py) = python_for_arviz("two_chains_of_101_match_arviz") else {
        return;
    };
    let (m, n) = (2, 101);
    let (mu, sigma, ll) = normal_model(m, n, 50);
    let params = [
        ("mu", mu.clone()),
        ("sigma", sigma.clone()),
        ("iid", ar1(m, n, 0.0, 0.0, 21)),
        ("ar1", ar1(m, n, 0.95, 0.0, 22)),
        ("student_t", student_t(m, n, 23)),
        ("shifted", ar1(m, n, 0.0, 2.0, 24)),
    ];
    let mut inp = input(&params, 0.9);
    inp["log_lik"] = json!(ll);
    let report = arviz_reference(&py, &inp);
    check_params(&params, &report, 0.9);
    check_loo_waic(&params, &ll, &report);
}

#[test]
fn edge_cases_match_arviz() {
    let Some(py) = python_for_arviz("edge_cases_match_arviz") else {
        return;
    };
    let params = [
        // Split chains of 3 draws (odd, middle one dropped), of 2, and too short (NaN).
        ("three_by_7", ar1(3, 7, 0.3, 0.0, 31)),
        ("two_by_5", ar1(2, 5, 0.3, 0.0, 32)),
        ("two_by_4", ar1(2, 4, 0.0, 0.0, 33)),
        ("two_by_3", ar1(2, 3, 0.0, 0.0, 34)),
        // One chain: R-hat NaN, ESS from its two halves.
        ("one_by_200", ar1(1, 200, 0.8, 0.0, 35)),
        // Constant: R-hat NaN, ESS = number of draws, MCSE of the sd NaN.
        ("constant", vec![vec![2.5; 50]; 2]),
        // Discrete values with many ties (average ranks).
        (
            "ties",
            ar1(4, 60, 0.5, 0.0, 36)
                .into_iter()
                .map(|c| c.into_iter().map(|v| (2.0 * v).round()).collect())
                .collect(),
        ),
    ];
    let report = arviz_reference(&py, &input(&params, 0.94));
    check_params(&params, &report, 0.94);
    assert!(diag::rhat(&params[5].1).unwrap().is_nan());
    assert!(diag::rhat(&params[3].1).unwrap().is_nan());
    assert!(diag::rhat(&params[4].1).unwrap().is_nan());
}
