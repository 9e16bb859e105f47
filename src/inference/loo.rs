//! Predictive criteria from a pointwise log likelihood `log_lik[chain][draw][observation]`:
//! PSIS-LOO and WAIC, on ArviZ's log scale (higher is better), written to give the numbers
//! ArviZ 0.23 (`az.loo`, `az.waic`, `az.psislw`) gives.
//!
//! Reference: Vehtari, Gelman, Gabry (2017), "Practical Bayesian model evaluation using
//! leave-one-out cross-validation and WAIC", Statistics and Computing 27, 1413-1432; the
//! generalised Pareto fit is Zhang & Stephens (2009), Technometrics 51(3), 316-325, with the
//! weakly informative prior of Vehtari et al.
//!
//! # Definitions
//! With `S` posterior draws `s` (all chains pooled) and `n` observations `i`,
//! `l_is = log p(y_i | theta_s)`:
//! * `lppd = sum_i log(1/S sum_s exp(l_is))`.
//! * **PSIS**: the log ratios `r_s = -l_is` (shifted to max 0) keep all but their largest
//!   `M = ceil(min(S/5, 3 sqrt(S / r_eff)))`; those above the cutoff `c` (the next largest, at
//!   least `log(f64::MIN_POSITIVE)`) are fitted by a generalised Pareto law to `exp(r) - exp(c)`
//!   (Zhang-Stephens posterior mean over `30 + floor(sqrt(M))` grid points, prior
//!   `k <- (M k + 5) / (M + 10)`), replaced by its quantiles at `(j - 1/2)/M` (log, plus
//!   `exp(c)`), truncated at 0 and normalised. `k_i` is the fitted shape (infinite when at most 4
//!   ratios exceed the cutoff; then nothing is smoothed).
//! * **LOO**: `elpd_i = log sum_s w_is exp(l_is)`, `elpd = sum_i elpd_i`,
//!   `se = sqrt(n var_i(elpd_i))` (ddof 0), `p_loo = lppd - elpd`. ArviZ's default `r_eff` is the
//!   mean over the posterior's quantities of `ESS_mean / S` (1 for a single chain),
//!   [`relative_eff`].
//! * **WAIC**: `v_i = var_s(l_is)` (ddof 0), `elpd_i = log(1/S sum_s exp(l_is)) - v_i`,
//!   `elpd = sum_i elpd_i`, `se = sqrt(n var_i(elpd_i))`, `p_waic = sum_i v_i`.
//!
//! `looic = -2 elpd` (deviance scale) is available from [`Loo::looic`] / [`Waic::waic`].

use super::diagnostics::{self, DiagnosticsError};

/// Malformed input to LOO or WAIC.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LooError {
    /// No chains, draws or observations.
    #[error("empty log-likelihood array (need at least one chain, draw and observation)")]
    Empty,
    /// Chains or draws of different sizes.
    #[error("ragged log-likelihood array at chain {chain}, draw {draw}")]
    Ragged {
        /// Chain index.
        chain: usize,
        /// Draw index within the chain.
        draw: usize,
    },
    /// A NaN or +inf log likelihood.
    #[error("log likelihood of observation {obs} is {value} at chain {chain}, draw {draw}")]
    NotFinite {
        /// Chain index.
        chain: usize,
        /// Draw index.
        draw: usize,
        /// Observation index.
        obs: usize,
        /// The offending value.
        value: f64,
    },
    /// A relative efficiency that is not positive and finite.
    #[error("relative efficiency must be positive and finite, got {0}")]
    BadRelativeEfficiency(f64),
    /// The posterior draws given for the relative efficiency are malformed.
    #[error(transparent)]
    Diagnostics(#[from] DiagnosticsError),
}

/// The Pareto k above which ArviZ's `loo` flags an observation (and all PSIS estimates become
/// unreliable): 0.7.
pub const PARETO_K_THRESHOLD: f64 = 0.7;

/// PSIS-LOO estimate (log scale).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Loo {
    /// Expected log pointwise predictive density, `sum_i elpd_i`.
    pub elpd: f64,
    /// Its standard error.
    pub se: f64,
    /// Effective number of parameters, `lppd - elpd`.
    pub p_loo: f64,
    /// `elpd_i` per observation.
    pub pointwise: Vec<f64>,
    /// Pareto shape `k_i` per observation (infinite when its tail was too short to fit).
    pub pareto_k: Vec<f64>,
    /// `k_i > 0.7` ([`PARETO_K_THRESHOLD`]) per observation.
    pub high_k: Vec<bool>,
    /// ArviZ's sample-size-dependent threshold `min(1 - 1/log10(S), 0.7)`.
    pub good_k: f64,
    /// ArviZ's warning flag: some `k_i > good_k`.
    pub warning: bool,
    /// The relative efficiency used.
    pub r_eff: f64,
    /// Number of posterior draws `S`.
    pub n_samples: usize,
}

