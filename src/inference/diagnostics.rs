//! MCMC convergence diagnostics and posterior summaries of one scalar quantity, written to give
//! the numbers ArviZ 0.23 (`az.rhat`, `az.ess`, `az.mcse`, `az.hdi`, `az.bfmi`) gives.
//!
//! Input is always `draws[chain][draw]`: `M` chains of `N` draws each (chains must be of equal
//! length). References: Vehtari, Gelman, Simpson, Carpenter, Bürkner (2021), "Rank-normalization,
//! folding, and localization: an improved R-hat for assessing convergence of MCMC", Bayesian
//! Analysis 16(2), 667-718 (R-hat, ESS, MCSE); Betancourt (2017), "A conceptual introduction to
//! Hamiltonian Monte Carlo", arXiv:1701.02434 (E-BFMI).
//!
//! # Definitions
//! * **Split chains**: each chain is cut into its first and last `floor(N/2)` draws (the middle
//!   draw of an odd chain is dropped), giving `2M` chains of `n = floor(N/2)` draws.
//! * **Rank normalisation**: with `r` the average rank of a draw among all `S` draws,
//!   `z = Phi^-1((r - 3/8) / (S + 1/4))`.
//! * **R-hat** of chains `j` with means `m_j` and variances `s_j^2` (ddof 1):
//!   `W = mean_j s_j^2`, `B = n var_j(m_j)` (ddof 1), `R = sqrt(((n-1)/n W + B/n) / W)`.
//!   Rank R-hat = max(bulk, tail): bulk is R of the rank-normalised split chains, tail of the
//!   rank-normalised folded split draws `|x - median(x)|`. NaN for fewer than 2 chains or 4 draws.
//! * **ESS** (Geyer's initial monotone sequence): with the per-chain autocovariances `c_j(t)`
//!   (divisor `n`), `W = mean_j c_j(0) n/(n-1)`, `var+ = W (n-1)/n + var_j(m_j)` (the second term
//!   only when `M > 1`), `rho(t) = 1 - (W - mean_j c_j(t)) / var+`. Pairs `rho(2k) + rho(2k+1)` are
//!   summed while positive, made monotone, and `tau = -1 + 2 sum_{t<=T} rho(t) + rho(T+1)`,
//!   bounded below by `1/log10(M n)`; `ESS = M n / tau`. Constant input gives `ESS = M n`.
//!   * bulk: ESS of the rank-normalised split chains;
//!   * tail: min of the ESS of the split indicators `x <= q_0.05` and `x <= q_0.95`;
//!   * mean: ESS of the split chains themselves;
//!   * quantile `p`: ESS of the split indicator `x <= q_p`.
//! * **MCSE**: of the mean `sd(x) / sqrt(ESS_mean)`; of the sd, with `d = (x - mean x)^2`,
//!   `sqrt((mean(d^2) - mean(d)^2) / ESS_mean(d) / mean(d) / 4)`; of a quantile `p`, with
//!   `a = ESS_p p + 1`, `b = ESS_p (1-p) + 1`, `u1,2 = Beta^-1(0.1586553 | 0.8413447; a, b)` and
//!   the sorted draws `x_(1..S)`: `(x_(min(ceil(S u2), S)) - x_(max(floor(S u1), 1))) / 2` (the
//!   +-1 sd interval of the quantile's order statistic).
//! * **Quantiles** interpolate linearly between order statistics at `(S - 1) p` (numpy's
//!   default); the **HDI** at probability `P` is the narrowest interval `[x_(i), x_(i+K)]`,
//!   `K = floor(P S)` (first one on ties), over all chains pooled (unimodal).
//! * **E-BFMI** of one chain of NUTS energies `E_1..E_N`:
//!   `sum_{t>1} (E_t - E_{t-1})^2 / sum_t (E_t - mean E)^2`.
//!
//! Invalid input in ArviZ's sense (any NaN, fewer than 4 draws, R-hat with one chain) gives NaN,
//! as ArviZ does; only malformed input (no chains, ragged chains, a probability outside (0, 1))
//! is an error.

