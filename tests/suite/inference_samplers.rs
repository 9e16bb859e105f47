//! The samplers (NUTS, TMCMC, stepping-stone) on targets with known answers: Gaussian
//! posteriors with analytic mean, covariance and evidence (2-D and 5-D, correlated), a bimodal
//! mixture with known mode masses, a likelihood that fails recoverably on part of the space;
//! then determinism across thread counts and bit-identical resumption from checkpoints.

use std::sync::Mutex;

use rand::rngs::StdRng;
use rand_distr::{Distribution, StandardNormal};
use rfmlab::inference::{
    importance_evidence, no_progress, reference_stepping_stone, sample_nuts, sample_tmcmc,
    stepping_stone, unit_rng, DensityError, NutsParams, Posterior, Progress, Reference,
    SamplerError, SteppingStoneParams, TmcmcParams,
};

// ---------------------------------------------------------------- small dense linear algebra

/// Lower Cholesky factor of a row-major SPD matrix (the library's, unit-tested in
/// `linalg::dense`).
fn chol(a: &[f64], d: usize) -> Vec<f64> {
    rfmlab::linalg::dense::cholesky(a, d).expect("not SPD")
}

fn inverse(a: &[f64], d: usize) -> Vec<f64> {
    rfmlab::linalg::dense::chol_inverse(&chol(a, d), d)
}

fn log_det(a: &[f64], d: usize) -> f64 {
    let l = chol(a, d);
    (0..d).map(|i| 2.0 * l[i * d + i].ln()).sum()
}

fn matvec(a: &[f64], x: &[f64]) -> Vec<f64> {
    let d = x.len();
    (0..d)
        .map(|i| (0..d).map(|k| a[i * d + k] * x[k]).sum())
        .collect()
}

fn add(a: &[f64], b: &[f64]) -> Vec<f64> {
    a.iter().zip(b).map(|(a, b)| a + b).collect()
}

/// `log N(x; m, C)` with `C^-1` and `log det C` given; its gradient in `x` into `grad`.
fn log_normal(x: &[f64], m: &[f64], prec: &[f64], logdet: f64, grad: Option<&mut [f64]>) -> f64 {
    let d = x.len();
    let r: Vec<f64> = x.iter().zip(m).map(|(x, m)| x - m).collect();
    let pr = matvec(prec, &r);
    if let Some(g) = grad {
        g.iter_mut().zip(&pr).for_each(|(g, p)| *g = -p);
    }
    let q: f64 = r.iter().zip(&pr).map(|(a, b)| a * b).sum();
    -0.5 * (q + logdet + d as f64 * (2.0 * std::f64::consts::PI).ln())
}

// ---------------------------------------------------------------- the Gaussian target

/// Prior `N(m0, S0)`, likelihood `N(y; x, R)`: the posterior is Gaussian with precision
/// `S0^-1 + R^-1`, and the evidence is `N(y; m0, S0 + R)`.
pub(crate) struct Gauss {
    d: usize,
    m0: Vec<f64>,
    s0: Vec<f64>,
    s0_prec: Vec<f64>,
    s0_logdet: f64,
    y: Vec<f64>,
    r_prec: Vec<f64>,
    r_logdet: f64,
    /// Likelihood fails (recoverably) where `x[0]` exceeds this.
    fail_above: f64,
}

impl Gauss {
    pub(crate) fn new(m0: Vec<f64>, s0: Vec<f64>, y: Vec<f64>, r: Vec<f64>) -> Self {
        let d = m0.len();
        Self {
            d,
            s0_prec: inverse(&s0, d),
            s0_logdet: log_det(&s0, d),
            r_prec: inverse(&r, d),
            r_logdet: log_det(&r, d),
            m0,
            s0,
            y,
            fail_above: f64::INFINITY,
        }
    }

    /// Posterior mean and covariance.
    fn posterior(&self) -> (Vec<f64>, Vec<f64>) {
        let prec = add(&self.s0_prec, &self.r_prec);
        let cov = inverse(&prec, self.d);
        let b = add(
            &matvec(&self.s0_prec, &self.m0),
            &matvec(&self.r_prec, &self.y),
        );
        (matvec(&cov, &b), cov)
    }

    fn log_evidence(&self) -> f64 {
        let r = inverse(&self.r_prec, self.d);
        let c = add(&self.s0, &r);
        log_normal(
            &self.y,
            &self.m0,
            &inverse(&c, self.d),
            log_det(&c, self.d),
            None,
        )
    }
}