impl Loo {
    /// LOO information criterion on the deviance scale: `(-2 elpd, 2 se)`.
    pub fn looic(&self) -> (f64, f64) {
        (-2.0 * self.elpd, 2.0 * self.se)
    }
}

/// WAIC estimate (log scale).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Waic {
    /// `sum_i elpd_i`.
    pub elpd: f64,
    /// Its standard error.
    pub se: f64,
    /// Effective number of parameters `sum_i var_s(l_is)`.
    pub p_waic: f64,
    /// `elpd_i` per observation.
    pub pointwise: Vec<f64>,
    /// ArviZ's warning flag: some `var_s(l_is) > 0.4`.
    pub warning: bool,
}

impl Waic {
    /// WAIC on the deviance scale: `(-2 elpd, 2 se)`.
    pub fn waic(&self) -> (f64, f64) {
        (-2.0 * self.elpd, 2.0 * self.se)
    }
}

/// `log_lik[chain][draw][obs]` as `n` rows of `S` draws (chains pooled, chain-major).
fn by_observation(log_lik: &[Vec<Vec<f64>>]) -> Result<Vec<Vec<f64>>, LooError> {
    let n_draw = log_lik.first().map_or(0, |c| c.len());
    let n_obs = log_lik
        .first()
        .and_then(|c| c.first())
        .map_or(0, |d| d.len());
    if n_draw == 0 || n_obs == 0 {
        return Err(LooError::Empty);
    }
    let s = log_lik.len() * n_draw;
    let mut rows = vec![Vec::with_capacity(s); n_obs];
    for (chain, c) in log_lik.iter().enumerate() {
        if c.len() != n_draw {
            return Err(LooError::Ragged { chain, draw: 0 });
        }
        for (draw, d) in c.iter().enumerate() {
            if d.len() != n_obs {
                return Err(LooError::Ragged { chain, draw });
            }
            for (obs, &value) in d.iter().enumerate() {
                if value.is_nan() || value == f64::INFINITY {
                    return Err(LooError::NotFinite {
                        chain,
                        draw,
                        obs,
                        value,
                    });
                }
                rows[obs].push(value);
            }
        }
    }
    Ok(rows)
}

/// `log(sum exp(x) / b_inv)`, shifted by the maximum.
fn log_sum_exp(x: &[f64], b_inv: f64) -> f64 {
    let mx = x.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if mx == f64::NEG_INFINITY {
        return mx;
    }
    (x.iter().map(|v| (v - mx).exp()).sum::<f64>() / b_inv).ln() + mx
}

fn mean(x: &[f64]) -> f64 {
    x.iter().sum::<f64>() / x.len() as f64
}

fn var0(x: &[f64]) -> f64 {
    let m = mean(x);
    x.iter().map(|v| (v - m) * (v - m)).sum::<f64>() / x.len() as f64
}

/// Zhang-Stephens fit of a generalised Pareto law to sorted positive exceedances `x`, with
/// Vehtari et al.'s prior on the shape: `(k, sigma)`.
pub fn gpd_fit(x: &[f64]) -> (f64, f64) {
    const PRIOR_BS: f64 = 3.0;
    const PRIOR_K: f64 = 10.0;
    let n = x.len();
    let nf = n as f64;
    let m_est = 30 + (nf.sqrt().floor() as usize);
    let x_q = x[((nf / 4.0 + 0.5).floor() as usize).saturating_sub(1)];
    let x_max = x[n - 1];
    let b: Vec<f64> = (1..=m_est)
        .map(|j| (1.0 - (m_est as f64 / (j as f64 - 0.5)).sqrt()) / (PRIOR_BS * x_q) + 1.0 / x_max)
        .collect();
    let k_of = |bj: f64| x.iter().map(|&v| (-bj * v).ln_1p()).sum::<f64>() / nf;
    let len_scale: Vec<f64> = b
        .iter()
        .map(|&bj| {
            let k = k_of(bj);
            nf * ((-(bj / k)).ln() - k - 1.0)
        })
        .collect();
    let mut w: Vec<f64> = len_scale
        .iter()
        .map(|li| 1.0 / len_scale.iter().map(|lj| (lj - li).exp()).sum::<f64>())
        .collect();
    let keep: Vec<bool> = w.iter().map(|&wi| wi >= 10.0 * f64::EPSILON).collect();
    let b: Vec<f64> = b
        .iter()
        .zip(&keep)
        .filter(|(_, &k)| k)
        .map(|(&v, _)| v)
        .collect();
    w.retain(|&wi| wi >= 10.0 * f64::EPSILON);
    let wsum: f64 = w.iter().sum();
    let b_post: f64 = b.iter().zip(&w).map(|(bj, wj)| bj * (wj / wsum)).sum();
    let k_post = k_of(b_post);
    let sigma = -k_post / b_post;
    ((nf * k_post + PRIOR_K * 0.5) / (nf + PRIOR_K), sigma)
}