use crate::common::quantile_sorted;
use rustfft::{num_complex::Complex, FftPlanner};

/// Malformed input to a diagnostic.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DiagnosticsError {
    /// No chains at all.
    #[error("no chains given")]
    NoChains,
    /// Chains of different lengths.
    #[error("chain {chain} has {len} draws but chain 0 has {expected}")]
    RaggedChains {
        /// Index of the offending chain.
        chain: usize,
        /// Its number of draws.
        len: usize,
        /// The number of draws of chain 0.
        expected: usize,
    },
    /// A probability outside the open interval (0, 1).
    #[error("probability must lie in (0, 1), got {0}")]
    BadProbability(f64),
    /// No draws at all (HDI of an empty sample).
    #[error("no draws to compute an interval from")]
    NoDraws,
}

/// Draws of one quantity as a dense `m x n` row-major matrix (chain-major).
#[derive(Debug, Clone)]
struct Chains {
    m: usize,
    n: usize,
    x: Vec<f64>,
}

impl Chains {
    fn from_draws(draws: &[Vec<f64>]) -> Result<Self, DiagnosticsError> {
        let first = draws.first().ok_or(DiagnosticsError::NoChains)?;
        let n = first.len();
        for (chain, c) in draws.iter().enumerate() {
            if c.len() != n {
                return Err(DiagnosticsError::RaggedChains {
                    chain,
                    len: c.len(),
                    expected: n,
                });
            }
        }
        Ok(Chains {
            m: draws.len(),
            n,
            x: draws.iter().flatten().copied().collect(),
        })
    }

    fn chain(&self, j: usize) -> &[f64] {
        &self.x[j * self.n..(j + 1) * self.n]
    }

    fn map(&self, f: impl Fn(f64) -> f64) -> Chains {
        Chains {
            m: self.m,
            n: self.n,
            x: self.x.iter().map(|&v| f(v)).collect(),
        }
    }

    /// ArviZ's validity check: no NaN, at least `min_chains` chains of at least 4 draws.
    fn valid(&self, min_chains: usize) -> bool {
        self.m >= min_chains && self.n >= 4 && !self.x.iter().any(|v| v.is_nan())
    }

    /// First and last `floor(n/2)` draws of every chain as separate chains (all first halves,
    /// then all second halves).
    fn split(&self) -> Chains {
        let h = self.n / 2;
        let mut x = Vec::with_capacity(2 * self.m * h);
        for j in 0..self.m {
            x.extend_from_slice(&self.chain(j)[..h]);
        }
        for j in 0..self.m {
            x.extend_from_slice(&self.chain(j)[self.n - h..]);
        }
        Chains {
            m: 2 * self.m,
            n: h,
            x,
        }
    }
}

fn mean(x: &[f64]) -> f64 {
    x.iter().sum::<f64>() / x.len() as f64
}

/// Variance with `ddof` (0 or 1).
fn var(x: &[f64], ddof: usize) -> f64 {
    let m = mean(x);
    x.iter().map(|v| (v - m) * (v - m)).sum::<f64>() / (x.len() - ddof) as f64
}

fn sorted(x: &[f64]) -> Vec<f64> {
    let mut s = x.to_vec();
    s.sort_by(f64::total_cmp);
    s
}

/// Quantile `p` in `[0, 1]` of `values` with numpy's default linear interpolation
/// (`np.quantile(values, p)`); NaN for no values or when any value is NaN.
pub fn quantile(values: &[f64], p: f64) -> f64 {
    if values.iter().any(|v| v.is_nan()) {
        return f64::NAN;
    }
    quantile_sorted(&sorted(values), p)
}

pub(crate) use crate::stats::special::norm_ppf;

/// Regularised incomplete beta function `I_x(a, b)` (continued fraction, modified Lentz).
fn beta_inc(a: f64, b: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 0.0;
    }
    if x >= 1.0 {
        return 1.0;
    }
    let ln_front =
        libm::lgamma(a + b) - libm::lgamma(a) - libm::lgamma(b) + a * x.ln() + b * (-x).ln_1p();
    if x < (a + 1.0) / (a + b + 2.0) {
        ln_front.exp() * beta_cf(a, b, x) / a
    } else {
        1.0 - ln_front.exp() * beta_cf(b, a, 1.0 - x) / b
    }
}

