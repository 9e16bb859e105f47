//! The refit's start for a candidate effect: a profile over the effect's prior range.
//!
//! The score test's one-step size `S* / I*` is a linearisation at zero. For an effect whose
//! FRF changes non-linearly with its size (a mass or a shaker's moving mass shift resonances;
//! the shaker adds a stinger resonance whose frequency moves with `1 / sqrt(m_s)`), the step
//! can land far from the mode and the local refit then stops in another basin (a 20 g shaker
//! refitted to 42.7 g with chi-square ~1e4 on the dense chain). Here the effect's size is held
//! at each point of a grid across its prior (plus the one-step size), the model's other
//! parameters follow by a few Gauss-Newton steps (the profile), and the point with the
//! smallest weighted residual sum of squares `sum |X - E[H1]|^2 / v` is the refit's start.
//! The grid points race by successive halving: each round gives every point still in the race
//! one Gauss-Newton step and keeps the better half, so most points cost one step with the
//! Jacobian and the best few [`PROFILE_STEPS`], far less than a refit.

use super::candidate_model;
use crate::forward::{Effect, ForwardError};
use crate::inference::likelihood::FrfPosterior;
use crate::inference::prior::Prior;
use crate::linalg::dense::{chol_solve, cholesky};

/// Grid points across a uniform prior (cell centres).
pub const PROFILE_GRID: usize = 10;
/// Gauss-Newton steps of the other parameters at most per grid point (the race's rounds).
pub const PROFILE_STEPS: usize = 4;
/// A resonator's scan: its own frequency `sqrt(k / m) / 2 pi` stepped by half the line spacing
/// across the band (at most this many sizes), the best [`RESONATOR_SCAN_KEEP`] joining the race.
pub const RESONATOR_SCAN_MAX: usize = 400;
/// Sizes of a resonator's scan that join the race.
pub const RESONATOR_SCAN_KEEP: usize = 2;

/// A profiled start: the effect's size, the model's other parameters and the weighted
/// residual sum of squares there.
#[derive(Clone, Debug, PartialEq)]
pub struct ProfileStart {
    pub size: f64,
    pub params: Vec<f64>,
    pub wrss: f64,
    /// Forward evaluations the profile spent (with or without the Jacobian).
    pub evaluations: usize,
}