impl Posterior for Gauss {
    fn dim(&self) -> usize {
        self.d
    }
    fn names(&self) -> Vec<String> {
        (0..self.d).map(|i| format!("x{i}")).collect()
    }
    fn log_prior(&self, x: &[f64], grad: Option<&mut [f64]>) -> f64 {
        log_normal(x, &self.m0, &self.s0_prec, self.s0_logdet, grad)
    }
    fn log_likelihood(&self, x: &[f64], grad: Option<&mut [f64]>) -> Result<f64, DensityError> {
        if x[0] > self.fail_above {
            return Err(DensityError::Recoverable(
                "outside the model's range".into(),
            ));
        }
        // N(y; x, R) is symmetric in x and y; its gradient in x is R^-1 (y - x).
        Ok(log_normal(x, &self.y, &self.r_prec, self.r_logdet, grad))
    }
    fn sample_prior(&self, rng: &mut StdRng) -> Vec<f64> {
        let l = chol(&self.s0, self.d);
        let z: Vec<f64> = (0..self.d).map(|_| StandardNormal.sample(rng)).collect();
        (0..self.d)
            .map(|i| self.m0[i] + (0..=i).map(|k| l[i * self.d + k] * z[k]).sum::<f64>())
            .collect()
    }
    fn constrained(&self, x: &[f64]) -> Vec<f64> {
        x.to_vec()
    }
}

fn diag(v: &[f64]) -> Vec<f64> {
    let d = v.len();
    let mut a = vec![0.0; d * d];
    for i in 0..d {
        a[i * d + i] = v[i];
    }
    a
}

/// 2-D: prior N(0, 2^2 I), likelihood correlation 0.67.
fn gauss_2d() -> Gauss {
    Gauss::new(
        vec![0.0, 0.0],
        diag(&[4.0, 4.0]),
        vec![1.0, -0.5],
        vec![0.25, 0.2, 0.2, 0.36],
    )
}

/// 5-D: prior N(0.5, 2^2 I), likelihood scales 0.3-0.7 with correlation 0.6^|i-j|.
fn gauss_5d() -> Gauss {
    let d = 5;
    let sd = [0.3, 0.4, 0.5, 0.6, 0.7];
    let mut r = vec![0.0; d * d];
    for i in 0..d {
        for j in 0..d {
            r[i * d + j] = sd[i] * sd[j] * 0.6f64.powi((i as i32 - j as i32).abs());
        }
    }
    Gauss::new(
        vec![0.5; d],
        diag(&[4.0; 5]),
        vec![1.0, -0.5, 0.3, 2.0, -1.2],
        r,
    )
}

/// Dispersed starts: prior draws from the test's own streams.
fn starts(post: &dyn Posterior, n: usize, seed: u64) -> Vec<Vec<f64>> {
    (0..n)
        .map(|c| post.sample_prior(&mut unit_rng(seed, 1000 + c as u64)))
        .collect()
}

// ---------------------------------------------------------------- estimates

fn mean_var(rows: &[&Vec<f64>], k: usize) -> (f64, f64) {
    let n = rows.len() as f64;
    let m = rows.iter().map(|r| r[k]).sum::<f64>() / n;
    let v = rows.iter().map(|r| (r[k] - m) * (r[k] - m)).sum::<f64>() / (n - 1.0);
    (m, v)
}

/// Monte Carlo standard error of the mean of coordinate `k` by batch means: each chain cut
/// into `batches` consecutive batches, `sd(batch means) / sqrt(number of batches)`.
fn mcse_batch_means(chains: &[Vec<Vec<f64>>], k: usize, batches: usize) -> f64 {
    let mut means = Vec::new();
    for c in chains {
        let b = c.len() / batches;
        for j in 0..batches {
            means.push(c[j * b..(j + 1) * b].iter().map(|r| r[k]).sum::<f64>() / b as f64);
        }
    }
    let n = means.len() as f64;
    let m = means.iter().sum::<f64>() / n;
    let v = means.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (n - 1.0);
    (v / n).sqrt()
}

/// Checks NUTS draws against the analytic posterior: means within 4 MCSE, variances within
/// 10 %. Returns the largest |error| / MCSE and the largest relative variance error.
fn check_nuts(post: &Gauss, chains: &[Vec<Vec<f64>>]) -> (f64, f64) {
    let (mu, cov) = post.posterior();
    let all: Vec<&Vec<f64>> = chains.iter().flatten().collect();
    let (mut worst_z, mut worst_v) = (0.0f64, 0.0f64);
    for k in 0..post.d {
        let (m, v) = mean_var(&all, k);
        let se = mcse_batch_means(chains, k, 20);
        let z = (m - mu[k]).abs() / se;
        let rv = (v / cov[k * post.d + k] - 1.0).abs();
        assert!(
            z < 4.0,
            "x{k}: mean {m} vs {} ({z:.2} MCSE of {se:.2e})",
            mu[k]
        );
        assert!(
            rv < 0.10,
            "x{k}: variance {v} vs {} ({rv:.3})",
            cov[k * post.d + k]
        );
        worst_z = worst_z.max(z);
        worst_v = worst_v.max(rv);
    }
    (worst_z, worst_v)
}