fn beta_cf(a: f64, b: f64, x: f64) -> f64 {
    const TINY: f64 = 1e-300;
    let (qab, qap, qam) = (a + b, a + 1.0, a - 1.0);
    let mut c = 1.0;
    let mut d = 1.0 - qab * x / qap;
    if d.abs() < TINY {
        d = TINY;
    }
    d = 1.0 / d;
    let mut h = d;
    for m in 1..100_000 {
        let m = m as f64;
        let m2 = 2.0 * m;
        let aa = m * (b - m) * x / ((qam + m2) * (a + m2));
        d = 1.0 + aa * d;
        if d.abs() < TINY {
            d = TINY;
        }
        c = 1.0 + aa / c;
        if c.abs() < TINY {
            c = TINY;
        }
        d = 1.0 / d;
        h *= d * c;
        let aa = -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2));
        d = 1.0 + aa * d;
        if d.abs() < TINY {
            d = TINY;
        }
        c = 1.0 + aa / c;
        if c.abs() < TINY {
            c = TINY;
        }
        d = 1.0 / d;
        let del = d * c;
        h *= del;
        if (del - 1.0).abs() < 1e-16 {
            break;
        }
    }
    h
}

/// Quantile `p` of the Beta(a, b) distribution, by bisection of `I_x(a, b)` to full precision.
fn beta_ppf(p: f64, a: f64, b: f64) -> f64 {
    if !(a > 0.0 && b > 0.0 && (0.0..=1.0).contains(&p)) {
        return f64::NAN;
    }
    let (mut lo, mut hi) = (0.0_f64, 1.0_f64);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if mid <= lo || mid >= hi {
            break;
        }
        if beta_inc(a, b, mid) < p {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// Average ranks (1-based, ties share their mean rank) of all values.
fn average_ranks(x: &[f64]) -> Vec<f64> {
    let mut idx: Vec<usize> = (0..x.len()).collect();
    idx.sort_by(|&a, &b| x[a].total_cmp(&x[b]));
    let mut r = vec![0.0; x.len()];
    let mut i = 0;
    while i < idx.len() {
        let mut j = i;
        while j + 1 < idx.len() && x[idx[j + 1]] == x[idx[i]] {
            j += 1;
        }
        let avg = (i + j) as f64 / 2.0 + 1.0;
        for &k in &idx[i..=j] {
            r[k] = avg;
        }
        i = j + 1;
    }
    r
}

/// Rank normalisation of all draws together: `Phi^-1((r - 3/8) / (S + 1/4))`.
fn z_scale(c: &Chains) -> Chains {
    let s = c.x.len() as f64;
    let r = average_ranks(&c.x);
    Chains {
        m: c.m,
        n: c.n,
        x: r.iter()
            .map(|&ri| norm_ppf((ri - 0.375) / (s + 0.25)))
            .collect(),
    }
}

/// Classic R-hat of (already split) chains.
fn rhat_core(c: &Chains) -> f64 {
    let n = c.n as f64;
    let means: Vec<f64> = (0..c.m).map(|j| mean(c.chain(j))).collect();
    let w = (0..c.m).map(|j| var(c.chain(j), 1)).sum::<f64>() / c.m as f64;
    let b = n * var(&means, 1);
    ((b / w + n - 1.0) / n).sqrt()
}

/// Autocovariance of one chain at lags `0..n` (divisor `n`), by FFT with zero padding to `2n`.
fn autocov(x: &[f64], planner: &mut FftPlanner<f64>) -> Vec<f64> {
    let n = x.len();
    let mu = mean(x);
    let len = 2 * n;
    let mut buf: Vec<Complex<f64>> = x
        .iter()
        .map(|&v| Complex::new(v - mu, 0.0))
        .chain(std::iter::repeat_n(Complex::new(0.0, 0.0), len - n))
        .collect();
    planner.plan_fft_forward(len).process(&mut buf);
    for z in buf.iter_mut() {
        *z = Complex::new(z.norm_sqr(), 0.0);
    }
    planner.plan_fft_inverse(len).process(&mut buf);
    buf[..n].iter().map(|z| z.re / (len * n) as f64).collect()
}

/// ESS of (already split or transformed) chains by Geyer's initial monotone sequence.
fn ess_core(c: &Chains) -> f64 {
    let size = c.x.len() as f64;
    let (lo, hi) =
        c.x.iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
                (lo.min(v), hi.max(v))
            });
    // numpy's float64 resolution (1e-15): constant input has ESS equal to the number of draws.
    if hi - lo < 1e-15 {
        return size;
    }
    let (m, n) = (c.m, c.n);
    let nf = n as f64;
    let mut planner = FftPlanner::new();
    let acov: Vec<Vec<f64>> = (0..m).map(|j| autocov(c.chain(j), &mut planner)).collect();
    let mean_acov = |t: usize| acov.iter().map(|a| a[t]).sum::<f64>() / m as f64;
    let means: Vec<f64> = (0..m).map(|j| mean(c.chain(j))).collect();
    let mean_var = mean_acov(0) * nf / (nf - 1.0);
    let mut var_plus = mean_var * (nf - 1.0) / nf;
    if m > 1 {
        var_plus += var(&means, 1);
    }
    let rho = |t: usize| 1.0 - (mean_var - mean_acov(t)) / var_plus;

    let mut rho_t = vec![0.0; n];
    let mut rho_even = 1.0;
    rho_t[0] = rho_even;
    let mut rho_odd = rho(1);
    rho_t[1] = rho_odd;
    // Initial positive sequence.
    let mut t: usize = 1;
    while t + 3 < n && rho_even + rho_odd > 0.0 {
        rho_even = rho(t + 1);
        rho_odd = rho(t + 2);
        if rho_even + rho_odd >= 0.0 {
            rho_t[t + 1] = rho_even;
            rho_t[t + 2] = rho_odd;
        }
        t += 2;
    }
    // max_t = t - 2 may be -1: hold max_t + 1 instead.
    let max_t1 = t - 1;
    if rho_even > 0.0 {
        rho_t[max_t1] = rho_even;
    }
    // Initial monotone sequence.
    let mut t = 1;
    while t + 3 <= max_t1 {
        if rho_t[t + 1] + rho_t[t + 2] > rho_t[t - 1] + rho_t[t] {
            rho_t[t + 1] = (rho_t[t - 1] + rho_t[t]) / 2.0;
            rho_t[t + 2] = rho_t[t + 1];
        }
        t += 2;
    }
    let ess = m as f64 * nf;
    let tau = -1.0 + 2.0 * rho_t[..max_t1].iter().sum::<f64>() + rho_t[max_t1];
    let tau = tau.max(1.0 / ess.log10());
    if rho_t.iter().any(|v| v.is_nan()) {
        return f64::NAN;
    }
    ess / tau
}

