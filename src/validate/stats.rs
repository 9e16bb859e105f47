//! Small distribution functions of the validation's acceptance tests: the chi-square upper
//! tail (regularised incomplete gamma, Numerical Recipes' series and Lentz continued fraction,
//! written from the definitions) and the binomial central band.

/// `Q(a, x) = Gamma(a, x) / Gamma(a)`, the regularised upper incomplete gamma function.
pub fn gamma_q(a: f64, x: f64) -> f64 {
    if !(a > 0.0) || x < 0.0 || x.is_nan() {
        return f64::NAN;
    }
    if x == 0.0 {
        return 1.0;
    }
    let ln_pre = a * x.ln() - x - libm::lgamma(a);
    if x < a + 1.0 {
        // P(a, x) = x^a e^-x / Gamma(a) sum_n x^n / (a (a+1) ... (a+n)).
        let (mut term, mut sum, mut ap) = (1.0 / a, 1.0 / a, a);
        for _ in 0..10_000 {
            ap += 1.0;
            term *= x / ap;
            sum += term;
            if term.abs() < sum.abs() * 1e-16 {
                break;
            }
        }
        1.0 - sum * ln_pre.exp()
    } else {
        // Q(a, x) = x^a e^-x / Gamma(a) * 1 / (x + 1 - a - 1 (1 - a) / (x + 3 - a - ...)).
        let tiny = 1e-300;
        let mut b = x + 1.0 - a;
        let mut c = 1.0 / tiny;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..10_000 {
            let an = -(i as f64) * (i as f64 - a);
            b += 2.0;
            d = an * d + b;
            if d.abs() < tiny {
                d = tiny;
            }
            c = b + an / c;
            if c.abs() < tiny {
                c = tiny;
            }
            d = 1.0 / d;
            let del = d * c;
            h *= del;
            if (del - 1.0).abs() < 1e-16 {
                break;
            }
        }
        ln_pre.exp() * h
    }
}

/// Upper-tail p-value of a chi-square statistic with `dof` degrees of freedom.
pub fn chi2_sf(stat: f64, dof: f64) -> f64 {
    gamma_q(dof / 2.0, stat / 2.0)
}

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
    fn chi_square_tail_matches_closed_forms() {
        // dof 2: Q = exp(-x / 2); dof 1: Q = erfc(sqrt(x / 2)).
        for x in [0.1, 1.0, 3.0, 10.0, 40.0] {
            assert!((chi2_sf(x, 2.0) - (-x / 2.0f64).exp()).abs() < 1e-13);
            assert!((chi2_sf(x, 1.0) - libm::erfc((x / 2.0f64).sqrt())).abs() < 1e-12);
        }
        // dof 4: Q = exp(-x/2) (1 + x/2).
        for x in [0.5, 2.0, 9.0, 30.0] {
            let q = (-x / 2.0f64).exp() * (1.0 + x / 2.0);
            assert!((chi2_sf(x, 4.0) - q).abs() < 1e-13, "{x}");
        }
    }

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
