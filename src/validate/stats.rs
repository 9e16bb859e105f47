//! Small distribution functions of the validation's acceptance tests: the chi-square upper
//! tail ([`crate::inference::special`]), Pearson's uniformity test and the binomial central band.

pub use crate::inference::special::{chi2_sf, gamma_q};

/// Pearson's chi-square test of uniformity of `counts` (equal expected counts): the
/// statistic, its degrees of freedom and p-value.
pub fn uniformity(counts: &[usize]) -> (f64, usize, f64) {
    let n: usize = counts.iter().sum();
    let b = counts.len();
    if b < 2 || n == 0 {
        return (f64::NAN, b.saturating_sub(1), f64::NAN);
    }
    let e = n as f64 / b as f64;
    let stat: f64 = counts.iter().map(|&c| (c as f64 - e).powi(2) / e).sum();
    (stat, b - 1, chi2_sf(stat, (b - 1) as f64))
}

/// `P(X <= k)` for `X ~ Binomial(n, p)`.
pub fn binom_cdf(k: usize, n: usize, p: f64) -> f64 {
    let lnc = |j: usize| {
        libm::lgamma(n as f64 + 1.0)
            - libm::lgamma(j as f64 + 1.0)
            - libm::lgamma((n - j) as f64 + 1.0)
    };
    (0..=k.min(n))
        .map(|j| (lnc(j) + j as f64 * p.ln() + (n - j) as f64 * (1.0 - p).ln()).exp())
        .sum::<f64>()
        .min(1.0)
}

/// Central band holding `X ~ Binomial(n, p)` with probability at least `prob`: the
/// `(1 - prob) / 2` and `(1 + prob) / 2` quantiles (smallest `k` with `P(X <= k) >= q`,
/// as scipy's `binom.ppf`).
pub fn binom_band(n: usize, p: f64, prob: f64) -> (usize, usize) {
    let ppf = |q: f64| {
        (0..=n)
            .find(|&k| binom_cdf(k, n, p) >= q * (1.0 - 1e-12))
            .unwrap_or(n)
    };
    (ppf((1.0 - prob) / 2.0), ppf((1.0 + prob) / 2.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn binomial_band_sums_to_its_probability() {
        let (lo, hi) = binom_band(200, 0.95, 0.99);
        assert!(binom_cdf(hi, 200, 0.95) >= 0.995);
        assert!(binom_cdf(hi - 1, 200, 0.95) < 0.995);
        assert!(binom_cdf(lo, 200, 0.95) >= 0.005);
        assert!(binom_cdf(lo - 1, 200, 0.95) < 0.005);
        assert!((binom_cdf(200, 200, 0.3) - 1.0).abs() < 1e-12);
    }
}