/// Quantiles of the generalised Pareto law `(k, sigma)` at probabilities in (0, 1).
fn gpd_inv(p: &[f64], k: f64, sigma: f64) -> Vec<f64> {
    if !(sigma > 0.0) {
        return vec![f64::NAN; p.len()];
    }
    p.iter()
        .map(|&pi| {
            let x = if k.abs() < f64::EPSILON {
                -(-pi).ln_1p()
            } else {
                (-k * (-pi).ln_1p()).exp_m1() / k
            };
            x * sigma
        })
        .collect()
}

/// Pareto-smoothed importance sampling of one vector of log importance ratios with relative
/// efficiency `r_eff` (`az.psislw`): the normalised smoothed log weights and the Pareto `k`.
pub fn psis_log_weights(log_ratios: &[f64], r_eff: f64) -> (Vec<f64>, f64) {
    let s = log_ratios.len();
    let mx = log_ratios.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let mut x: Vec<f64> = log_ratios.iter().map(|v| v - mx).collect();
    let m_tail = (0.2 * s as f64).min(3.0 * (s as f64 / r_eff).sqrt()).ceil() as usize;
    let mut sorted = x.clone();
    sorted.sort_by(f64::total_cmp);
    // The (M+1)-th largest value, as numpy's negative index -(M+1) (clamped like it wraps no
    // further than the smallest).
    let cut_idx = s.saturating_sub(m_tail + 1);
    let cutoff = sorted[cut_idx].max(f64::MIN_POSITIVE.ln());
    let exp_cut = cutoff.exp();
    let mut tail: Vec<usize> = (0..s).filter(|&i| x[i] > cutoff).collect();
    let k = if tail.len() <= 4 {
        f64::INFINITY
    } else {
        tail.sort_by(|&a, &b| x[a].total_cmp(&x[b]));
        let exceed: Vec<f64> = tail.iter().map(|&i| x[i].exp() - exp_cut).collect();
        let (k, sigma) = gpd_fit(&exceed);
        if k.is_finite() {
            let len = tail.len() as f64;
            let p: Vec<f64> = (0..tail.len()).map(|j| (j as f64 + 0.5) / len).collect();
            let smoothed = gpd_inv(&p, k, sigma);
            for (&i, v) in tail.iter().zip(smoothed) {
                x[i] = (v + exp_cut).ln();
            }
            for v in x.iter_mut() {
                if *v > 0.0 {
                    *v = 0.0;
                }
            }
        }
        k
    };
    let norm = log_sum_exp(&x, 1.0);
    x.iter_mut().for_each(|v| *v -= norm);
    (x, k)
}

/// ArviZ's default relative efficiency for [`loo`]: the mean over the posterior's quantities
/// `params[q][chain][draw]` of `ESS_mean / S`, or 1 for a single chain.
pub fn relative_eff(params: &[Vec<Vec<f64>>]) -> Result<f64, DiagnosticsError> {
    let first = params.first().ok_or(DiagnosticsError::NoChains)?;
    if first.len() == 1 {
        return Ok(1.0);
    }
    let s = (first.len() * first.first().map_or(0, |c| c.len())) as f64;
    let mut sum = 0.0;
    for p in params {
        sum += diagnostics::ess_mean(p)?;
    }
    Ok(sum / params.len() as f64 / s)
}