fn indicator(c: &Chains, q: f64) -> Chains {
    c.map(|v| if v <= q { 1.0 } else { 0.0 })
}

fn ess_quantile_c(c: &Chains, p: f64) -> f64 {
    if !c.valid(1) {
        return f64::NAN;
    }
    let q = quantile_sorted(&sorted(&c.x), p);
    ess_core(&indicator(c, q).split())
}

fn ess_mean_c(c: &Chains) -> f64 {
    if !c.valid(1) {
        return f64::NAN;
    }
    ess_core(&c.split())
}

fn check_prob(p: f64) -> Result<(), DiagnosticsError> {
    if p > 0.0 && p < 1.0 {
        Ok(())
    } else {
        Err(DiagnosticsError::BadProbability(p))
    }
}

/// Rank-normalised split R-hat, max of bulk and tail (`az.rhat(method="rank")`).
///
/// NaN with fewer than 2 chains or 4 draws, any NaN draw, or constant draws (as ArviZ). When
/// only the tail R-hat is NaN the bulk one is returned (and vice versa NaN), as ArviZ's `max`.
pub fn rhat(draws: &[Vec<f64>]) -> Result<f64, DiagnosticsError> {
    let c = Chains::from_draws(draws)?;
    if !c.valid(2) {
        return Ok(f64::NAN);
    }
    let s = c.split();
    let bulk = rhat_core(&z_scale(&s));
    let med = quantile_sorted(&sorted(&s.x), 0.5);
    let tail = rhat_core(&z_scale(&s.map(|v| (v - med).abs())));
    // Python's max(bulk, tail): the first unless the second is strictly greater.
    Ok(if tail > bulk { tail } else { bulk })
}

