//! Small dense Cholesky helpers on row-major `d x d` slices, for the few-parameter matrices
//! of the inference (Hessians, covariances, Levenberg-Marquardt normal equations). The
//! factorisation and the triangular solves are faer's, run sequentially (`Par::Seq`) so that
//! results are bit-identical whatever the thread count; the slices keep the callers' layout.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::{factor, solve};
use faer::{Conj, Mat, MatRef, Par};

/// Cholesky factor `L` (row-major, zero above the diagonal) of a symmetric d x d matrix
/// (row-major; only its lower triangle is read); None when not positive definite or not
/// finite.
pub fn cholesky(a: &[f64], d: usize) -> Option<Vec<f64>> {
    assert_eq!(a.len(), d * d);
    let lower_finite = (0..d).all(|i| (0..=i).all(|j| a[i * d + j].is_finite()));
    if !lower_finite {
        return None;
    }
    let mut l = Mat::from_fn(d, d, |i, j| if j <= i { a[i * d + j] } else { 0.0 });
    let mut mem = MemBuffer::new(factor::cholesky_in_place_scratch::<f64>(
        d,
        Par::Seq,
        Default::default(),
    ));
    factor::cholesky_in_place(
        l.as_mut(),
        Default::default(),
        Par::Seq,
        MemStack::new(&mut mem),
        Default::default(),
    )
    .ok()?;
    // A pivot of zero, or one that overflowed, is not a factor to solve with.
    if !(0..d).all(|i| l[(i, i)] > 0.0 && l[(i, i)].is_finite()) {
        return None;
    }
    Some(
        (0..d * d)
            .map(|ij| {
                let (i, j) = (ij / d, ij % d);
                if j <= i {
                    l[(i, j)]
                } else {
                    0.0
                }
            })
            .collect(),
    )
}

/// Solve `L L^T X = B` in place for the columns of `b` (d x k).
fn solve_columns(l: &[f64], d: usize, b: &mut Mat<f64>) {
    let l = MatRef::from_row_major_slice(l, d, d);
    let k = b.ncols();
    let mut mem = MemBuffer::new(solve::solve_in_place_scratch::<f64>(d, k, Par::Seq));
    solve::solve_in_place_with_conj(l, Conj::No, b.as_mut(), Par::Seq, MemStack::new(&mut mem));
}

/// Solve `L L^T x = b`.
pub fn chol_solve(l: &[f64], d: usize, b: &[f64]) -> Vec<f64> {
    let mut x = Mat::from_fn(d, 1, |i, _| b[i]);
    solve_columns(l, d, &mut x);
    (0..d).map(|i| x[(i, 0)]).collect()
}

/// Inverse (row-major) of a positive definite matrix from its Cholesky factor.
pub fn chol_inverse(l: &[f64], d: usize) -> Vec<f64> {
    let mut x = Mat::<f64>::identity(d, d);
    solve_columns(l, d, &mut x);
    // The inverse is symmetric; its lower triangle is mirrored so that it is exactly so.
    (0..d * d)
        .map(|ij| {
            let (i, j) = (ij / d, ij % d);
            if j <= i {
                x[(i, j)]
            } else {
                x[(j, i)]
            }
        })
        .collect()
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
                assert_eq!(inv[i * d + j], inv[j * d + i]);
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