/// PSIS-LOO of `log_lik[chain][draw][observation]` with relative efficiency `r_eff` (use
/// [`relative_eff`] of the posterior draws for ArviZ's default, 1 for independent draws).
pub fn loo(log_lik: &[Vec<Vec<f64>>], r_eff: f64) -> Result<Loo, LooError> {
    if !(r_eff > 0.0 && r_eff.is_finite()) {
        return Err(LooError::BadRelativeEfficiency(r_eff));
    }
    let rows = by_observation(log_lik)?;
    let s = rows[0].len();
    let n = rows.len() as f64;
    let mut pointwise = Vec::with_capacity(rows.len());
    let mut pareto_k = Vec::with_capacity(rows.len());
    let mut lppd = 0.0;
    for row in &rows {
        let neg: Vec<f64> = row.iter().map(|v| -v).collect();
        let (mut lw, k) = psis_log_weights(&neg, r_eff);
        lw.iter_mut().zip(row).for_each(|(w, l)| *w += l);
        pointwise.push(log_sum_exp(&lw, 1.0));
        pareto_k.push(k);
        lppd += log_sum_exp(row, s as f64);
    }
    let elpd: f64 = pointwise.iter().sum();
    let good_k = (1.0 - 1.0 / (s as f64).log10()).min(PARETO_K_THRESHOLD);
    Ok(Loo {
        elpd,
        se: (n * var0(&pointwise)).sqrt(),
        p_loo: lppd - elpd,
        high_k: pareto_k.iter().map(|&k| k > PARETO_K_THRESHOLD).collect(),
        warning: pareto_k.iter().any(|&k| k > good_k),
        good_k,
        pointwise,
        pareto_k,
        r_eff,
        n_samples: s,
    })
}

/// WAIC of `log_lik[chain][draw][observation]` (`az.waic`).
pub fn waic(log_lik: &[Vec<Vec<f64>>]) -> Result<Waic, LooError> {
    let rows = by_observation(log_lik)?;
    let s = rows[0].len() as f64;
    let n = rows.len() as f64;
    let mut pointwise = Vec::with_capacity(rows.len());
    let mut p_waic = 0.0;
    let mut warning = false;
    for row in &rows {
        let v = var0(row);
        warning |= v > 0.4;
        p_waic += v;
        pointwise.push(log_sum_exp(row, s) - v);
    }
    Ok(Waic {
        elpd: pointwise.iter().sum(),
        se: (n * var0(&pointwise)).sqrt(),
        p_waic,
        pointwise,
        warning,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gpd_fit_recovers_the_shape_of_pareto_quantiles() {
        // Exact GPD(k = 0.5, sigma = 1) quantiles at (j - 1/2)/n: the fit should be near 0.5
        // (pulled slightly towards the prior's 0.5 anyway).
        let n = 2000;
        let x: Vec<f64> = (0..n)
            .map(|j| {
                let p = (j as f64 + 0.5) / n as f64;
                ((-0.5 * (-p).ln_1p()).exp() - 1.0) / 0.5
            })
            .collect();
        let (k, sigma) = gpd_fit(&x);
        assert!((k - 0.5).abs() < 0.02, "k {k}");
        assert!((sigma - 1.0).abs() < 0.05, "sigma {sigma}");
        // Exponential quantiles: k near 0.
        let e: Vec<f64> = (0..n)
            .map(|j| -(-(j as f64 + 0.5) / n as f64).ln_1p())
            .collect();
        assert!(gpd_fit(&e).0.abs() < 0.03);
    }

    #[test]
    fn equal_weights_give_exact_loo_and_zero_p() {
        // A likelihood that does not depend on the draw: LOO = WAIC = lppd, p = 0, k = -inf-ish.
        let ll = vec![vec![vec![-1.0, -2.0, -3.5]; 50]; 2];
        let l = loo(&ll, 1.0).unwrap();
        assert!((l.elpd + 6.5).abs() < 1e-12);
        assert!(l.p_loo.abs() < 1e-12);
        let w = waic(&ll).unwrap();
        assert!((w.elpd + 6.5).abs() < 1e-12 && w.p_waic == 0.0);
        // se = sqrt(n var): var of (-1, -2, -3.5) is 19/18 * ... computed directly.
        let m = -6.5 / 3.0;
        let v = [(-1.0 - m), (-2.0 - m), (-3.5 - m)]
            .iter()
            .map(|d: &f64| d * d)
            .sum::<f64>()
            / 3.0;
        assert!((w.se - (3.0 * v).sqrt()).abs() < 1e-12);
    }

    #[test]
    fn malformed_input_is_an_error() {
        assert_eq!(loo(&[], 1.0), Err(LooError::Empty));
        let ll = vec![vec![vec![0.0; 3], vec![0.0; 2]]];
        assert_eq!(waic(&ll), Err(LooError::Ragged { chain: 0, draw: 1 }));
        let ll = vec![vec![vec![f64::NAN]]];
        assert!(matches!(loo(&ll, 1.0), Err(LooError::NotFinite { .. })));
        assert!(matches!(
            loo(&[vec![vec![0.0]]], 0.0),
            Err(LooError::BadRelativeEfficiency(_))
        ));
    }
}