/// Bulk ESS: ESS of the rank-normalised split chains (`az.ess(method="bulk")`).
pub fn ess_bulk(draws: &[Vec<f64>]) -> Result<f64, DiagnosticsError> {
    let c = Chains::from_draws(draws)?;
    if !c.valid(1) {
        return Ok(f64::NAN);
    }
    Ok(ess_core(&z_scale(&c.split())))
}

/// Tail ESS: min of the ESS of the 5 % and 95 % quantile indicators (`az.ess(method="tail")`).
pub fn ess_tail(draws: &[Vec<f64>]) -> Result<f64, DiagnosticsError> {
    let c = Chains::from_draws(draws)?;
    let q05 = ess_quantile_c(&c, 0.05);
    let q95 = ess_quantile_c(&c, 0.95);
    // Python's min(q05, q95).
    Ok(if q95 < q05 { q95 } else { q05 })
}

/// ESS of the mean: ESS of the split chains (`az.ess(method="mean")`).
pub fn ess_mean(draws: &[Vec<f64>]) -> Result<f64, DiagnosticsError> {
    Ok(ess_mean_c(&Chains::from_draws(draws)?))
}

/// ESS of the quantile `p` (`az.ess(method="quantile", prob=p)`).
pub fn ess_quantile(draws: &[Vec<f64>], p: f64) -> Result<f64, DiagnosticsError> {
    check_prob(p)?;
    Ok(ess_quantile_c(&Chains::from_draws(draws)?, p))
}

fn mcse_mean_c(c: &Chains) -> f64 {
    if !c.valid(1) {
        return f64::NAN;
    }
    var(&c.x, 1).sqrt() / ess_mean_c(c).sqrt()
}

fn mcse_sd_c(c: &Chains) -> f64 {
    if !c.valid(1) {
        return f64::NAN;
    }
    let mu = mean(&c.x);
    let d = c.map(|v| (v - mu) * (v - mu));
    let ess = ess_mean_c(&d);
    let evar = mean(&d.x);
    let varvar = (d.x.iter().map(|v| v * v).sum::<f64>() / d.x.len() as f64 - evar * evar) / ess;
    (varvar / evar / 4.0).sqrt()
}

fn mcse_quantile_c(c: &Chains, p: f64) -> f64 {
    if !c.valid(1) {
        return f64::NAN;
    }
    let ess = ess_quantile_c(c, p);
    let (a, b) = (ess * p + 1.0, ess * (1.0 - p) + 1.0);
    let s = sorted(&c.x);
    let size = s.len() as f64;
    // 1-based order statistics max(floor(S a1), 1) and min(ceil(S a2), S).
    let lo = (beta_ppf(0.158_655_3, a, b) * size).floor();
    let hi = (beta_ppf(0.841_344_7, a, b) * size).ceil();
    let lo = if lo.is_nan() { 1.0 } else { lo.max(1.0) };
    let hi = if hi.is_nan() { size } else { hi.min(size) };
    (s[hi as usize - 1] - s[lo as usize - 1]) / 2.0
}

/// MCSE of the mean: `sd / sqrt(ESS_mean)` (`az.mcse(method="mean")`).
pub fn mcse_mean(draws: &[Vec<f64>]) -> Result<f64, DiagnosticsError> {
    Ok(mcse_mean_c(&Chains::from_draws(draws)?))
}