/// The refit's start for `candidate` added to `post`'s current model at physical parameters
/// `phys` (model parameters then noise): the best of the profile at `one_step` (the model's
/// parameters from `gn_start`, or from the current MAP's when `gn_start` lies outside their
/// priors) and at [`PROFILE_GRID`] cell centres of the effect's uniform prior (other priors:
/// the one-step size only). Every profile point lies inside the priors' support.
pub fn profile_start(
    post: &FrfPosterior<'_>,
    phys: &[f64],
    candidate: &Effect,
    one_step: f64,
    gn_start: &[f64],
) -> Result<ProfileStart, ForwardError> {
    let lik = &post.likelihood;
    let np = lik.forward.n_params();
    let mut fm = candidate_model(lik, candidate)?;
    // With a term of the term ROM the profile runs on the measurement bias linearised at the
    // current fit (the start needs the valley, not its last digits; the refit re-linearises).
    if super::uses_linearised_bias(&fm, &fm.effects) {
        let mut at = phys[..np].to_vec();
        at.push(candidate.null_value());
        fm.linearise_model_measurement(&at)?;
    }
    let v = lik.variances(&phys[np..]);
    let mut sizes = vec![one_step];
    if let Prior::Uniform { lo, hi } = candidate.default_prior() {
        let span = hi - lo;
        sizes.extend((0..PROFILE_GRID).map(|i| lo + span * (i as f64 + 0.5) / PROFILE_GRID as f64));
    }
    // A start outside the priors' support has no finite posterior density (the refit could
    // not begin there), so the profile's Gauss-Newton steps stay inside it.
    let inside = |p: &[f64]| {
        p[..np]
            .iter()
            .zip(&post.priors[..np])
            .all(|(x, pr)| pr.contains(*x))
    };
    let evaluations = std::cell::Cell::new(0usize);
    let wrss = |p: &[f64]| -> Option<f64> {
        fm.check(p).ok()?;
        evaluations.set(evaluations.get() + 1);
        inside(p).then_some(())?;
        let pred = fm.predict(p, false).ok()?;
        let s = super::weighted_rss(&lik.data.values, &pred.values, &v);
        s.is_finite().then_some(s)
    };
    // The Gauss-Newton start of the model's parameters, else (outside the priors) the current
    // MAP's.
    let base = if inside(gn_start) {
        &gn_start[..np]
    } else {
        &phys[..np]
    };
    let at_base = |e: f64| {
        let mut p = base.to_vec();
        p.push(e);
        wrss(&p).map(|q| (e, p, q))
    };
    // The sizes in order of their residual at the start (the ties in the given order).
    let mut alive: Vec<(f64, Vec<f64>, f64)> = sizes.iter().filter_map(|&e| at_base(e)).collect();
    // A resonator's residual is rugged in its size: its own resonance is as sharp as the
    // structure's damping lets it be, so the residual has a narrow valley wherever that
    // resonance matches the data's (about 0.5 % wide in frequency for an undamped 20 g on 2e5 N/m
    // on the dense chain), which the prior's grid misses. Its frequency is scanned across the
    // band with the model's parameters held (values only, no Jacobian), and the best sizes race.
    let mut scanned: Vec<(f64, Vec<f64>, f64)> = resonator_scan(candidate, &fm.obs.omega_rad_s)
        .into_iter()
        .filter(|&e| lo_hi_contains(candidate, e))
        .filter_map(at_base)
        .collect();
    scanned.sort_by(|a, b| a.2.total_cmp(&b.2));
    alive.extend(scanned.into_iter().take(RESONATOR_SCAN_KEEP));
    alive.sort_by(|a, b| a.2.total_cmp(&b.2));
    // Successive halving: one Gauss-Newton step for every size still in the race, then the
    // better half (at least two) goes on, so most of the grid costs one step, not
    // PROFILE_STEPS (each step is a forward evaluation with the Jacobian: 2 s on a term ROM).
    // A size whose Gauss-Newton model cannot reach the best point so far even at twice its
    // predicted decrease leaves the race at once, as does one whose step does not decrease.
    let mut best_q = alive.first().map_or(f64::INFINITY, |a| a.2);
    let mut done: Vec<(f64, Vec<f64>, f64)> = Vec::new();
    for _ in 0..PROFILE_STEPS {
        let mut next = Vec::with_capacity(alive.len());
        for (e, mut p, mut q) in std::mem::take(&mut alive) {
            evaluations.set(evaluations.get() + 1);
            let Some((dp, decrease)) = gauss_newton_step(&fm, lik, &v, &p, np)? else {
                done.push((e, p, q));
                continue;
            };
            if q - 2.0 * decrease > best_q {
                done.push((e, p, q));
                continue;
            }
            let mut f = 1.0;
            let mut moved = false;
            for _ in 0..8 {
                let mut trial = p.clone();
                for i in 0..np {
                    trial[i] += f * dp[i];
                }
                if let Some(qt) = wrss(&trial) {
                    if qt < q {
                        p = trial;
                        q = qt;
                        moved = true;
                        break;
                    }
                }
                f *= 0.5;
            }
            best_q = best_q.min(q);
            if moved {
                next.push((e, p, q));
            } else {
                done.push((e, p, q));
            }
        }
        next.sort_by(|a, b| a.2.total_cmp(&b.2));
        let keep = next.len().div_ceil(2).max(2).min(next.len());
        done.extend(next.drain(keep..));
        alive = next;
        if alive.is_empty() {
            break;
        }
    }
    done.extend(alive);
    let mut best = done
        .into_iter()
        .min_by(|a, b| a.2.total_cmp(&b.2))
        .map(|(e, p, q)| ProfileStart {
            size: e,
            params: p[..np].to_vec(),
            wrss: q,
            evaluations: 0,
        });
    if let Some(b) = best.as_mut() {
        b.evaluations = evaluations.get();
    }
    best.ok_or_else(|| {
        ForwardError::Setup(format!(
            "no admissible start for the refit of {}",
            candidate.name()
        ))
    })
}

/// Whether `e` lies inside `candidate`'s default prior (any size when the prior is not uniform).
fn lo_hi_contains(candidate: &Effect, e: f64) -> bool {
    match candidate.default_prior() {
        Prior::Uniform { lo, hi } => e > lo && e < hi,
        _ => true,
    }
}