/// Checks equal-weight particles: means within `tol_sd` posterior standard deviations,
/// variances within `tol_var`. Returns the largest errors.
fn check_particles(post: &Gauss, x: &[Vec<f64>], tol_sd: f64, tol_var: f64) -> (f64, f64) {
    let (mu, cov) = post.posterior();
    let all: Vec<&Vec<f64>> = x.iter().collect();
    let (mut worst_m, mut worst_v) = (0.0f64, 0.0f64);
    for k in 0..post.d {
        let (m, v) = mean_var(&all, k);
        let s = cov[k * post.d + k];
        let em = (m - mu[k]).abs() / s.sqrt();
        let ev = (v / s - 1.0).abs();
        assert!(em < tol_sd, "x{k}: mean {m} vs {} ({em:.3} sd)", mu[k]);
        assert!(ev < tol_var, "x{k}: variance {v} vs {s} ({ev:.3})");
        worst_m = worst_m.max(em);
        worst_v = worst_v.max(ev);
    }
    (worst_m, worst_v)
}

fn positions(run: &rfmlab::inference::NutsRun) -> Vec<Vec<Vec<f64>>> {
    run.chains.iter().map(|c| c.x.clone()).collect()
}

fn tmcmc_params(particles: usize, seed: u64) -> TmcmcParams {
    TmcmcParams {
        particles,
        seed,
        ..TmcmcParams::default()
    }
}

// ---------------------------------------------------------------- accuracy

#[test]
fn nuts_recovers_correlated_gaussian_posteriors_in_2d_and_5d() {
    for (name, post) in [("2-D", gauss_2d()), ("5-D", gauss_5d())] {
        let p = NutsParams {
            seed: 11,
            ..NutsParams::default()
        };
        let run = sample_nuts(&post, &starts(&post, 4, 5), &p, None, &no_progress).unwrap();
        assert_eq!(run.chains.len(), 4);
        assert!(run.chains.iter().all(|c| c.len() == 1000));
        assert_eq!(
            run.n_divergent(),
            0,
            "{name}: a Gaussian has no divergences"
        );
        let (z, v) = check_nuts(&post, &positions(&run));
        // The draws' log likelihood and prior are the target's.
        let c = &run.chains[0];
        let x = &c.x[7];
        assert_eq!(c.log_prior[7], post.log_prior(x, None));
        assert_eq!(c.log_lik[7], post.log_likelihood(x, None).unwrap());
        eprintln!("NUTS {name}: max |mean err| = {z:.2} MCSE, max var err = {v:.3}");
    }
}

#[test]
fn tmcmc_recovers_gaussian_posteriors_and_their_evidence() {
    for (name, post) in [("2-D", gauss_2d()), ("5-D", gauss_5d())] {
        let run = sample_tmcmc(&post, &tmcmc_params(2000, 3), None, &no_progress).unwrap();
        assert_eq!(run.x.len(), 2000);
        assert_eq!(run.stages.last().unwrap().beta, 1.0);
        let (m, v) = check_particles(&post, &run.x, 0.12, 0.15);
        let truth = post.log_evidence();
        let err = run.log_evidence - truth;
        eprintln!(
            "TMCMC {name}: {} stages, log Z = {:.4} (analytic {truth:.4}, error {err:+.4}, se {:.4}), max mean err {m:.3} sd, max var err {v:.3}",
            run.stages.len() - 1,
            run.log_evidence,
            run.log_evidence_se
        );
        assert!(
            err.abs() < 0.15,
            "{name}: log Z {} vs {truth}",
            run.log_evidence
        );
        assert!(run.log_evidence_se > 0.0 && run.log_evidence_se < 0.15);
        for s in &run.stages[1..] {
            assert!(s.acceptance > 0.05 && s.acceptance < 0.8, "{s:?}");
            assert!(s.weight_cov <= 1.0 + 1e-6, "{s:?}");
        }
        // Final particles carry their own densities.
        assert_eq!(
            run.log_lik[5],
            post.log_likelihood(&run.x[5], None).unwrap()
        );
        assert_eq!(run.log_prior[5], post.log_prior(&run.x[5], None));
    }
}