/// MCSE of the standard deviation (`az.mcse(method="sd")`); NaN for constant draws.
pub fn mcse_sd(draws: &[Vec<f64>]) -> Result<f64, DiagnosticsError> {
    Ok(mcse_sd_c(&Chains::from_draws(draws)?))
}

/// MCSE of the quantile `p` (`az.mcse(method="quantile", prob=p)`).
pub fn mcse_quantile(draws: &[Vec<f64>], p: f64) -> Result<f64, DiagnosticsError> {
    check_prob(p)?;
    Ok(mcse_quantile_c(&Chains::from_draws(draws)?, p))
}

/// Highest-density interval of probability `hdi_prob` of all chains pooled, for a unimodal
/// distribution (`az.hdi(x, hdi_prob)`): `(lower, upper)`. NaNs when a draw is NaN.
pub fn hdi(draws: &[Vec<f64>], hdi_prob: f64) -> Result<(f64, f64), DiagnosticsError> {
    check_prob(hdi_prob)?;
    let c = Chains::from_draws(draws)?;
    hdi_sorted(&sorted(&c.x), hdi_prob, c.x.iter().any(|v| v.is_nan()))
}

fn hdi_sorted(s: &[f64], p: f64, has_nan: bool) -> Result<(f64, f64), DiagnosticsError> {
    if s.is_empty() {
        return Err(DiagnosticsError::NoDraws);
    }
    if has_nan {
        return Ok((f64::NAN, f64::NAN));
    }
    let k = (p * s.len() as f64).floor() as usize;
    let mut best = 0;
    let mut width = f64::INFINITY;
    for i in 0..s.len() - k {
        let w = s[i + k] - s[i];
        if w < width {
            width = w;
            best = i;
        }
    }
    Ok((s[best], s[best + k]))
}

/// E-BFMI of each chain of NUTS energies (`az.bfmi`): `sum diff(E)^2 / sum (E - mean E)^2`.
/// NaN for a chain of fewer than 2 draws.
pub fn bfmi(energy: &[Vec<f64>]) -> Result<Vec<f64>, DiagnosticsError> {
    let c = Chains::from_draws(energy)?;
    Ok((0..c.m)
        .map(|j| {
            let e = c.chain(j);
            if e.len() < 2 {
                return f64::NAN;
            }
            let num = e.windows(2).map(|w| (w[1] - w[0]).powi(2)).sum::<f64>();
            let mu = mean(e);
            num / e.iter().map(|v| (v - mu).powi(2)).sum::<f64>()
        })
        .collect())
}

/// The HDI probability [`summarize`] uses: ArviZ's default `stats.hdi_prob`.
pub const DEFAULT_HDI_PROB: f64 = 0.94;

/// Posterior summary of one scalar quantity, all chains pooled for the moments and intervals.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Summary {
    /// Mean of all draws.
    pub mean: f64,
    /// Standard deviation of all draws (ddof 1).
    pub sd: f64,
    /// Median (quantile 0.5).
    pub median: f64,
    /// Quantile 0.025 (numpy's linear interpolation, as all quantiles here).
    pub q2_5: f64,
    /// Quantile 0.975.
    pub q97_5: f64,
    /// Quantile 0.05.
    pub q5: f64,
    /// Quantile 0.95.
    pub q95: f64,
    /// Probability of the HDI below.
    pub hdi_prob: f64,
    /// Lower end of the HDI.
    pub hdi_lower: f64,
    /// Upper end of the HDI.
    pub hdi_upper: f64,
    /// Rank-normalised split R-hat ([`rhat`]).
    pub r_hat: f64,
    /// Bulk ESS ([`ess_bulk`]).
    pub ess_bulk: f64,
    /// Tail ESS ([`ess_tail`]).
    pub ess_tail: f64,
    /// MCSE of the mean ([`mcse_mean`]).
    pub mcse_mean: f64,
    /// MCSE of the sd ([`mcse_sd`]).
    pub mcse_sd: f64,
}

