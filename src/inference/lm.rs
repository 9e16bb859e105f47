//! Levenberg-Marquardt on an objective with a Gauss-Newton curvature: the one damped
//! Newton loop of the crate (the MAP's polish and Gauss-Newton search, the closed loop's
//! refits, its alternative laws' fits to a modulus curve and their profiles on the data, the
//! circle fit). The profile race of a candidate effect's start
//! ([`crate::closed_loop::start`]) takes single Gauss-Newton steps of many points in turn,
//! not a search to a stop.
//!
//! At `x` with value `f`, gradient `g` and curvature `H` (positive semi-definite), the step
//! `s = -(H + lambda D)^-1 g`, `D = diag(max(|H_ii|, 1e-12 max_j |H_jj|))`, is taken when the
//! objective falls and the gain ratio `rho = (f(x) - f(x + s)) / (-(g^T s + s^T (H + lambda D)
//! s / 2))` exceeds 1e-4; then `lambda *= max(1/3, 1 - (2 rho - 1)^3)`, else `lambda *= nu`,
//! `nu *= 2` (Nielsen's update: Madsen, Nielsen & Tingleff 2004, *Methods for non-linear least
//! squares problems*, sec. 3.2). It stops when the Newton decrement `g^T H^-1 g / 2` (undamped)
//! falls below the tolerance, after the iteration limit, or when `lambda` exceeds 1e16 (no
//! damped step decreases the objective).
//!
//! Tests: tests/suite/inference_samplers.rs (the MAP), tests/suite/closed_loop_alt.rs (the law
//! fits), and the unit tests below (a Rosenbrock valley and a linear least-squares problem).

use crate::linalg::dense::{chol_solve, cholesky};

/// An objective's value, gradient and curvature (row-major) at a point.
pub type Quadratic = (f64, Vec<f64>, Vec<f64>);

/// Stopping rules.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LmParams {
    /// Iteration limit.
    pub max_iters: u64,
    /// Absolute tolerance on the Newton decrement `g^T H^-1 g / 2`.
    pub tol: f64,
    /// Relative tolerance: stop also when the decrement is below `rel_tol |f|`. Default 0.
    pub rel_tol: f64,
    /// Give up ([`LmStop::GivenUp`]) when, after [`GIVE_UP_AFTER`] iterations, the
    /// objective is still above this by more than [`GIVE_UP_RATIO`] Newton decrements: the
    /// search cannot reach it at the pace its quadratic model predicts. For a candidate that
    /// must beat a known fit (an alternative law refitted against the current one); `INFINITY`
    /// never gives up.
    pub give_up_above: f64,
}

/// Iterations before [`LmParams::give_up_above`] is checked.
pub const GIVE_UP_AFTER: u64 = 3;
/// Newton decrements the objective may be above [`LmParams::give_up_above`] before the
/// search gives up.
pub const GIVE_UP_RATIO: f64 = 100.0;

/// Why a search stopped. Its `Display` is the reason in words, as the tables and reports
/// give it ("converged: ...", "given up: ...", "stalled: ...", "failed: ...", "maximum
/// iterations reached").
#[derive(Clone, Debug, PartialEq)]
pub enum LmStop {
    /// The Newton decrement fell below the tolerance.
    Converged,
    /// The iteration limit was reached.
    MaxIterations,
    /// The objective stayed `above` the value to beat ([`LmParams::give_up_above`]) by more
    /// than [`GIVE_UP_RATIO`] times the decrease `predicted` by the quadratic model.
    GivenUp { above: f64, predicted: f64 },
    /// No damped step decreases the objective.
    Stalled,
    /// The objective or its curvature is not finite at the start or at an accepted point.
    Failed(String),
}

impl std::fmt::Display for LmStop {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            LmStop::Converged => write!(f, "converged: Newton decrement below tolerance"),
            LmStop::MaxIterations => write!(f, "maximum iterations reached"),
            LmStop::GivenUp { above, predicted } => write!(
                f,
                "given up: {above:.4e} above the objective to beat, with {predicted:.3e} predicted by the quadratic model"
            ),
            LmStop::Stalled => write!(f, "stalled: no damped step decreases the objective"),
            LmStop::Failed(why) => write!(f, "failed: {why}"),
        }
    }
}

/// Where the search ended.
#[derive(Clone, Debug, PartialEq)]
pub struct LmOutcome {
    pub x: Vec<f64>,
    pub f: f64,
    pub iterations: u64,
    /// Why it stopped.
    pub stop: LmStop,
}