#[test]
fn stepping_stone_evidence_matches_the_analytic_value_and_tmcmc() {
    for (name, post) in [("2-D", gauss_2d()), ("5-D", gauss_5d())] {
        let p = SteppingStoneParams {
            seed: 3,
            ..SteppingStoneParams::default()
        };
        let ss = stepping_stone(&post, &p, &no_progress).unwrap();
        let truth = post.log_evidence();
        let err = ss.log_evidence - truth;
        eprintln!(
            "stepping-stone {name}: log Z = {:.4} (analytic {truth:.4}, error {err:+.4}, se {:.4}), {} rungs, {} likelihood evaluations",
            ss.log_evidence,
            ss.log_evidence_se,
            ss.replicas[0].rungs.len(),
            ss.n_loglik
        );
        assert!(
            err.abs() < 0.15,
            "{name}: log Z {} vs {truth}",
            ss.log_evidence
        );
        assert!(ss.log_evidence_se > 0.0 && ss.log_evidence_se < 0.15);
        assert_eq!(ss.replicas.len(), p.replicas);
        // Independent estimators agree within their combined errors (and 0.2 nats).
        let tm = sample_tmcmc(&post, &tmcmc_params(2000, 3), None, &no_progress).unwrap();
        assert!((tm.log_evidence - ss.log_evidence).abs() < 0.2);
    }
}

/// Prior N(0, I) in 5-D; likelihood N(y; x, (1e-3)^2 I): the posterior is 1000 times narrower
/// than the prior in every coordinate (as the FRF posteriors are) and `log Z` is known in closed
/// form. The former stepping-stone (fixed power ladder, no resampling, 50 Metropolis rounds per
/// rung) was 0.55-1.54 nats low here (seeds 0-2, 500 particles).
fn narrow_5d() -> Gauss {
    Gauss::new(
        vec![0.0; 5],
        diag(&[1.0; 5]),
        vec![0.3, -0.8, 1.1, 0.05, -1.6],
        diag(&[1e-6; 5]),
    )
}

#[test]
fn stepping_stone_evidence_of_a_narrow_likelihood_under_a_wide_prior() {
    let post = narrow_5d();
    let truth = post.log_evidence();
    let p = SteppingStoneParams {
        particles: 1000,
        replicas: 8,
        seed: 1,
        ..SteppingStoneParams::default()
    };
    let t = std::time::Instant::now();
    let ss = stepping_stone(&post, &p, &no_progress).unwrap();
    let err = ss.log_evidence - truth;
    let first = &ss.replicas[0];
    let rounds: usize = first.rungs.iter().map(|r| r.steps).sum();
    eprintln!(
        "stepping-stone, 5-D, likelihood 1000x narrower than the prior: log Z = {:.4} (analytic {truth:.4}, error {err:+.4} = {:+.2} se, se {:.4}); replica errors {:?}; {} rungs, {rounds} Metropolis rounds per particle, {} likelihood evaluations ({:.2} s)",
        ss.log_evidence,
        err / ss.log_evidence_se,
        ss.log_evidence_se,
        ss.replicas
            .iter()
            .map(|r| format!("{:+.3}", r.log_evidence - truth))
            .collect::<Vec<_>>(),
        first.rungs.len(),
        ss.n_loglik,
        t.elapsed().as_secs_f64()
    );
    assert!(err.abs() < 0.1, "log Z {} vs {truth}", ss.log_evidence);
    assert!(
        err.abs() < 3.0 * ss.log_evidence_se,
        "error {err} vs se {}",
        ss.log_evidence_se
    );
    assert!(ss.log_evidence_se > 0.0 && ss.log_evidence_se < 0.1);
    for r in &ss.replicas {
        let (last, inner) = r.rungs.split_last().unwrap();
        assert_eq!(last.beta_to, 1.0);
        assert_eq!(last.steps, 0, "no moves are needed at beta = 1");
        assert!(r.rungs.windows(2).all(|w| w[0].beta_to == w[1].beta_from));
        for q in inner {
            // The ladder holds each rung's effective sample size at its target, and the moves
            // stop once the log likelihoods have decorrelated (or at the round limit).
            assert!((q.ess - p.target_ess).abs() < 1e-6, "{q:?}");
            assert!(q.steps >= p.min_steps && q.steps <= p.max_steps, "{q:?}");
            assert!(
                q.correlation < p.decorrelation || q.steps == p.max_steps,
                "{q:?}"
            );
            assert!(q.acceptance > 0.05 && q.acceptance < 0.8, "{q:?}");
        }
    }
}

