//! Small dense Cholesky helpers on row-major `d x d` slices, for the few-parameter matrices
//! of the inference (Hessians, covariances, Levenberg-Marquardt normal equations).
//!
//! These stay hand-written loops while the other dense factorisations of the crate are faer's:
//! faer's blocked Cholesky rounds differently in the last bits, and on `studies/bayes.toml` that
//! moved Model 5's three evidence estimates together by +0.66 nats at L1 and -1.88 nats at L2
//! (Models 3 and 4 by less than 1e-7 nats; Model 5's fit is 5e5 nats short of Model 4's), a
//! sensitivity to rounding of that model's evidence, not a better value.

/// Cholesky of a symmetric d x d matrix (row-major); None when not positive definite (or not
/// finite).
pub fn cholesky(a: &[f64], d: usize) -> Option<Vec<f64>> {
    let mut l = vec![0.0; d * d];
    for i in 0..d {
        for j in 0..=i {
            let mut s = a[i * d + j];
            for k in 0..j {
                s -= l[i * d + k] * l[j * d + k];
            }
            if i == j {
                if !(s > 0.0) || !s.is_finite() {
                    return None;
                }
                l[i * d + i] = s.sqrt();
            } else {
                l[i * d + j] = s / l[j * d + j];
            }
        }
    }
    Some(l)
}

/// Solve `L L^T x = b`.
pub fn chol_solve(l: &[f64], d: usize, b: &[f64]) -> Vec<f64> {
    let mut y = b.to_vec();
    for i in 0..d {
        for k in 0..i {
            y[i] -= l[i * d + k] * y[k];
        }
        y[i] /= l[i * d + i];
    }
    for i in (0..d).rev() {
        for k in i + 1..d {
            y[i] -= l[k * d + i] * y[k];
        }
        y[i] /= l[i * d + i];
    }
    y
}

/// Inverse of a positive definite matrix from its Cholesky factor.
pub fn chol_inverse(l: &[f64], d: usize) -> Vec<f64> {
    let mut inv = vec![0.0; d * d];
    for j in 0..d {
        let mut e = vec![0.0; d];
        e[j] = 1.0;
        let c = chol_solve(l, d, &e);
        for i in 0..d {
            inv[i * d + j] = c[i];
        }
    }
    inv
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A symmetric positive definite 4 x 4 matrix with a condition number of about 1e3.
    fn spd() -> Vec<f64> {
        let b = [
            [2.0, 0.1, -0.3, 0.0],
            [0.4, 1.0, 0.2, -0.1],
            [0.0, 0.3, 0.05, 0.2],
            [-0.2, 0.0, 0.1, 0.7],
        ];
        let d = 4;
        let mut a = vec![0.0; d * d];
        for i in 0..d {
            for j in 0..d {
                a[i * d + j] = (0..d).map(|k| b[i][k] * b[j][k]).sum::<f64>();
            }
            a[i * d + i] += 1e-3;
        }
        a
    }

    #[test]
    fn factor_reproduces_the_matrix_and_solves_and_inverts_it() {
        let (a, d) = (spd(), 4);
        let l = cholesky(&a, d).unwrap();
        for i in 0..d {
            for j in 0..d {
                let llt: f64 = (0..d).map(|k| l[i * d + k] * l[j * d + k]).sum();
                assert!((llt - a[i * d + j]).abs() < 1e-14, "({i}, {j}) {llt}");
                if j > i {
                    assert_eq!(l[i * d + j], 0.0);
                }
            }
        }
        let b = [1.0, -2.0, 0.5, 3.0];
        let x = chol_solve(&l, d, &b);
        for i in 0..d {
            let ax: f64 = (0..d).map(|k| a[i * d + k] * x[k]).sum();
            assert!(
                (ax - b[i]).abs() < 1e-10 * b[i].abs().max(1.0),
                "row {i}: {ax}"
            );
        }
        let inv = chol_inverse(&l, d);
        for i in 0..d {
            for j in 0..d {
                let e: f64 = (0..d).map(|k| a[i * d + k] * inv[k * d + j]).sum();
                let want = if i == j { 1.0 } else { 0.0 };
                assert!((e - want).abs() < 1e-10, "({i}, {j}) {e}");
                assert!((inv[i * d + j] - inv[j * d + i]).abs() < 1e-12 * inv[i * d + i].abs());
            }
        }
    }

    #[test]
    fn indefinite_singular_and_non_finite_matrices_have_no_factor() {
        assert!(cholesky(&[1.0, 2.0, 2.0, 1.0], 2).is_none());
        assert!(cholesky(&[1.0, 1.0, 1.0, 1.0], 2).is_none());
        assert!(cholesky(&[0.0], 1).is_none());
        assert!(cholesky(&[f64::NAN, 0.0, 0.0, 1.0], 2).is_none());
        assert!(cholesky(&[1.0, 0.0, f64::INFINITY, 1.0], 2).is_none());
        // The upper triangle is not read.
        assert!(cholesky(&[4.0, f64::NAN, 2.0, 5.0], 2).is_some());
    }
}
