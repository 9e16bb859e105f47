//! The maximum a posteriori point by a multistart search, and the Laplace approximation there.
//!
//! 1. Starts: the caller's initial point (the study's initial values) plus `n_starts`
//!    space-filling points over the prior (a Latin hypercube in prior quantiles, mapped to
//!    unconstrained coordinates).
//! 2. From each start, L-BFGS (argmin's `LBFGS` with a More-Thuente line search) on
//!    `-log p(x | data)` in unconstrained coordinates, with the analytic gradient.
//! 3. The best end point is polished by Newton steps on a central-difference Hessian of the
//!    analytic gradient (backtracking on the objective) until the gradient's Newton decrement
//!    is below `polish_tol`.
//! 4. Laplace (Tierney & Kadane 1986): with `A` the Hessian of `-log p` at the MAP `x*`,
//!    `log Z ~ log L(x*) + log pi(x*) + (d/2) ln 2 pi - (1/2) ln det A`, covariance `A^-1`
//!    in unconstrained coordinates and `D A^-1 D` (D = diag dp/dx) for the physical
//!    parameters (delta method).
//!
//! Every start's end point, objective, iteration count and stop reason are kept: the raw
//! material of the initial-value sensitivity study. Starts run in parallel (rayon); results
//! are collected in start order, so they do not depend on the thread count.

use super::lm::Quadratic;
use super::{unit_rng, DensityError, Posterior};
use crate::linalg::dense::{chol_inverse, cholesky};
use argmin::core::{CostFunction, Executor, Gradient, State};
use argmin::solver::linesearch::MoreThuenteLineSearch;
use argmin::solver::quasinewton::LBFGS;
use rand::RngExt;
use rayon::prelude::*;

/// Settings of the multistart search.
#[derive(Clone, Debug, PartialEq)]
pub struct MapParams {
    /// Space-filling starts besides the caller's. Default 16.
    pub n_starts: usize,
    /// L-BFGS iterations per start. Default 200.
    pub max_iters: u64,
    /// L-BFGS memory. Default 7.
    pub memory: usize,
    /// Gradient-norm tolerance of L-BFGS. Default 1e-6.
    pub tol_grad: f64,
    /// Newton decrement (`g^T A^-1 g / 2`) below which polishing stops. Default 1e-10.
    pub polish_tol: f64,
    /// Seed of the space-filling design.
    pub seed: u64,
    /// How each start searches. Default L-BFGS.
    pub search: SearchMethod,
    /// A Gauss-Newton search gives up when its objective `-log p` (physical) stays this far
    /// above the value to beat ([`super::lm::LmParams::give_up_above`]); its end point is then
    /// not polished. Default `INFINITY` (never).
    pub give_up_above: f64,
}

/// The local search of each start.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum SearchMethod {
    /// L-BFGS on the analytic gradient: needs nothing but the gradient.
    #[default]
    Lbfgs,
    /// Levenberg-Marquardt on the posterior's Gauss-Newton curvature
    /// ([`Posterior::curvature`]): a few evaluations where L-BFGS needs hundreds on a
    /// narrow, correlated least-squares valley. L-BFGS where the posterior has no curvature.
    GaussNewton,
}

impl Default for MapParams {
    fn default() -> Self {
        MapParams {
            n_starts: 16,
            max_iters: 200,
            memory: 7,
            tol_grad: 1e-6,
            polish_tol: 1e-10,
            seed: 0,
            search: SearchMethod::Lbfgs,
            give_up_above: f64::INFINITY,
        }
    }
}

/// One start of the search.
#[derive(Clone, Debug, PartialEq)]
pub struct StartResult {
    pub index: usize,
    /// "initial" for the caller's start, "design" for space-filling ones.
    pub kind: &'static str,
    pub start_x: Vec<f64>,
    pub end_x: Vec<f64>,
    /// `-log p(x | data)` up to `log Z` at the end point (infinite when it failed).
    pub objective: f64,
    pub iterations: u64,
    /// Why the search stopped, in words (the tables' `stop_reason`).
    pub stop_reason: String,
    /// The Gauss-Newton search's stop ([`super::lm::LmStop`]); None for an L-BFGS search.
    pub lm_stop: Option<super::lm::LmStop>,
}