/// Generalized stepping-stone on the narrow 5-D Gaussian: reference fitted to TMCMC's particles
/// (what the runner does without NUTS), widened 1.5x, Student-t with 5 degrees of freedom.
/// Over 4 seeds: each within 0.05 nats of the closed form and within 3.5 of its own se, and the
/// path from the reference costs a fraction of the path from the prior (same replicas and
/// particles).
#[test]
fn reference_stepping_stone_matches_the_closed_form_with_few_calls() {
    let post = narrow_5d();
    let truth = post.log_evidence();
    let tm = sample_tmcmc(&post, &tmcmc_params(1000, 3), None, &no_progress).unwrap();
    let q = Reference::from_draws(&tm.x, 1.5, 5.0).unwrap();
    // TMCMC's final importance reweighting from the same reference: 4000 independent draws.
    for seed in 1..=4 {
        let is = importance_evidence(&post, &q, 4000, seed).unwrap();
        let err = is.log_evidence - truth;
        eprintln!(
            "importance reweighting seed {seed}: error {err:+.4}, se {:.4}, ESS {:.2}",
            is.log_evidence_se, is.ess
        );
        assert!(
            err.abs() < 0.05 && err.abs() < 3.5 * is.log_evidence_se,
            "{err} {is:?}"
        );
    }
    let one = in_pool(1, || importance_evidence(&post, &q, 500, 5)).unwrap();
    let two = in_pool(2, || importance_evidence(&post, &q, 500, 5)).unwrap();
    assert_eq!(one, two);
    let mut errs = Vec::new();
    for seed in 1..=4 {
        let p = SteppingStoneParams {
            particles: 250,
            replicas: 8,
            seed,
            ..SteppingStoneParams::default()
        };
        let g = reference_stepping_stone(&post, &q, &p, &no_progress).unwrap();
        let err = g.log_evidence - truth;
        eprintln!(
            "reference stepping-stone seed {seed}: log Z {:.4} (closed form {truth:.4}, error {err:+.4}, se {:.4}), rungs {:?}, {} likelihood calls",
            g.log_evidence,
            g.log_evidence_se,
            g.replicas.iter().map(|r| r.rungs.len()).collect::<Vec<_>>(),
            g.n_loglik
        );
        assert!(err.abs() < 0.05, "seed {seed}: error {err}");
        assert!(
            err.abs() < 3.5 * g.log_evidence_se,
            "seed {seed}: error {err} vs se {}",
            g.log_evidence_se
        );
        assert!(g.log_evidence_se > 0.0 && g.log_evidence_se < 0.05);
        errs.push((err, g.n_loglik));
        if seed == 1 {
            let prior_path = stepping_stone(&post, &p, &no_progress).unwrap();
            eprintln!(
                "prior-path stepping-stone, same settings: error {:+.4}, se {:.4}, {} likelihood calls",
                prior_path.log_evidence - truth,
                prior_path.log_evidence_se,
                prior_path.n_loglik
            );
            assert!(g.n_loglik * 3 < prior_path.n_loglik);
        }
    }
    // The replicas' spread says how far the estimate is from the truth: the four errors are
    // not all on one side by more than their se would allow.
    let mean: f64 = errs.iter().map(|e| e.0).sum::<f64>() / errs.len() as f64;
    assert!(mean.abs() < 0.03, "mean error {mean}");
}

#[test]
fn reference_stepping_stone_is_bit_identical_with_one_and_two_threads() {
    let post = gauss_5d();
    let (m, c) = post.posterior();
    let q = Reference::new(&m, &c, 1.5, 5.0).unwrap();
    let p = SteppingStoneParams {
        particles: 100,
        replicas: 2,
        seed: 8,
        ..SteppingStoneParams::default()
    };
    let one = in_pool(1, || reference_stepping_stone(&post, &q, &p, &no_progress)).unwrap();
    let two = in_pool(2, || reference_stepping_stone(&post, &q, &p, &no_progress)).unwrap();
    assert_eq!(one, two);
    assert_eq!(one.log_evidence.to_bits(), two.log_evidence.to_bits());
    let other = reference_stepping_stone(
        &post,
        &q,
        &SteppingStoneParams { seed: 9, ..p },
        &no_progress,
    )
    .unwrap();
    assert_ne!(one.log_evidence, other.log_evidence);
}

/// Prior N(0, 3^2 I); likelihood 0.3 N(x; (-2, 0), 0.5^2 I) + 0.7 N(x; (2, 0), 0.5^2 I). The
/// prior is symmetric, so the posterior masses of the modes are 0.3 and 0.7 and the evidence
/// is `sum_k w_k N(m_k; 0, (9 + 0.25) I)`.
struct Bimodal;

