//! Parameter redundancy: the singular value decomposition of the scaled sensitivity, the
//! posterior correlation matrix and per-parameter identifiability.
//!
//! With `r_o(p)` the whitened residuals (real and imaginary parts of `(E[H1]_o - X_o) /
//! sqrt(v_o)`), the scaled sensitivity is `S_ok = dr_o / d ln p_k = p_k dE[H1]_o/dp_k /
//! sqrt(v_o)`: dimensionless, and `S^T S` is the Fisher information of the Gaussian
//! likelihood in `ln p`. Its SVD `S = U Sigma V^T` gives the combinations `v_i` of relative
//! parameter changes the data determine to a standard deviation `1 / sigma_i` (Brun, Reichert
//! and Kunsch 2001, "Practical identifiability analysis of large environmental simulation
//! models", Water Resour. Res. 37(4): collinearity index `1 / sigma_min` of the normalised
//! sensitivity). The condition number is `sigma_max / sigma_min`; the weakest direction
//! `v_min` is the parameter combination the data cannot separate.
//!
//! Identifiability per parameter: posterior sd over prior sd in the sampler's unconstrained
//! coordinates (1 = the data taught nothing, small = well identified).

use super::prior::Prior;

/// The SVD of a scaled sensitivity.
#[derive(Clone, Debug, PartialEq)]
pub struct SensitivitySvd {
    /// Nonincreasing.
    pub singular_values: Vec<f64>,
    /// Right singular vectors, `v[i][k]`: direction `i` (same order as the singular values)
    /// over parameter `k`, unit length, sign fixed so that its largest entry is positive.
    pub right_vectors: Vec<Vec<f64>>,
    /// `s_max / s_min` (infinite when `s_min` is zero).
    pub condition_number: f64,
}

impl SensitivitySvd {
    /// The weakest direction (smallest singular value).
    pub fn weakest(&self) -> Option<(&f64, &Vec<f64>)> {
        self.singular_values.last().zip(self.right_vectors.last())
    }
}

/// Why the sensitivity's SVD could not be formed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SensitivityError {
    #[error("the sensitivity needs at least as many rows as parameters, all columns of one length (got {columns} columns of {rows} rows)")]
    Shape { columns: usize, rows: usize },
    #[error("the sensitivity has non-finite entries")]
    NonFinite,
    #[error("SVD failed: {0}")]
    Svd(String),
}

/// SVD of `S` given by its columns (`cols[k][row]`, one per parameter).
pub fn sensitivity_svd(cols: &[Vec<f64>]) -> Result<SensitivitySvd, SensitivityError> {
    let d = cols.len();
    let n = cols.first().map_or(0, Vec::len);
    if d == 0 || n < d || cols.iter().any(|c| c.len() != n) {
        return Err(SensitivityError::Shape {
            columns: d,
            rows: n,
        });
    }
    if cols.iter().flatten().any(|v| !v.is_finite()) {
        return Err(SensitivityError::NonFinite);
    }
    let m = faer::Mat::<f64>::from_fn(n, d, |r, k| cols[k][r]);
    let svd = m
        .thin_svd()
        .map_err(|e| SensitivityError::Svd(format!("{e:?}")))?;
    let s: Vec<f64> = svd.S().column_vector().iter().copied().collect();
    let v = svd.V();
    let mut order: Vec<usize> = (0..s.len()).collect();
    order.sort_by(|a, b| s[*b].total_cmp(&s[*a]));
    let singular_values: Vec<f64> = order.iter().map(|&i| s[i]).collect();
    let right_vectors = order
        .iter()
        .map(|&i| {
            let mut col: Vec<f64> = (0..d).map(|k| v[(k, i)]).collect();
            let big = col
                .iter()
                .copied()
                .max_by(|a, b| a.abs().total_cmp(&b.abs()))
                .unwrap_or(1.0);
            if big < 0.0 {
                col.iter_mut().for_each(|x| *x = -*x);
            }
            col
        })
        .collect();
    let smax = singular_values.first().copied().unwrap_or(0.0);
    let smin = singular_values.last().copied().unwrap_or(0.0);
    Ok(SensitivitySvd {
        singular_values,
        right_vectors,
        condition_number: if smin > 0.0 {
            smax / smin
        } else {
            f64::INFINITY
        },
    })
}

/// A direction as text, `+0.71 d ln E0 - 0.70 d ln eta0` (entries below 0.05 left out).
pub fn combination_text(names: &[String], v: &[f64]) -> String {
    let mut s = String::new();
    for (n, x) in names.iter().zip(v) {
        if x.abs() < 0.05 {
            continue;
        }
        if !s.is_empty() {
            s.push(' ');
        }
        s += &format!(
            "{}{:.2} d ln {n}",
            if *x < 0.0 { "-" } else { "+" },
            x.abs()
        );
    }
    s
}