impl StartResult {
    /// Whether its search gave up above [`MapParams::give_up_above`]
    /// ([`super::lm::LmStop::GivenUp`]).
    pub fn gave_up(&self) -> bool {
        matches!(self.lm_stop, Some(super::lm::LmStop::GivenUp { .. }))
    }
}

/// The Laplace approximation at the mode of the density in unconstrained coordinates.
#[derive(Clone, Debug, PartialEq)]
pub struct Laplace {
    pub x: Vec<f64>,
    /// Physical values at the MAP.
    pub physical: Vec<f64>,
    pub log_likelihood: f64,
    pub log_prior: f64,
    /// Covariance in unconstrained coordinates, row-major d x d.
    pub cov_x: Vec<f64>,
    /// Covariance of the physical values (delta method), row-major d x d.
    pub cov_physical: Vec<f64>,
    pub log_evidence: f64,
    /// Whether the Hessian was positive definite (else the covariance is not usable).
    pub positive_definite: bool,
}

impl Laplace {
    pub fn dim(&self) -> usize {
        self.x.len()
    }
    /// Log likelihood plus log prior at the MAP (the search's `-objective`).
    pub fn log_posterior(&self) -> f64 {
        self.log_likelihood + self.log_prior
    }
    /// Physical standard deviations.
    pub fn sd_physical(&self) -> Vec<f64> {
        let d = self.dim();
        (0..d)
            .map(|i| self.cov_physical[i * d + i].max(0.0).sqrt())
            .collect()
    }
}

/// What the search found.
#[derive(Clone, Debug)]
pub struct MapResult {
    pub starts: Vec<StartResult>,
    /// Index into `starts` of the best end point (before polishing).
    pub best: usize,
    /// The MAP (mode of the posterior density of the physical parameters), unconstrained.
    pub map_x: Vec<f64>,
    /// The MAP's physical values.
    pub map_physical: Vec<f64>,
    pub laplace: Laplace,
    /// Newton polishing steps taken.
    pub polish_steps: usize,
    /// Density evaluations (with gradient) spent.
    pub evaluations: usize,
}

impl MapResult {
    /// Whether the best start's search gave up ([`StartResult::gave_up`]).
    pub fn gave_up(&self) -> bool {
        self.starts[self.best].gave_up()
    }
}

/// Errors of the search.
#[derive(Debug, Clone, thiserror::Error)]
pub enum MapError {
    #[error("no start reached a finite posterior density; first failure: {0}")]
    NoFiniteStart(String),
    #[error(transparent)]
    Density(#[from] DensityError),
}

/// `-log p(x | data)` (physical-space MAP objective) divided by `scale`: the log posterior of
/// a few thousand FRF values spans many decades between the prior box and the optimum, and
/// L-BFGS's first step is the raw gradient, so the search works on `f / |f(x_0)|`.
struct Objective<'a> {
    post: &'a dyn Posterior,
    count: &'a std::sync::atomic::AtomicUsize,
    scale: f64,
}

/// `log p(x | data)` without (`physical`) or with the transform's log-Jacobian, and its gradient.
fn objective(
    post: &dyn Posterior,
    x: &[f64],
    grad: Option<&mut [f64]>,
    physical: bool,
) -> Result<f64, DensityError> {
    match grad {
        None => {
            let v = post.log_posterior(x, None)?;
            Ok(if physical {
                v - post.log_jacobian(x, None)
            } else {
                v
            })
        }
        Some(g) => {
            let v = post.log_posterior(x, Some(g))?;
            if !physical {
                return Ok(v);
            }
            let mut gj = vec![0.0; x.len()];
            let j = post.log_jacobian(x, Some(&mut gj));
            g.iter_mut().zip(&gj).for_each(|(a, b)| *a -= b);
            Ok(v - j)
        }
    }
}

