//! Is a residual scatter or systematic? Statistics of a residual sequence ordered by frequency.
//!
//! * Runs test (Wald and Wolfowitz 1940): the number of runs of equal sign among the `n+`
//!   positive and `n-` negative residuals has mean `1 + 2 n+ n- / n` and variance
//!   `2 n+ n- (2 n+ n- - n) / (n^2 (n - 1))`; too few runs (z < 0) means the residual follows
//!   a trend in frequency. Two-sided p-value from the normal approximation.
//! * Scatter from successive differences (von Neumann 1941): `s_d^2 = sum (r_{i+1} - r_i)^2 /
//!   (2 (n - 1))` estimates the point-to-point scatter without the smooth part of the residual;
//!   the normalised chi-square `mean(r^2) / s_d^2` is about 1 for white residuals and grows
//!   with the systematic part.
//! * The lag-1 autocorrelation.

use libm::erfc;

/// Statistics of one residual sequence.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ResidualStats {
    pub n: usize,
    /// RMS of the residual.
    pub rms: f64,
    pub runs: usize,
    pub runs_expected: f64,
    /// (runs - expected) / sd.
    pub runs_z: f64,
    /// Two-sided p-value of the runs test.
    pub runs_p: f64,
    /// Scatter estimated from successive differences.
    pub scatter_sd: f64,
    /// mean(r^2) / scatter_sd^2.
    pub chi2_norm: f64,
    pub lag1_autocorrelation: f64,
}

impl ResidualStats {
    /// "systematic" when the runs test rejects randomness at 1 % (too few runs), else "scatter".
    pub fn verdict(&self) -> &'static str {
        if self.is_systematic() {
            "systematic"
        } else {
            "scatter"
        }
    }
    pub fn is_systematic(&self) -> bool {
        self.runs_p < 0.01 && self.runs_z < 0.0
    }
}

/// The statistics of `r` (ordered by frequency; at least 3 values).
pub fn residual_stats(r: &[f64]) -> ResidualStats {
    let n = r.len();
    let nf = n as f64;
    let rms = (r.iter().map(|v| v * v).sum::<f64>() / nf).sqrt();
    let np = r.iter().filter(|v| **v > 0.0).count() as f64;
    let nm = nf - np;
    let runs = 1 + r
        .windows(2)
        .filter(|w| (w[0] > 0.0) != (w[1] > 0.0))
        .count();
    let mean = 1.0 + 2.0 * np * nm / nf;
    let var = 2.0 * np * nm * (2.0 * np * nm - nf) / (nf * nf * (nf - 1.0));
    let z = if var > 0.0 {
        (runs as f64 - mean) / var.sqrt()
    } else {
        0.0
    };
    let p = erfc(z.abs() / std::f64::consts::SQRT_2);
    let sd2 = r.windows(2).map(|w| (w[1] - w[0]).powi(2)).sum::<f64>() / (2.0 * (nf - 1.0));
    let m = r.iter().sum::<f64>() / nf;
    let c0: f64 = r.iter().map(|v| (v - m).powi(2)).sum();
    let c1: f64 = r.windows(2).map(|w| (w[0] - m) * (w[1] - m)).sum();
    ResidualStats {
        n,
        rms,
        runs,
        runs_expected: mean,
        runs_z: z,
        runs_p: p,
        scatter_sd: sd2.sqrt(),
        chi2_norm: if sd2 > 0.0 {
            rms * rms / sd2
        } else {
            f64::INFINITY
        },
        lag1_autocorrelation: if c0 > 0.0 { c1 / c0 } else { 0.0 },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn alternating_and_trending_sequences() {
        // A smooth trend: 2 runs, z strongly negative, chi2_norm large.
        let trend: Vec<f64> = (0..100).map(|i| (i as f64 - 49.5) / 50.0).collect();
        let s = residual_stats(&trend);
        assert_eq!(s.runs, 2);
        assert!(s.is_systematic() && s.chi2_norm > 100.0);
        // Hand count: [1, -1, -1, 1, 1, 1, -1] has 4 runs; n+ = 4, n- = 3, mean 1 + 24/7.
        let s = residual_stats(&[1.0, -1.0, -1.0, 1.0, 1.0, 1.0, -1.0]);
        assert_eq!(s.runs, 4);
        assert!((s.runs_expected - (1.0 + 24.0 / 7.0)).abs() < 1e-12);
    }
}