/// Pearson correlation matrix (row-major `d x d`) of the columns `cols[k][draw]`.
pub fn correlation_matrix(cols: &[Vec<f64>]) -> Vec<f64> {
    let d = cols.len();
    let n = cols.first().map_or(0, Vec::len) as f64;
    let means: Vec<f64> = cols.iter().map(|c| c.iter().sum::<f64>() / n).collect();
    let mut cov = vec![0.0; d * d];
    for i in 0..d {
        for j in 0..=i {
            let c: f64 = cols[i]
                .iter()
                .zip(&cols[j])
                .map(|(a, b)| (a - means[i]) * (b - means[j]))
                .sum::<f64>()
                / (n - 1.0);
            cov[i * d + j] = c;
            cov[j * d + i] = c;
        }
    }
    let mut out = vec![0.0; d * d];
    for i in 0..d {
        for j in 0..d {
            out[i * d + j] = cov[i * d + j] / (cov[i * d + i] * cov[j * d + j]).sqrt();
        }
    }
    out
}

/// Standard deviation of a sample.
pub fn sd(v: &[f64]) -> f64 {
    let n = v.len() as f64;
    let m = v.iter().sum::<f64>() / n;
    (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0)).sqrt()
}

/// Prior standard deviation in the unconstrained coordinate, by the midpoint rule on 4000
/// quantiles (pi / sqrt 3 = 1.8138 for the logistic coordinate of a (log-)uniform prior).
pub fn prior_sd_x(p: &Prior) -> f64 {
    let n = 4000;
    let v: Vec<f64> = (0..n)
        .map(|i| p.quantile_x((i as f64 + 0.5) / n as f64))
        .collect();
    let m = v.iter().sum::<f64>() / n as f64;
    (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / n as f64).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    #[test]
    fn svd_finds_a_known_null_direction() {
        // Columns 0 and 1 enter only through their sum (a + b): the direction (1, -1)/sqrt 2
        // has zero singular value; column 2 is independent.
        let mut rng = rand::rngs::StdRng::seed_from_u64(3);
        let n = 50;
        let a: Vec<f64> = (0..n).map(|_| rng.random::<f64>() - 0.5).collect();
        let c: Vec<f64> = (0..n).map(|_| rng.random::<f64>() - 0.5).collect();
        let cols = vec![a.clone(), a.clone(), c];
        let s = sensitivity_svd(&cols).unwrap();
        let (smin, v) = s.weakest().unwrap();
        assert!(*smin < 1e-12 * s.singular_values[0], "{smin}");
        assert!(s.condition_number > 1e10);
        let h = 0.5f64.sqrt();
        assert!(
            (v[0] - h).abs() < 1e-10 && (v[1] + h).abs() < 1e-10 && v[2].abs() < 1e-10,
            "{v:?}"
        );
        let names: Vec<String> = ["E0", "eta0", "E1"].iter().map(|s| s.to_string()).collect();
        assert_eq!(combination_text(&names, v), "+0.71 d ln E0 -0.71 d ln eta0");
        // Singular values are those of the Gram matrix's eigenvalues: sum of squares.
        let fro: f64 = cols.iter().flatten().map(|x| x * x).sum();
        let ss: f64 = s.singular_values.iter().map(|x| x * x).sum();
        assert!((fro - ss).abs() < 1e-10 * fro);
    }

    #[test]
    fn svd_of_a_diagonal_scaling_is_the_scaling() {
        let cols = vec![vec![3.0, 0.0, 0.0, 0.0], vec![0.0, 0.5, 0.0, 0.0]];
        let s = sensitivity_svd(&cols).unwrap();
        assert!((s.singular_values[0] - 3.0).abs() < 1e-12);
        assert!((s.singular_values[1] - 0.5).abs() < 1e-12);
        assert!((s.condition_number - 6.0).abs() < 1e-12);
        assert!((s.right_vectors[1][1] - 1.0).abs() < 1e-12);
        assert!(sensitivity_svd(&[vec![1.0], vec![1.0], vec![1.0]]).is_err());
    }

    #[test]
    fn correlation_of_a_known_bivariate_sample() {
        // y = rho x + sqrt(1 - rho^2) z: correlation rho up to sampling error 1/sqrt(n).
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        let n = 20000;
        let rho = -0.8;
        let mut x = Vec::new();
        let mut y = Vec::new();
        for _ in 0..n {
            let a: f64 = rng.sample(rand_distr::StandardNormal);
            let b: f64 = rng.sample(rand_distr::StandardNormal);
            x.push(a);
            y.push(rho * a + (1.0f64 - rho * rho).sqrt() * b);
        }
        let c = correlation_matrix(&[x, y]);
        assert!((c[0] - 1.0).abs() < 1e-12 && (c[3] - 1.0).abs() < 1e-12);
        assert!((c[1] - rho).abs() < 0.01, "{}", c[1]);
        assert_eq!(c[1], c[2]);
    }

    #[test]
    fn prior_sd_of_the_logistic_coordinate() {
        let p = Prior::LogUniform { lo: 1.0, hi: 100.0 };
        let want = std::f64::consts::PI / 3f64.sqrt();
        assert!((prior_sd_x(&p) - want).abs() < 5e-3, "{}", prior_sd_x(&p));
        let q = Prior::LogNormal {
            median: 5.0,
            sigma_ln: 0.7,
        };
        assert!((prior_sd_x(&q) - 0.7).abs() < 2e-3);
    }
}