impl Objective<'_> {
    fn value_grad(&self, x: &[f64]) -> Result<(f64, Vec<f64>), DensityError> {
        self.count
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let mut g = vec![0.0; x.len()];
        let v = objective(self.post, x, Some(&mut g), true)?;
        g.iter_mut().for_each(|v| *v = -*v / self.scale);
        Ok((-v / self.scale, g))
    }
}

impl CostFunction for Objective<'_> {
    type Param = Vec<f64>;
    type Output = f64;
    fn cost(&self, x: &Self::Param) -> Result<f64, argmin::core::Error> {
        self.count
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        match objective(self.post, x, None, true) {
            Ok(v) if v.is_finite() => Ok(-v / self.scale),
            // A huge finite cost makes the line search back off (argmin stops on NaN/inf).
            Ok(_) | Err(DensityError::Recoverable(_)) => Ok(1e300),
            Err(e) => Err(argmin::core::Error::msg(e.to_string())),
        }
    }
}

impl Gradient for Objective<'_> {
    type Param = Vec<f64>;
    type Gradient = Vec<f64>;
    fn gradient(&self, x: &Self::Param) -> Result<Vec<f64>, argmin::core::Error> {
        match self.value_grad(x) {
            Ok((_, g)) if g.iter().all(|v| v.is_finite()) => Ok(g),
            Ok(_) | Err(DensityError::Recoverable(_)) => Ok(vec![0.0; x.len()]),
            Err(e) => Err(argmin::core::Error::msg(e.to_string())),
        }
    }
}

/// A Latin hypercube of `n` points in `(0, 1)^d` (one RNG, so it is reproducible).
pub fn latin_hypercube(n: usize, d: usize, seed: u64) -> Vec<Vec<f64>> {
    let mut rng = unit_rng(seed, 0x4C48_5300);
    let mut pts = vec![vec![0.0; d]; n];
    for j in 0..d {
        let mut perm: Vec<usize> = (0..n).collect();
        for i in (1..n).rev() {
            let k = rng.random_range(0..=i);
            perm.swap(i, k);
        }
        for i in 0..n {
            let u: f64 = rng.random::<f64>();
            pts[i][j] = (perm[i] as f64 + u) / n as f64;
        }
    }
    pts
}

/// Run one L-BFGS search from `x0`.
fn search(
    post: &dyn Posterior,
    x0: &[f64],
    p: &MapParams,
    count: &std::sync::atomic::AtomicUsize,
) -> (Vec<f64>, f64, u64, String) {
    let f0 = objective(post, x0, None, true).unwrap_or(f64::NAN);
    if !f0.is_finite() {
        return (
            x0.to_vec(),
            f64::INFINITY,
            0,
            "failed: the posterior density is not finite at the start".into(),
        );
    }
    let scale = f0.abs().max(1.0);
    let obj = Objective { post, count, scale };
    let ls = MoreThuenteLineSearch::new();
    let solver = match LBFGS::new(ls, p.memory).with_tolerance_grad(p.tol_grad) {
        Ok(s) => s,
        Err(e) => return (x0.to_vec(), f64::INFINITY, 0, format!("failed: {e}")),
    };
    let solver = match solver.with_tolerance_cost(1e-12) {
        Ok(s) => s,
        Err(e) => return (x0.to_vec(), f64::INFINITY, 0, format!("failed: {e}")),
    };
    let res = Executor::new(obj, solver)
        .configure(|s| s.param(x0.to_vec()).max_iters(p.max_iters))
        .run();
    match res {
        Ok(r) => {
            let st = r.state();
            let x = st.get_best_param().cloned().unwrap_or_else(|| x0.to_vec());
            let reason = st
                .get_termination_reason()
                .map(|t| t.text().to_string())
                .unwrap_or_else(|| "unknown".into());
            (x, st.get_best_cost() * scale, st.get_iter(), reason)
        }
        Err(e) => (x0.to_vec(), f64::INFINITY, 0, format!("failed: {e}")),
    }
}

