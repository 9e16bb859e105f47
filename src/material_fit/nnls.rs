//! Non-negative least squares, min ||A x - b|| subject to x >= 0, by the active-set method of
//! Lawson and Hanson (1974, *Solving Least Squares Problems*, ch. 23, algorithm NNLS). The
//! unconstrained sub-problems on the passive set are solved by faer's Householder QR
//! (sequential, so bit-identical whatever the thread count) on unit-norm columns.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::householder;
use faer::linalg::qr::no_pivoting::factor;
use faer::{Conj, Mat, Par};

/// Least squares `min ||A z - b||` over the columns `cols` of the row-major `m x n` matrix `a`
/// (Householder QR; columns are expected scaled, and no more of them than rows). A column whose
/// diagonal entry of `R` is below 1e-12 (numerically dependent on the others) gets `z = 0`.
/// Returns `z` (one value per entry of `cols`).
fn lstsq(a: &[f64], m: usize, n: usize, cols: &[usize], b: &[f64]) -> Vec<f64> {
    let k = cols.len();
    let size = m.min(k);
    let mut qr = Mat::from_fn(m, k, |i, c| a[i * n + cols[c]]);
    let block = factor::recommended_block_size::<f64>(m, k);
    let mut coeff = Mat::<f64>::zeros(block, size);
    factor::qr_in_place(
        qr.as_mut(),
        coeff.as_mut(),
        Par::Seq,
        MemStack::new(&mut MemBuffer::new(factor::qr_in_place_scratch::<f64>(
            m,
            k,
            block,
            Par::Seq,
            Default::default(),
        ))),
        Default::default(),
    );
    // Q^T b.
    let mut qtb = Mat::from_fn(m, 1, |i, _| b[i]);
    householder::apply_block_householder_sequence_transpose_on_the_left_in_place_with_conj(
        qr.as_ref().get(.., ..size),
        coeff.as_ref(),
        Conj::No,
        qtb.as_mut(),
        Par::Seq,
        MemStack::new(&mut MemBuffer::new(
            householder::apply_block_householder_sequence_transpose_on_the_left_in_place_scratch::<
                f64,
            >(m, block, 1),
        )),
    );
    // Back substitution R z = Q^T b, dropping numerically dependent columns.
    let tol = 1e-12;
    let mut z = vec![0.0; k];
    for c in (0..size).rev() {
        let s = qtb[(c, 0)] - (c + 1..k).map(|j| qr[(c, j)] * z[j]).sum::<f64>();
        z[c] = if qr[(c, c)].abs() > tol {
            s / qr[(c, c)]
        } else {
            0.0
        };
    }
    z
}

/// `x >= 0` minimising `||A x - b||` (`a` row-major `m x n`). Columns are scaled to unit norm
/// internally; zero columns get `x = 0`.
pub fn nnls(a: &[f64], m: usize, n: usize, b: &[f64]) -> Vec<f64> {
    let scale: Vec<f64> = (0..n)
        .map(|j| (0..m).map(|i| a[i * n + j].powi(2)).sum::<f64>().sqrt())
        .collect();
    let a: Vec<f64> = (0..m * n)
        .map(|k| {
            let s = scale[k % n];
            if s > 0.0 {
                a[k] / s
            } else {
                0.0
            }
        })
        .collect();
    let mut x = vec![0.0; n];
    let mut passive = vec![false; n];
    let grad = |x: &[f64]| -> Vec<f64> {
        let res: Vec<f64> = (0..m)
            .map(|i| b[i] - (0..n).map(|j| a[i * n + j] * x[j]).sum::<f64>())
            .collect();
        (0..n)
            .map(|j| (0..m).map(|i| a[i * n + j] * res[i]).sum())
            .collect()
    };
    let bnorm = b.iter().map(|v| v * v).sum::<f64>().sqrt().max(1e-300);
    let tol = 1e-12 * bnorm;
    for _ in 0..3 * n + 10 {
        let w = grad(&x);
        let Some((t, wt)) = (0..n)
            .filter(|&j| !passive[j] && scale[j] > 0.0)
            .map(|j| (j, w[j]))
            .max_by(|a, b| a.1.total_cmp(&b.1))
        else {
            break;
        };
        if wt <= tol {
            break;
        }
        passive[t] = true;
        loop {
            let cols: Vec<usize> = (0..n).filter(|&j| passive[j]).collect();
            let z = lstsq(&a, m, n, &cols, b);
            if z.iter().all(|&v| v > 0.0) {
                for (c, &j) in cols.iter().enumerate() {
                    x[j] = z[c];
                }
                break;
            }
            let mut alpha = f64::INFINITY;
            for (c, &j) in cols.iter().enumerate() {
                if z[c] <= 0.0 {
                    let d = x[j] - z[c];
                    if d > 0.0 {
                        alpha = alpha.min(x[j] / d);
                    }
                }
            }
            if !alpha.is_finite() {
                alpha = 0.0;
            }
            for (c, &j) in cols.iter().enumerate() {
                x[j] += alpha * (z[c] - x[j]);
                if x[j] <= 1e-15 * (1.0 + z[c].abs()) {
                    x[j] = 0.0;
                    passive[j] = false;
                }
            }
            if !passive.iter().any(|&p| p) {
                break;
            }
        }
    }
    x.iter()
        .zip(&scale)
        .map(|(v, s)| if *s > 0.0 { v / s } else { 0.0 })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_a_nonnegative_solution_and_clips_a_negative_one() {
        // Exact data from x = [1, 0, 2]: NNLS returns it.
        let a = [1.0, 0.5, 0.2, 0.3, 1.0, 0.1, 0.2, 0.4, 1.0, 0.7, 0.2, 0.3];
        let x0 = [1.0, 0.0, 2.0];
        let b: Vec<f64> = (0..4)
            .map(|i| (0..3).map(|j| a[i * 3 + j] * x0[j]).sum())
            .collect();
        let x = nnls(&a, 4, 3, &b);
        for (u, v) in x.iter().zip(&x0) {
            assert!((u - v).abs() < 1e-10, "{x:?}");
        }
        // b = -A[:,0]: the best non-negative x is 0 in that column; KKT: gradient <= 0 where x = 0.
        let b: Vec<f64> = (0..4).map(|i| -a[i * 3]).collect();
        let x = nnls(&a, 4, 3, &b);
        let res: Vec<f64> = (0..4)
            .map(|i| b[i] - (0..3).map(|j| a[i * 3 + j] * x[j]).sum::<f64>())
            .collect();
        for j in 0..3 {
            assert!(x[j] >= 0.0);
            let g: f64 = (0..4).map(|i| a[i * 3 + j] * res[i]).sum();
            if x[j] == 0.0 {
                assert!(g <= 1e-10, "KKT violated at {j}: {g}");
            } else {
                assert!(g.abs() <= 1e-10);
            }
        }
    }
}