/// Summary of one quantity `draws[chain][draw]` with the HDI at `hdi_prob`.
pub fn summary(draws: &[Vec<f64>], hdi_prob: f64) -> Result<Summary, DiagnosticsError> {
    check_prob(hdi_prob)?;
    let c = Chains::from_draws(draws)?;
    let s = sorted(&c.x);
    let has_nan = c.x.iter().any(|v| v.is_nan());
    let q = |p: f64| {
        if has_nan {
            f64::NAN
        } else {
            quantile_sorted(&s, p)
        }
    };
    let (hdi_lower, hdi_upper) = hdi_sorted(&s, hdi_prob, has_nan)?;
    Ok(Summary {
        mean: mean(&c.x),
        sd: if c.x.len() > 1 {
            var(&c.x, 1).sqrt()
        } else {
            f64::NAN
        },
        median: q(0.5),
        q2_5: q(0.025),
        q97_5: q(0.975),
        q5: q(0.05),
        q95: q(0.95),
        hdi_prob,
        hdi_lower,
        hdi_upper,
        r_hat: rhat(draws)?,
        ess_bulk: ess_bulk(draws)?,
        ess_tail: ess_tail(draws)?,
        mcse_mean: mcse_mean_c(&c),
        mcse_sd: mcse_sd_c(&c),
    })
}

/// [`summary`] of every parameter `draws_by_param[param][chain][draw]`, HDI at
/// [`DEFAULT_HDI_PROB`] (94 %, as ArviZ).
pub fn summarize(draws_by_param: &[Vec<Vec<f64>>]) -> Result<Vec<Summary>, DiagnosticsError> {
    summarize_with_hdi(draws_by_param, DEFAULT_HDI_PROB)
}