/// `-log p(x | data)` (plus the transform's log-Jacobian when `physical`: the physical-MAP
/// objective), its gradient and Gauss-Newton curvature; the log-Jacobian's Hessian by central
/// differences of its gradient (the transform only, no likelihood). None when the posterior
/// has no curvature.
fn gn_objective(
    post: &dyn Posterior,
    x: &[f64],
    physical: bool,
) -> Option<Result<Quadratic, DensityError>> {
    let c = match post.curvature(x)? {
        Ok(c) => c,
        Err(e) => return Some(Err(e)),
    };
    let d = x.len();
    let mut f = -c.value;
    let mut g: Vec<f64> = c.grad.iter().map(|v| -v).collect();
    let mut h = c.hess;
    if physical {
        let mut gj = vec![0.0; d];
        f += post.log_jacobian(x, Some(&mut gj));
        g.iter_mut().zip(&gj).for_each(|(a, b)| *a += b);
        let mut xp = x.to_vec();
        let (mut gp, mut gm) = (vec![0.0; d], vec![0.0; d]);
        for k in 0..d {
            let e = 1e-5 * (1.0 + x[k].abs());
            xp[k] = x[k] + e;
            post.log_jacobian(&xp, Some(&mut gp));
            xp[k] = x[k] - e;
            post.log_jacobian(&xp, Some(&mut gm));
            xp[k] = x[k];
            for i in 0..d {
                h[i * d + k] += 0.5 * (gp[i] - gm[i]) / (2.0 * e);
                h[k * d + i] += 0.5 * (gp[i] - gm[i]) / (2.0 * e);
            }
        }
    }
    if !(f.is_finite() && g.iter().chain(&h).all(|v| v.is_finite())) {
        return Some(Err(DensityError::Recoverable(format!(
            "objective {f} or its curvature is not finite"
        ))));
    }
    Some(Ok((f, g, h)))
}

/// Levenberg-Marquardt ([`super::lm`]) from `x0` on the MAP objective (see [`gn_objective`]).
/// Stops when the Newton decrement `g^T H^-1 g / 2` (undamped curvature) is below `tol`, after
/// `max_iters` iterations, or when no damped step decreases the objective. Returns (x,
/// objective, iterations, stop reason), or None when the posterior has no curvature.
#[allow(clippy::too_many_arguments)]
fn gauss_newton_search(
    post: &dyn Posterior,
    x0: &[f64],
    max_iters: u64,
    tol: f64,
    give_up_above: f64,
    physical: bool,
    count: &std::sync::atomic::AtomicUsize,
) -> Option<(Vec<f64>, f64, u64, super::lm::LmStop)> {
    use std::sync::atomic::Ordering::Relaxed;
    count.fetch_add(1, Relaxed);
    let mut first = match gn_objective(post, x0, physical)? {
        Ok(q) => Some(q),
        Err(e) => {
            return Some((
                x0.to_vec(),
                f64::INFINITY,
                0,
                super::lm::LmStop::Failed(format!(
                    "the posterior density is not finite at the start ({e})"
                )),
            ))
        }
    };
    let quadratic = |x: &[f64]| -> Result<Quadratic, DensityError> {
        if let Some(q) = first.take() {
            return Ok(q);
        }
        count.fetch_add(1, Relaxed);
        gn_objective(post, x, physical)
            .unwrap_or_else(|| Err(DensityError::Fatal("the posterior has no curvature".into())))
    };
    let value = |x: &[f64]| {
        count.fetch_add(1, Relaxed);
        objective(post, x, None, physical).map_or(f64::INFINITY, |v| -v)
    };
    let out = super::lm::levenberg_marquardt(
        x0,
        quadratic,
        value,
        &super::lm::LmParams {
            max_iters,
            tol,
            rel_tol: 0.0,
            give_up_above,
        },
    );
    Some((out.x, out.f, out.iterations, out.stop))
}