const MODES: [(f64, [f64; 2]); 2] = [(0.3, [-2.0, 0.0]), (0.7, [2.0, 0.0])];

impl Posterior for Bimodal {
    fn dim(&self) -> usize {
        2
    }
    fn names(&self) -> Vec<String> {
        vec!["a".into(), "b".into()]
    }
    fn log_prior(&self, x: &[f64], grad: Option<&mut [f64]>) -> f64 {
        if let Some(g) = grad {
            g[0] = -x[0] / 9.0;
            g[1] = -x[1] / 9.0;
        }
        -0.5 * (x[0] * x[0] + x[1] * x[1]) / 9.0 - (2.0 * std::f64::consts::PI * 9.0).ln()
    }
    fn log_likelihood(&self, x: &[f64], grad: Option<&mut [f64]>) -> Result<f64, DensityError> {
        let s2 = 0.25;
        let comps: Vec<f64> = MODES
            .iter()
            .map(|(w, m)| {
                let q = (x[0] - m[0]).powi(2) + (x[1] - m[1]).powi(2);
                w.ln() - 0.5 * q / s2 - (2.0 * std::f64::consts::PI * s2).ln()
            })
            .collect();
        let mx = comps[0].max(comps[1]);
        let ll = mx + ((comps[0] - mx).exp() + (comps[1] - mx).exp()).ln();
        if let Some(g) = grad {
            g.fill(0.0);
            for ((_, m), c) in MODES.iter().zip(&comps) {
                let r = (c - ll).exp();
                g[0] += r * -(x[0] - m[0]) / s2;
                g[1] += r * -(x[1] - m[1]) / s2;
            }
        }
        Ok(ll)
    }
    fn sample_prior(&self, rng: &mut StdRng) -> Vec<f64> {
        (0..2)
            .map(|_| 3.0 * <StandardNormal as Distribution<f64>>::sample(&StandardNormal, rng))
            .collect()
    }
    fn constrained(&self, x: &[f64]) -> Vec<f64> {
        x.to_vec()
    }
}

#[test]
fn tmcmc_puts_the_right_mass_in_each_mode_of_a_bimodal_posterior() {
    let run = sample_tmcmc(&Bimodal, &tmcmc_params(2000, 21), None, &no_progress).unwrap();
    let left = run.x.iter().filter(|x| x[0] < 0.0).count() as f64 / run.x.len() as f64;
    let v = 9.25;
    let truth = MODES
        .iter()
        .map(|(w, m)| {
            w * (-(m[0] * m[0] + m[1] * m[1]) / (2.0 * v)).exp() / (2.0 * std::f64::consts::PI * v)
        })
        .sum::<f64>()
        .ln();
    eprintln!(
        "TMCMC bimodal: left mass {left:.4} (0.3), log Z {:.4} (analytic {truth:.4})",
        run.log_evidence
    );
    assert!((left - 0.3).abs() < 0.04, "left-mode mass {left}");
    assert!((run.log_evidence - truth).abs() < 0.15);
}

/// `Phi(z)` by Simpson's rule on the density over (-10, z).
fn normal_cdf(z: f64) -> f64 {
    let n = 20_000;
    let (a, h) = (-10.0, (z + 10.0) / n as f64);
    let f = |t: f64| (-0.5 * t * t).exp() / (2.0 * std::f64::consts::PI).sqrt();
    let mut s = f(a) + f(z);
    for i in 1..n {
        s += f(a + i as f64 * h) * if i % 2 == 1 { 4.0 } else { 2.0 };
    }
    s * h / 3.0
}