/// Levenberg-Marquardt from `x0` (see the module doc). `quadratic(x)` gives the value,
/// gradient and curvature (`Err` with a reason where they are not finite); `value(x)` the value
/// alone (`INFINITY` where it is not finite). A start without a finite quadratic model ends at
/// once with [`LmStop::Failed`].
pub fn levenberg_marquardt<Q, V, E>(
    x0: &[f64],
    mut quadratic: Q,
    mut value: V,
    params: &LmParams,
) -> LmOutcome
where
    Q: FnMut(&[f64]) -> Result<Quadratic, E>,
    V: FnMut(&[f64]) -> f64,
    E: std::fmt::Display,
{
    let d = x0.len();
    let (mut f, mut g, mut h) = match quadratic(x0) {
        Ok(v) => v,
        Err(e) => {
            return LmOutcome {
                x: x0.to_vec(),
                f: f64::INFINITY,
                iterations: 0,
                stop: LmStop::Failed(format!("the objective is not finite at the start ({e})")),
            }
        }
    };
    let mut x = x0.to_vec();
    let mut lambda = 1e-3;
    let mut nu = 2.0;
    let mut stop = LmStop::MaxIterations;
    let mut it = 0;
    while it < params.max_iters {
        if let Some(l) = cholesky(&h, d) {
            let s = chol_solve(&l, d, &g);
            let dec = 0.5 * s.iter().zip(&g).map(|(a, b)| a * b).sum::<f64>();
            if dec < params.tol || dec < params.rel_tol * f.abs() {
                stop = LmStop::Converged;
                break;
            }
            if it >= GIVE_UP_AFTER && f - params.give_up_above > GIVE_UP_RATIO * dec {
                stop = LmStop::GivenUp {
                    above: f - params.give_up_above,
                    predicted: dec,
                };
                break;
            }
        }
        it += 1;
        let top = (0..d).map(|i| h[i * d + i].abs()).fold(0.0, f64::max);
        let mut a = h.clone();
        for i in 0..d {
            a[i * d + i] += lambda * h[i * d + i].abs().max(1e-12 * top).max(1e-300);
        }
        let Some(l) = cholesky(&a, d) else {
            lambda *= nu;
            nu *= 2.0;
            continue;
        };
        let step: Vec<f64> = chol_solve(&l, d, &g).iter().map(|v| -v).collect();
        // Predicted decrease of the damped quadratic model (positive: A is positive definite).
        let gs: f64 = g.iter().zip(&step).map(|(a, b)| a * b).sum();
        let sas: f64 = (0..d)
            .map(|i| step[i] * (0..d).map(|j| a[i * d + j] * step[j]).sum::<f64>())
            .sum();
        let predicted = -(gs + 0.5 * sas);
        let xn: Vec<f64> = x.iter().zip(&step).map(|(a, b)| a + b).collect();
        let fn_ = value(&xn);
        let rho = (f - fn_) / predicted;
        if fn_.is_finite() && fn_ < f && rho > 1e-4 {
            match quadratic(&xn) {
                Ok((f1, g1, h1)) => {
                    x = xn;
                    (f, g, h) = (f1, g1, h1);
                }
                Err(e) => {
                    stop = LmStop::Failed(format!("curvature at an accepted point ({e})"));
                    break;
                }
            }
            lambda *= (1.0 - (2.0 * rho - 1.0).powi(3)).max(1.0 / 3.0);
            nu = 2.0;
        } else {
            lambda *= nu;
            nu *= 2.0;
        }
        if lambda > 1e16 {
            stop = LmStop::Stalled;
            break;
        }
    }
    LmOutcome {
        x,
        f,
        iterations: it,
        stop,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params() -> LmParams {
        LmParams {
            max_iters: 500,
            tol: 1e-20,
            rel_tol: 0.0,
            give_up_above: f64::INFINITY,
        }
    }

    /// The tests' objectives fail only by not being finite.
    #[derive(Debug, thiserror::Error)]
    #[error("not finite")]
    struct NotFinite;

    #[test]
    fn rosenbrock_valley_reaches_its_minimum() {
        // r = (10 (y - x^2), 1 - x): f = |r|^2, g = 2 J^T r, H = 2 J^T J.
        let res = |p: &[f64]| [10.0 * (p[1] - p[0] * p[0]), 1.0 - p[0]];
        let q = |p: &[f64]| -> Result<Quadratic, NotFinite> {
            let r = res(p);
            let j = [[-20.0 * p[0], 10.0], [-1.0, 0.0]];
            let f = r[0] * r[0] + r[1] * r[1];
            let g = (0..2)
                .map(|k| 2.0 * (j[0][k] * r[0] + j[1][k] * r[1]))
                .collect();
            let h = (0..4)
                .map(|e| {
                    let (a, b) = (e / 2, e % 2);
                    2.0 * (j[0][a] * j[0][b] + j[1][a] * j[1][b])
                })
                .collect();
            Ok((f, g, h))
        };
        let v = |p: &[f64]| {
            let r = res(p);
            r[0] * r[0] + r[1] * r[1]
        };
        let out = levenberg_marquardt(&[-1.2, 1.0], q, v, &params());
        assert_eq!(out.stop, LmStop::Converged, "{}", out.stop);
        assert!(
            (out.x[0] - 1.0).abs() < 1e-8 && (out.x[1] - 1.0).abs() < 1e-8,
            "{:?}",
            out.x
        );
    }

    #[test]
    fn linear_least_squares_converge_in_a_few_steps_and_bad_starts_fail() {
        // f = (x - 3)^2 + 4 (y + 1)^2.
        let q = |p: &[f64]| -> Result<Quadratic, NotFinite> {
            Ok((
                (p[0] - 3.0).powi(2) + 4.0 * (p[1] + 1.0).powi(2),
                vec![2.0 * (p[0] - 3.0), 8.0 * (p[1] + 1.0)],
                vec![2.0, 0.0, 0.0, 8.0],
            ))
        };
        let v = |p: &[f64]| (p[0] - 3.0).powi(2) + 4.0 * (p[1] + 1.0).powi(2);
        let out = levenberg_marquardt(&[10.0, 10.0], q, v, &params());
        assert!(out.iterations < 20, "{}", out.iterations);
        assert!((out.x[0] - 3.0).abs() < 1e-9 && (out.x[1] + 1.0).abs() < 1e-9);
        let bad = levenberg_marquardt(
            &[0.0, 0.0],
            |_: &[f64]| -> Result<Quadratic, NotFinite> { Err(NotFinite) },
            |_: &[f64]| f64::NAN,
            &params(),
        );
        assert!(matches!(bad.stop, LmStop::Failed(_)) && bad.iterations == 0);
        assert!(bad
            .stop
            .to_string()
            .starts_with("failed: the objective is not finite"));
    }
}