/// Central-difference Hessian of `-log p(x | data)` (in x, Jacobian included) from the
/// analytic gradient (symmetrised).
pub fn hessian(post: &dyn Posterior, x: &[f64]) -> Result<Vec<f64>, DensityError> {
    hessian_of(post, x, false)
}

fn hessian_of(post: &dyn Posterior, x: &[f64], physical: bool) -> Result<Vec<f64>, DensityError> {
    let steps: Vec<f64> = x.iter().map(|v| 1e-5 * (1.0 + v.abs())).collect();
    hessian_steps(post, x, physical, &steps)
}

/// [`hessian`] with the Hessian's curvature scales used as difference steps: a first pass
/// with steps `1e-5 (1 + |x|)`, then steps of `1e-3` posterior sd per coordinate. A posterior
/// narrower than the first step (thousands of FRF values under a misspecified law) would
/// otherwise be differenced across its own width. The first pass only sets the steps, so a
/// posterior with a Gauss-Newton curvature ([`Posterior::curvature`]) gives it from that one
/// call instead of `2 d` gradients.
pub fn hessian_scaled(post: &dyn Posterior, x: &[f64]) -> Result<Vec<f64>, DensityError> {
    let d = x.len();
    let gauss_newton = match post.curvature(x) {
        Some(Ok(c)) => cholesky(&c.hess, d),
        _ => None,
    };
    let l = match gauss_newton {
        Some(l) => l,
        None => {
            let h = hessian_of(post, x, false)?;
            let Some(l) = cholesky(&h, d) else {
                return Ok(h);
            };
            l
        }
    };
    let cov = chol_inverse(&l, d);
    let steps: Vec<f64> = (0..d)
        .map(|i| {
            let sd = cov[i * d + i].sqrt();
            if sd.is_finite() && sd > 0.0 {
                (1e-3 * sd).min(1e-5 * (1.0 + x[i].abs()))
            } else {
                1e-5 * (1.0 + x[i].abs())
            }
        })
        .collect();
    hessian_steps(post, x, false, &steps)
}

fn hessian_steps(
    post: &dyn Posterior,
    x: &[f64],
    physical: bool,
    steps: &[f64],
) -> Result<Vec<f64>, DensityError> {
    let d = x.len();
    let mut h = vec![0.0; d * d];
    let mut xp = x.to_vec();
    let mut gp = vec![0.0; d];
    let mut gm = vec![0.0; d];
    for j in 0..d {
        let e = steps[j];
        xp[j] = x[j] + e;
        objective(post, &xp, Some(&mut gp), physical)?;
        xp[j] = x[j] - e;
        objective(post, &xp, Some(&mut gm), physical)?;
        xp[j] = x[j];
        for i in 0..d {
            h[i * d + j] = -(gp[i] - gm[i]) / (2.0 * e);
        }
    }
    for i in 0..d {
        for j in 0..i {
            let s = 0.5 * (h[i * d + j] + h[j * d + i]);
            h[i * d + j] = s;
            h[j * d + i] = s;
        }
    }
    Ok(h)
}

/// Laplace approximation at `x` (assumed the MAP).
pub fn laplace_at(post: &dyn Posterior, x: &[f64]) -> Result<Laplace, DensityError> {
    let d = x.len();
    let a = hessian_scaled(post, x)?;
    let lp = post.log_prior(x, None);
    let ll = post.log_likelihood(x, None)?;
    let (cov_x, logdet, pd) = match cholesky(&a, d) {
        Some(l) => {
            let logdet: f64 = (0..d).map(|i| 2.0 * l[i * d + i].ln()).sum();
            (chol_inverse(&l, d), logdet, true)
        }
        None => (vec![f64::NAN; d * d], f64::NAN, false),
    };
    // Jacobian of the physical values by central differences of the transform.
    let phys = post.constrained(x);
    let mut dp = vec![0.0; d];
    let mut xp = x.to_vec();
    for i in 0..d {
        let e = 1e-6 * (1.0 + x[i].abs());
        xp[i] = x[i] + e;
        let a1 = post.constrained(&xp)[i];
        xp[i] = x[i] - e;
        let a0 = post.constrained(&xp)[i];
        xp[i] = x[i];
        dp[i] = (a1 - a0) / (2.0 * e);
    }
    let cov_physical = (0..d * d)
        .map(|k| cov_x[k] * dp[k / d] * dp[k % d])
        .collect();
    Ok(Laplace {
        x: x.to_vec(),
        physical: phys,
        log_likelihood: ll,
        log_prior: lp,
        cov_x,
        cov_physical,
        log_evidence: ll + lp + 0.5 * d as f64 * std::f64::consts::TAU.ln() - 0.5 * logdet,
        positive_definite: pd,
    })
}