#[test]
fn a_recoverable_failure_region_is_rejected_without_aborting() {
    // Prior N(0, I), likelihood N((2, 0); x, I): posterior N((1, 0), I / 2), cut where the
    // likelihood fails (x0 > 1.5). The cut posterior of x0 is a truncated normal.
    let mut post = Gauss::new(
        vec![0.0; 2],
        diag(&[1.0, 1.0]),
        vec![2.0, 0.0],
        diag(&[1.0, 1.0]),
    );
    post.fail_above = 1.5;
    let s = 0.5f64.sqrt();
    let alpha = (1.5 - 1.0) / s;
    let phi = (-0.5 * alpha * alpha).exp() / (2.0 * std::f64::consts::PI).sqrt();
    let cdf = normal_cdf(alpha);
    let mean0 = 1.0 - s * phi / cdf;
    let log_z = post.log_evidence() + cdf.ln();

    let st = vec![
        vec![0.0, 0.0],
        vec![-1.0, 0.5],
        vec![0.5, -0.5],
        vec![1.0, 1.0],
    ];
    let run = sample_nuts(&post, &st, &NutsParams::default(), None, &no_progress).unwrap();
    let all: Vec<&Vec<f64>> = run.chains.iter().flat_map(|c| c.x.iter()).collect();
    assert!(all.iter().all(|x| x[0] <= 1.5));
    let (m, _) = mean_var(&all, 0);
    eprintln!(
        "NUTS cut: mean x0 {m:.4} (analytic {mean0:.4}), {} divergent draws",
        run.n_divergent()
    );
    assert!((m - mean0).abs() < 0.05, "NUTS mean x0 {m} vs {mean0}");

    let tm = sample_tmcmc(&post, &tmcmc_params(2000, 8), None, &no_progress).unwrap();
    assert!(tm.x.iter().all(|x| x[0] <= 1.5) && tm.log_lik.iter().all(|l| l.is_finite()));
    let all: Vec<&Vec<f64>> = tm.x.iter().collect();
    let (m, _) = mean_var(&all, 0);
    eprintln!(
        "TMCMC cut: mean x0 {m:.4} (analytic {mean0:.4}), log Z {:.4} (analytic {log_z:.4})",
        tm.log_evidence
    );
    assert!((m - mean0).abs() < 0.05, "TMCMC mean x0 {m} vs {mean0}");
    assert!((tm.log_evidence - log_z).abs() < 0.15);
}

#[test]
fn a_fatal_likelihood_error_stops_tmcmc_with_its_message() {
    struct Broken;
    impl Posterior for Broken {
        fn dim(&self) -> usize {
            1
        }
        fn names(&self) -> Vec<String> {
            vec!["x".into()]
        }
        fn log_prior(&self, x: &[f64], _: Option<&mut [f64]>) -> f64 {
            -0.5 * x[0] * x[0]
        }
        fn log_likelihood(&self, x: &[f64], _: Option<&mut [f64]>) -> Result<f64, DensityError> {
            if x[0] > 2.0 {
                Err(DensityError::Fatal("data file vanished".into()))
            } else {
                Ok(-x[0] * x[0])
            }
        }
        fn sample_prior(&self, rng: &mut StdRng) -> Vec<f64> {
            vec![StandardNormal.sample(rng)]
        }
        fn constrained(&self, x: &[f64]) -> Vec<f64> {
            x.to_vec()
        }
    }
    let e = sample_tmcmc(&Broken, &tmcmc_params(500, 1), None, &no_progress).unwrap_err();
    assert!(
        matches!(&e, SamplerError::Fatal(m) if m == "data file vanished"),
        "{e}"
    );
    assert_eq!(e.to_string(), "fatal density error: data file vanished");
}

// ---------------------------------------------------------------- determinism and resumption

fn in_pool<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> T {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
        .install(f)
}

fn small_nuts(seed: u64) -> NutsParams {
    NutsParams {
        chains: 4,
        tune: 200,
        draws: 150,
        seed,
        ..NutsParams::default()
    }
}

#[test]
fn nuts_and_tmcmc_draws_are_bit_identical_with_one_and_two_threads() {
    let post = gauss_5d();
    let st = starts(&post, 4, 9);
    let one = in_pool(1, || {
        sample_nuts(&post, &st, &small_nuts(4), None, &no_progress)
    })
    .unwrap();
    let two = in_pool(2, || {
        sample_nuts(&post, &st, &small_nuts(4), None, &no_progress)
    })
    .unwrap();
    assert_eq!(one, two);
    // A different seed gives different draws (the comparison can fail).
    let other = sample_nuts(&post, &st, &small_nuts(5), None, &no_progress).unwrap();
    assert_ne!(one.chains[0].x, other.chains[0].x);

    let p = tmcmc_params(400, 6);
    let one = in_pool(1, || sample_tmcmc(&post, &p, None, &no_progress)).unwrap();
    let two = in_pool(2, || sample_tmcmc(&post, &p, None, &no_progress)).unwrap();
    assert_eq!(one, two);
    assert_eq!(one.log_evidence.to_bits(), two.log_evidence.to_bits());
}