/// [`summarize`] with the HDI at `hdi_prob`.
pub fn summarize_with_hdi(
    draws_by_param: &[Vec<Vec<f64>>],
    hdi_prob: f64,
) -> Result<Vec<Summary>, DiagnosticsError> {
    draws_by_param
        .iter()
        .map(|d| summary(d, hdi_prob))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, StandardNormal};

    fn normal_chains(m: usize, n: usize, seed: u64, shift: f64) -> Vec<Vec<f64>> {
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        (0..m)
            .map(|j| {
                (0..n)
                    .map(|_| {
                        let z: f64 = StandardNormal.sample(&mut rng);
                        z + shift * j as f64
                    })
                    .collect()
            })
            .collect()
    }

    #[test]
    fn iid_chains_have_rhat_near_one_and_ess_near_n() {
        let d = normal_chains(4, 2000, 7, 0.0);
        let r = rhat(&d).unwrap();
        assert!((r - 1.0).abs() < 0.01, "rhat {r}");
        for (name, e) in [
            ("bulk", ess_bulk(&d).unwrap()),
            ("mean", ess_mean(&d).unwrap()),
        ] {
            assert!((e / 8000.0 - 1.0).abs() < 0.1, "ess {name} {e}");
        }
        let t = ess_tail(&d).unwrap();
        assert!(t > 0.7 * 8000.0 && t < 1.3 * 8000.0, "ess tail {t}");
        // MCSE of the mean of iid N(0,1): 1/sqrt(S).
        let m = mcse_mean(&d).unwrap();
        assert!((m * 8000f64.sqrt() - 1.0).abs() < 0.1, "mcse {m}");
        // MCSE of the sd of iid N(0,1): about 1/sqrt(2 S).
        let s = mcse_sd(&d).unwrap();
        assert!((s * 16000f64.sqrt() - 1.0).abs() < 0.15, "mcse sd {s}");
    }

    #[test]
    fn shifted_chains_have_large_rhat() {
        let d = normal_chains(4, 500, 3, 1.0);
        let r = rhat(&d).unwrap();
        assert!(r > 1.2, "rhat {r}");
    }

    #[test]
    fn ar1_ess_matches_the_integrated_autocorrelation_time() {
        // AR(1) with phi: tau = (1 + phi) / (1 - phi) = 39 for phi = 0.95.
        let phi: f64 = 0.95;
        let mut rng = rand::rngs::StdRng::seed_from_u64(11);
        let d: Vec<Vec<f64>> = (0..4)
            .map(|_| {
                let mut x = 0.0;
                (0..20_000)
                    .map(|_| {
                        let z: f64 = StandardNormal.sample(&mut rng);
                        x = phi * x + (1.0 - phi * phi).sqrt() * z;
                        x
                    })
                    .collect()
            })
            .collect();
        let expect = 80_000.0 * (1.0 - phi) / (1.0 + phi);
        let e = ess_mean(&d).unwrap();
        assert!((e / expect - 1.0).abs() < 0.2, "ess {e} vs {expect}");
    }

    #[test]
    fn quantile_and_hdi_of_known_samples() {
        let x: Vec<f64> = (0..11).map(|i| i as f64).collect();
        assert_eq!(quantile(&x, 0.5), 5.0);
        assert!((quantile(&x, 0.05) - 0.5).abs() < 1e-15);
        assert!((quantile(&[1.0, 2.0], 0.25) - 1.25).abs() < 1e-15);
        // Skewed sample: 0..9 dense then 100: the 90 % HDI (k = 9) is [0, 9].
        let mut y: Vec<f64> = (0..10).map(|i| i as f64).collect();
        y.push(100.0);
        assert_eq!(hdi(&[y], 0.9).unwrap(), (0.0, 9.0));
    }

    #[test]
    fn special_functions() {
        for (p, z) in [
            (0.5, 0.0),
            (0.975, 1.959_963_984_540_054),
            (0.001, -3.090_232_306_167_813_6),
            (1e-10, -6.361_340_902_404_056),
        ] {
            assert!((norm_ppf(p) - z).abs() < 1e-14 * (1.0 + z.abs()), "{p}");
        }
        // Beta(2, 3): I_x = 1 - (1-x)^3 (1 + 3x); at x = 0.4: 1 - 0.216 * 2.2 = 0.5248.
        assert!((beta_inc(2.0, 3.0, 0.4) - 0.5248).abs() < 1e-14);
        assert!((beta_ppf(0.5248, 2.0, 3.0) - 0.4).abs() < 1e-14);
    }

    #[test]
    fn bfmi_of_a_random_walk_is_small_and_of_iid_near_two() {
        let d = normal_chains(1, 20_000, 5, 0.0);
        let b = bfmi(&d).unwrap()[0];
        assert!((b - 2.0).abs() < 0.05, "iid bfmi {b}");
        let walk: Vec<f64> = d[0]
            .iter()
            .scan(0.0, |s, z| {
                *s += z;
                Some(*s)
            })
            .collect();
        assert!(bfmi(&[walk]).unwrap()[0] < 0.01);
    }

    #[test]
    fn edge_cases_give_nan_not_panics() {
        let c = vec![vec![1.5; 100]; 4];
        assert!(rhat(&c).unwrap().is_nan());
        assert_eq!(ess_bulk(&c).unwrap(), 400.0);
        assert_eq!(mcse_mean(&c).unwrap(), 0.0);
        assert!(mcse_sd(&c).unwrap().is_nan());
        let short = normal_chains(2, 3, 1, 0.0);
        assert!(rhat(&short).unwrap().is_nan());
        assert!(ess_bulk(&short).unwrap().is_nan());
        assert!(ess_tail(&short).unwrap().is_nan());
        assert!(mcse_quantile(&short, 0.05).unwrap().is_nan());
        let one = normal_chains(1, 100, 1, 0.0);
        assert!(rhat(&one).unwrap().is_nan());
        assert!(ess_bulk(&one).unwrap() > 10.0);
        assert!(matches!(
            rhat(&[vec![1.0; 5], vec![1.0; 4]]),
            Err(DiagnosticsError::RaggedChains { chain: 1, .. })
        ));
        assert_eq!(rhat(&[]), Err(DiagnosticsError::NoChains));
        assert!(summarize(&[short]).is_ok());
        let s = summary(&[vec![]], 0.9);
        assert_eq!(s, Err(DiagnosticsError::NoDraws));
    }
}