/// Newton polishing from `x` of the physical-space MAP objective (`physical`) or of the
/// density in x (returns the polished point and the iterations taken): the crate's
/// Levenberg-Marquardt ([`super::lm`]) with the finite-difference Hessian as its curvature, at
/// most [`POLISH_ITERATIONS`] iterations, until the Newton decrement is below `tol`. Where the
/// Hessian is not positive definite (a saddle, a flat ridge) the search stops there: at the
/// start the point is returned as it was.
fn polish(
    post: &dyn Posterior,
    x: &[f64],
    tol: f64,
    physical: bool,
) -> Result<(Vec<f64>, usize), DensityError> {
    let d = x.len();
    // The objective -log p, its gradient (g holds that of log p) and its Hessian at `x`.
    let at = |x: &[f64]| -> Result<Quadratic, DensityError> {
        let mut g = vec![0.0; d];
        let v = objective(post, x, Some(&mut g), physical)?;
        let h = hessian_of(post, x, physical)?;
        Ok((-v, g.iter().map(|a| -a).collect(), h))
    };
    // The start's: their errors are the caller's.
    let start = at(x)?;
    if cholesky(&start.2, d).is_none() {
        return Ok((x.to_vec(), 0));
    }
    let mut first = Some(start);
    let quadratic = |x: &[f64]| -> Result<Quadratic, String> {
        if let Some(q) = first.take() {
            return Ok(q);
        }
        let q = at(x).map_err(|e| e.to_string())?;
        if !q.0.is_finite() || cholesky(&q.2, d).is_none() {
            return Err("the Hessian is not positive definite".to_string());
        }
        Ok(q)
    };
    let value = |x: &[f64]| {
        objective(post, x, None, physical)
            .ok()
            .filter(|v| v.is_finite())
            .map_or(f64::INFINITY, |v| -v)
    };
    let out = super::lm::levenberg_marquardt(
        x,
        quadratic,
        value,
        &super::lm::LmParams {
            max_iters: POLISH_ITERATIONS,
            tol,
            rel_tol: 0.0,
            give_up_above: f64::INFINITY,
        },
    );
    Ok((out.x, out.iterations as usize))
}

/// Iterations of [`polish`] at most.
pub const POLISH_ITERATIONS: u64 = 20;

/// Newton-polish an end point of a local search to the stationary point of its basin (the
/// physical-MAP objective, as the search uses): L-BFGS stops on a gradient tolerance, which
/// leaves end points of one basin scattered by a fraction of a posterior sd; after polishing
/// they coincide to the Newton decrement `tol`. Returns the point and its `-log p` (up to
/// `log Z`). Where the Hessian is not positive definite (a saddle, a flat ridge) the point is
/// returned as it was.
pub fn polish_end_point(
    post: &dyn Posterior,
    x: &[f64],
    tol: f64,
) -> Result<(Vec<f64>, f64), DensityError> {
    let (x, _) = polish(post, x, tol, true)?;
    let f = -objective(post, &x, None, true)?;
    Ok((x, f))
}

