//! Block kernels on tall matrices (n x k with n the number of DOFs, k tens to hundreds of
//! columns), parallel over fixed-size row chunks so that every result is bit-identical
//! whatever the number of threads: a chunk's arithmetic does not depend on which thread runs
//! it, and partial sums over chunks are added in chunk order.
//!
//! - [`Csr`]: a row-major copy of a sparse matrix and Y = A X with X, Y dense;
//! - [`tn`]: A^T B (a k x l result, a reduction over the n rows);
//! - [`nn_acc`]: C += alpha A B (n x l, rows independent).

use crate::fe::model::SpMat;
use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, MatMut, MatRef, Par};
use rayon::prelude::*;

/// Rows per chunk of the dense kernels (fixed: it sets the order of the partial sums).
const ROW_CHUNK: usize = 4096;
/// Rows per chunk of the sparse product.
const SPARSE_CHUNK: usize = 512;

/// A real sparse matrix in compressed sparse row form.
pub struct Csr {
    nrows: usize,
    ncols: usize,
    row_ptr: Vec<usize>,
    col_idx: Vec<usize>,
    val: Vec<f64>,
}

impl Csr {
    /// Row-major copy of a CSC matrix (entries of a row in increasing column order).
    pub fn from_csc(a: &SpMat) -> Csr {
        let (nrows, ncols) = (a.nrows(), a.ncols());
        let sym = a.symbolic();
        let ri = sym.row_idx();
        let mut count = vec![0usize; nrows + 1];
        for &i in ri {
            count[i + 1] += 1;
        }
        for i in 0..nrows {
            count[i + 1] += count[i];
        }
        let row_ptr = count.clone();
        let mut next = count;
        let nnz = ri.len();
        let mut col_idx = vec![0usize; nnz];
        let mut val = vec![0.0; nnz];
        for j in 0..ncols {
            for p in sym.col_range(j) {
                let i = ri[p];
                col_idx[next[i]] = j;
                val[next[i]] = a.val()[p];
                next[i] += 1;
            }
        }
        Csr {
            nrows,
            ncols,
            row_ptr,
            col_idx,
            val,
        }
    }

    pub fn nrows(&self) -> usize {
        self.nrows
    }

    /// Y = A X (X: ncols x k, Y: nrows x k). Each row of Y is summed in storage order.
    pub fn mul(&self, x: MatRef<'_, f64>) -> Mat<f64> {
        assert_eq!(
            x.nrows(),
            self.ncols,
            "Csr::mul: X has the wrong number of rows"
        );
        let k = x.ncols();
        if k == 0 {
            return Mat::zeros(self.nrows, 0);
        }
        // X row-major so that each stored entry updates k contiguous values
        let mut xt = vec![0.0; self.ncols * k];
        xt.par_chunks_mut(SPARSE_CHUNK * k)
            .enumerate()
            .for_each(|(c, chunk)| {
                let i0 = c * SPARSE_CHUNK;
                for (r, row) in chunk.chunks_mut(k).enumerate() {
                    for (t, v) in row.iter_mut().enumerate() {
                        *v = x[(i0 + r, t)];
                    }
                }
            });
        let mut yt = vec![0.0; self.nrows * k];
        yt.par_chunks_mut(SPARSE_CHUNK * k)
            .enumerate()
            .for_each(|(c, chunk)| {
                let i0 = c * SPARSE_CHUNK;
                for (r, acc) in chunk.chunks_mut(k).enumerate() {
                    let i = i0 + r;
                    for p in self.row_ptr[i]..self.row_ptr[i + 1] {
                        let a = self.val[p];
                        let xr = &xt[self.col_idx[p] * k..][..k];
                        for (y, &xv) in acc.iter_mut().zip(xr) {
                            *y += a * xv;
                        }
                    }
                }
            });
        let mut y = Mat::<f64>::zeros(self.nrows, k);
        y.par_col_chunks_mut(1)
            .enumerate()
            .for_each(|(t, mut col)| {
                for i in 0..self.nrows {
                    col[(i, 0)] = yt[i * k + t];
                }
            });
        y
    }
}

/// A^T B for tall A (n x k) and B (n x l): partial products of fixed row chunks, summed in order.
pub fn tn(a: MatRef<'_, f64>, b: MatRef<'_, f64>) -> Mat<f64> {
    assert_eq!(a.nrows(), b.nrows(), "tn: row counts differ");
    let n = a.nrows();
    let (k, l) = (a.ncols(), b.ncols());
    let n_chunks = n.div_ceil(ROW_CHUNK).max(1);
    let parts: Vec<Mat<f64>> = (0..n_chunks)
        .into_par_iter()
        .map(|c| {
            let i0 = c * ROW_CHUNK;
            let m = ROW_CHUNK.min(n - i0.min(n));
            let mut out = Mat::<f64>::zeros(k, l);
            if m > 0 {
                matmul(
                    out.as_mut(),
                    Accum::Replace,
                    a.subrows(i0, m).transpose(),
                    b.subrows(i0, m),
                    1.0,
                    Par::Seq,
                );
            }
            out
        })
        .collect();
    let mut out = Mat::<f64>::zeros(k, l);
    for p in &parts {
        out += p;
    }
    out
}

/// C += alpha A B for tall A (n x k), small B (k x l), C (n x l); rows in fixed chunks.
pub fn nn_acc(c: MatMut<'_, f64>, a: MatRef<'_, f64>, b: MatRef<'_, f64>, alpha: f64) {
    assert_eq!(c.nrows(), a.nrows(), "nn_acc: row counts differ");
    assert_eq!(a.ncols(), b.nrows(), "nn_acc: inner dimensions differ");
    if a.ncols() == 0 || b.ncols() == 0 {
        return;
    }
    c.par_row_chunks_mut(ROW_CHUNK)
        .enumerate()
        .for_each(|(ch, cc)| {
            let i0 = ch * ROW_CHUNK;
            let m = cc.nrows();
            matmul(cc, Accum::Add, a.subrows(i0, m), b, alpha, Par::Seq);
        });
}