/// The sizes of a resonator's scan: masses `m = k / w_r^2` whose own frequency `w_r` steps by
/// half the (smallest) line spacing from the lowest line to the highest of `omega_rad_s`, on a
/// geometric grid of at most [`RESONATOR_SCAN_MAX`] points when that is too many. Empty for any
/// other effect.
fn resonator_scan(candidate: &Effect, omega_rad_s: &[f64]) -> Vec<f64> {
    let Effect::Resonator { stiffness_n_m, .. } = candidate else {
        return Vec::new();
    };
    let (Some(&w0), Some(&w1)) = (omega_rad_s.first(), omega_rad_s.last()) else {
        return Vec::new();
    };
    let dw = omega_rad_s
        .windows(2)
        .map(|p| (p[1] - p[0]).abs())
        .filter(|d| *d > 0.0)
        .fold(f64::INFINITY, f64::min);
    if !(w0 > 0.0 && w1 > w0 && dw.is_finite()) {
        return Vec::new();
    }
    let n = (((w1 - w0) / (0.5 * dw)).ceil() as usize + 1).min(RESONATOR_SCAN_MAX);
    let ratio = (w1 / w0).powf(1.0 / (n - 1).max(1) as f64);
    let linear = n < RESONATOR_SCAN_MAX;
    (0..n)
        .map(|i| {
            let w = if linear {
                w0 + (w1 - w0) * i as f64 / (n - 1).max(1) as f64
            } else {
                w0 * ratio.powi(i as i32)
            };
            stiffness_n_m / (w * w)
        })
        .collect()
}

/// One Gauss-Newton step of the first `np` parameters of `p` (the last, the effect, held):
/// `dp = I_pp^-1 S_p` with the columns scaled by `|p_i|` for conditioning, and the decrease of
/// the weighted residual sum of squares its linear model predicts, `S_p^T dp`. None when the
/// information is singular.
fn gauss_newton_step(
    fm: &crate::forward::ForwardModel<'_>,
    lik: &crate::inference::likelihood::FrfLikelihood<'_>,
    v: &[f64],
    p: &[f64],
    np: usize,
) -> Result<Option<(Vec<f64>, f64)>, ForwardError> {
    let pred = fm.predict(p, true)?;
    let scale: Vec<f64> = p[..np]
        .iter()
        .map(|x| if *x != 0.0 { x.abs() } else { 1.0 })
        .collect();
    let cols: Vec<usize> = (0..np).collect();
    let (s, fi) = super::normal_equations(&lik.data.values, &pred, v, &cols, &scale);
    let Some(l) = cholesky(&fi, np) else {
        return Ok(None);
    };
    let d = chol_solve(&l, np, &s);
    let decrease = d.iter().zip(&s).map(|(a, b)| a * b).sum::<f64>();
    Ok(Some((
        d.iter().zip(&scale).map(|(d, s)| d * s).collect(),
        decrease,
    )))
}

/// Relative distance (of the prior's range; log range for a log-uniform prior) within which
/// a parameter is at an edge of its prior.
pub const EDGE_FRACTION: f64 = 1e-3;

/// Whether any parameter of `phys` lies within [`EDGE_FRACTION`] of an edge of its bounded
/// prior (uniform, log-uniform, truncated normal).
pub fn at_prior_edge(priors: &[Prior], phys: &[f64]) -> bool {
    priors.iter().zip(phys).any(|(p, &x)| {
        let (a, b, y) = match *p {
            Prior::Uniform { lo, hi } | Prior::TruncatedNormal { lo, hi, .. } => (lo, hi, x),
            Prior::LogUniform { lo, hi } if x > 0.0 => (lo.ln(), hi.ln(), x.ln()),
            _ => return false,
        };
        if !(a.is_finite() && b.is_finite()) {
            return false;
        }
        let tol = EDGE_FRACTION * (b - a);
        y - a < tol || b - y < tol
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn edges_of_bounded_priors_are_detected_and_interior_points_are_not() {
        let pri = [
            Prior::Uniform { lo: 0.0, hi: 0.1 },
            Prior::LogUniform { lo: 1e5, hi: 1e7 },
            Prior::LogNormal {
                median: 1.0,
                sigma_ln: 1.0,
            },
        ];
        assert!(!at_prior_edge(&pri, &[0.05, 1e6, 1e9]));
        assert!(at_prior_edge(&pri, &[0.0, 1e6, 1.0]));
        assert!(at_prior_edge(&pri, &[0.09999, 1e6, 1.0]));
        // log range 4.6: 1e-3 of it is a factor 1.0046 above lo.
        assert!(at_prior_edge(&pri, &[0.05, 1.004e5, 1.0]));
        assert!(!at_prior_edge(&pri, &[0.05, 1.01e5, 1.0]));
    }
}