/// The multistart search: `initial` (unconstrained, e.g. the study's initial values) plus a
/// Latin hypercube over the prior.
pub fn find_map(
    post: &dyn Posterior,
    initial: Option<&[f64]>,
    params: &MapParams,
    progress: &(dyn Fn() + Sync),
) -> Result<MapResult, MapError> {
    let d = post.dim();
    let mut starts: Vec<(&'static str, Vec<f64>)> = Vec::new();
    if let Some(x) = initial {
        starts.push(("initial", x.to_vec()));
    }
    // Design points: prior quantiles through a probe draw of each coordinate's quantile map.
    let design = latin_hypercube(params.n_starts, d, params.seed);
    for u in design {
        starts.push(("design", quantiles_to_x(post, &u)));
    }
    let count = std::sync::atomic::AtomicUsize::new(0);
    let results: Vec<StartResult> = starts
        .par_iter()
        .enumerate()
        .map(|(i, (kind, x0))| {
            let gn = match params.search {
                SearchMethod::GaussNewton => gauss_newton_search(
                    post,
                    x0,
                    params.max_iters,
                    params.polish_tol,
                    params.give_up_above,
                    true,
                    &count,
                ),
                SearchMethod::Lbfgs => None,
            };
            let (end_x, objective, iterations, stop_reason, lm_stop) = match gn {
                Some((x, f, it, stop)) => (x, f, it, stop.to_string(), Some(stop)),
                None => {
                    let (x, f, it, reason) = search(post, x0, params, &count);
                    (x, f, it, reason, None)
                }
            };
            progress();
            StartResult {
                index: i,
                kind,
                start_x: x0.clone(),
                end_x,
                objective: if objective >= 1e300 {
                    f64::INFINITY
                } else {
                    objective
                },
                iterations,
                stop_reason,
                lm_stop,
            }
        })
        .collect();
    let best = results
        .iter()
        .enumerate()
        .filter(|(_, r)| r.objective.is_finite())
        .min_by(|a, b| a.1.objective.total_cmp(&b.1.objective))
        .map(|(i, _)| i)
        .ok_or_else(|| {
            MapError::NoFiniteStart(
                results
                    .first()
                    .map(|r| r.stop_reason.clone())
                    .unwrap_or_default(),
            )
        })?;
    // A Gauss-Newton search that converged ends where the polish would (its stop is the
    // polish's Newton decrement), so only an L-BFGS end point is polished.
    let gn_converged = results[best].lm_stop == Some(super::lm::LmStop::Converged);
    // A search that gave up is not polished: its end point is only where it stopped.
    let given_up = results[best].gave_up();
    let (x, polish_steps) = if gn_converged || given_up {
        (results[best].end_x.clone(), 0)
    } else {
        polish(post, &results[best].end_x, params.polish_tol, true)?
    };
    // Laplace at the mode of the density in x (where it is closest to Gaussian); it is next
    // to the physical MAP, differing only by the transform's Jacobian.
    let gn_x = if gn_converged {
        gauss_newton_search(
            post,
            &x,
            params.max_iters,
            params.polish_tol,
            f64::INFINITY,
            false,
            &count,
        )
        .filter(|r| r.3 == super::lm::LmStop::Converged)
    } else {
        None
    };
    let xl = match gn_x {
        Some(r) => r.0,
        None if given_up => x.clone(),
        None => polish(post, &x, params.polish_tol, false)?.0,
    };
    let laplace = laplace_at(post, &xl)?;
    Ok(MapResult {
        starts: results,
        best,
        map_x: x.clone(),
        map_physical: post.constrained(&x),
        laplace,
        polish_steps,
        evaluations: count.load(std::sync::atomic::Ordering::Relaxed),
    })
}

/// Map prior quantiles `u` (one per coordinate) to unconstrained coordinates. Uses the
/// posterior's own prior draws is not possible through the trait, so this inverts
/// `sample_prior` by a quantile function when the posterior offers one.
fn quantiles_to_x(post: &dyn Posterior, u: &[f64]) -> Vec<f64> {
    post.prior_quantile(u)
}