#[test]
fn stepping_stone_is_bit_identical_with_one_and_two_threads() {
    let post = gauss_5d();
    let p = SteppingStoneParams {
        particles: 100,
        replicas: 2,
        seed: 8,
        ..SteppingStoneParams::default()
    };
    let events = Mutex::new(Vec::new());
    let record = |e: Progress| {
        if let Progress::SteppingStoneRung {
            replica,
            replicas,
            rung,
            beta,
        } = e
        {
            events.lock().unwrap().push((replica, replicas, rung, beta));
        }
    };
    let one = in_pool(1, || stepping_stone(&post, &p, &record)).unwrap();
    let two = in_pool(2, || stepping_stone(&post, &p, &no_progress)).unwrap();
    assert_eq!(one, two);
    assert_eq!(one.log_evidence.to_bits(), two.log_evidence.to_bits());
    // One progress event per rung, in order, ending at beta = 1 in each replica.
    let ev = events.into_inner().unwrap();
    let rungs: Vec<_> = one
        .replicas
        .iter()
        .enumerate()
        .flat_map(|(r, rep)| {
            rep.rungs
                .iter()
                .enumerate()
                .map(move |(k, q)| (r, 2, k + 1, q.beta_to))
        })
        .collect();
    assert_eq!(ev, rungs);
    // A different seed gives a different estimate (the comparison can fail).
    let other = stepping_stone(&post, &SteppingStoneParams { seed: 9, ..p }, &no_progress).unwrap();
    assert_ne!(one.log_evidence, other.log_evidence);
}

#[test]
fn nuts_resumes_from_finished_chains_bit_identically_and_ignores_stale_checkpoints() {
    let post = gauss_2d();
    let st = starts(&post, 4, 2);
    let p = small_nuts(7);
    let reference = sample_nuts(&post, &st, &p, None, &no_progress).unwrap();

    let dir = tempfile::tempdir().unwrap();
    let first = sample_nuts(&post, &st, &p, Some(dir.path()), &no_progress).unwrap();
    assert_eq!(first.chains, reference.chains);
    assert!(first.loaded_chains.is_empty());
    let mut files: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    files.sort();
    assert_eq!(files.len(), 4, "one file per chain: {files:?}");

    // Interrupted: chains 1 and 3 never finished.
    std::fs::remove_file(&files[1]).unwrap();
    std::fs::remove_file(&files[3]).unwrap();
    let events = Mutex::new(Vec::new());
    let record = |e: Progress| {
        if let Progress::NutsChainLoaded { chain } = e {
            events.lock().unwrap().push(chain);
        }
    };
    let resumed = sample_nuts(&post, &st, &p, Some(dir.path()), &record).unwrap();
    assert_eq!(resumed.loaded_chains, vec![0, 2]);
    let mut loaded = events.into_inner().unwrap();
    loaded.sort();
    assert_eq!(loaded, vec![0, 2]);
    assert_eq!(resumed.chains, reference.chains);

    // Other settings (another seed) must not pick up these chains.
    let stale = sample_nuts(&post, &st, &small_nuts(8), Some(dir.path()), &no_progress).unwrap();
    assert!(stale.loaded_chains.is_empty());
    assert_ne!(stale.chains[0].x, reference.chains[0].x);
}

#[test]
fn tmcmc_resumes_after_the_last_saved_stage_bit_identically() {
    let post = gauss_5d();
    let p = tmcmc_params(400, 12);
    let reference = sample_tmcmc(&post, &p, None, &no_progress).unwrap();
    assert!(reference.stages.len() > 4, "need stages to interrupt");

    let dir = tempfile::tempdir().unwrap();
    let interrupted = TmcmcParams {
        stop_after_stages: Some(2),
        ..p.clone()
    };
    let e = sample_tmcmc(&post, &interrupted, Some(dir.path()), &no_progress).unwrap_err();
    assert!(matches!(e, SamplerError::Stopped { stage: 2 }), "{e}");

    let resumed = sample_tmcmc(&post, &p, Some(dir.path()), &no_progress).unwrap();
    assert_eq!(resumed.resumed_after, Some(2));
    assert_eq!(resumed.x, reference.x);
    assert_eq!(resumed.log_lik, reference.log_lik);
    assert_eq!(resumed.stages, reference.stages);
    assert_eq!(
        resumed.log_evidence.to_bits(),
        reference.log_evidence.to_bits()
    );

    // A finished run's checkpoint resumes to the same result without any new stage.
    let again = sample_tmcmc(&post, &p, Some(dir.path()), &no_progress).unwrap();
    assert_eq!(again.resumed_after, Some(reference.stages.len() - 1));
    assert_eq!(again.x, reference.x);

    // Other settings ignore the file.
    let other = TmcmcParams {
        steps_per_stage: 5,
        ..p
    };
    let fresh = sample_tmcmc(&post, &other, Some(dir.path()), &no_progress).unwrap();
    assert_eq!(fresh.resumed_after, None);
}
