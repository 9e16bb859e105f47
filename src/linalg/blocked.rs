//! Block kernels on tall matrices (n x k with n the number of DOFs, k tens to hundreds of
//! columns), parallel over fixed-size row chunks so that every result is bit-identical
//! whatever the number of threads: a chunk's arithmetic does not depend on which thread runs
//! it, and partial sums over chunks are added in chunk order.
//!
//! - [`Csr`]: a row-major copy of a sparse matrix and Y = A X with X, Y dense;
//! - [`combine_mul`]: W = sum_o A_o X C_o, complex columns with per-column coefficients
//!   (Z(w, E*) applied to many systems at once: one pass over the rows for all operators);
//! - [`to_row_major`] / [`from_row_major`]: layout changes of tall blocks;
//! - [`tn`]: A^T B (a k x l result, a reduction over the n rows);
//! - [`nn_acc`]: C += alpha A B (n x l, rows independent).

use super::SpMat;
use crate::common::C64;
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
        to_row_major(x, &mut xt);
        let mut yt = vec![0.0; self.nrows * k];
        yt.par_chunks_mut(SPARSE_CHUNK * k)
            .enumerate()
            .for_each(|(c, chunk)| {
                let mut acc = vec![0.0; k];
                rows_kernel(self, c * SPARSE_CHUNK, &xt, k, &mut acc, &mut |r, acc| {
                    chunk[r * k..][..k].copy_from_slice(&acc[..k]);
                });
            });
        let mut y = Mat::<f64>::zeros(self.nrows, k);
        from_row_major(&yt, y.as_mut());
        y
    }
}

/// A row-major sparse operand of the row kernels: one matrix, or several on one pattern.
trait RowOp {
    /// (rows, columns, operators).
    fn dims(&self) -> (usize, usize, usize);
    /// acc[o * k + t] += sum_p A_o[i, col_p] X[col_p, t] for every operator o and t < k,
    /// X row-major with k columns; the entries of row i are taken in storage order.
    fn row_acc(&self, i: usize, xt: &[f64], k: usize, acc: &mut [f64]);
}

impl RowOp for Csr {
    fn dims(&self) -> (usize, usize, usize) {
        (self.nrows, self.ncols, 1)
    }

    #[inline(always)]
    fn row_acc(&self, i: usize, xt: &[f64], k: usize, acc: &mut [f64]) {
        let acc = &mut acc[..k];
        for p in self.row_ptr[i]..self.row_ptr[i + 1] {
            let a = self.val[p];
            let xr = &xt[self.col_idx[p] * k..][..k];
            for (y, &xv) in acc.iter_mut().zip(xr) {
                *y += a * xv;
            }
        }
    }
}

/// Several sparse matrices of one size on the union of their patterns, row-major, with the
/// values of all matrices stored together per entry (`val[p * n_ops + o]`, 0 where a
/// matrix has no entry): one pass over the rows reads each column index and each row of X
/// once for all operators.
pub struct MultiCsr {
    nrows: usize,
    ncols: usize,
    n_ops: usize,
    row_ptr: Vec<usize>,
    col_idx: Vec<usize>,
    val: Vec<f64>,
}

impl MultiCsr {
    /// The union of the row-major copies `ops` (all of one size).
    pub fn new(ops: &[Csr]) -> MultiCsr {
        assert!(
            (1..=MAX_OPS).contains(&ops.len()),
            "MultiCsr: 1 to {MAX_OPS} operators, got {}",
            ops.len()
        );
        let (nrows, ncols, n_ops) = (ops[0].nrows, ops[0].ncols, ops.len());
        assert!(
            ops.iter().all(|a| a.nrows == nrows && a.ncols == ncols),
            "MultiCsr: operators of different sizes"
        );
        let mut row_ptr = vec![0usize];
        let mut col_idx = Vec::new();
        let mut val = Vec::new();
        let mut row: Vec<(usize, usize, f64)> = Vec::new();
        for i in 0..nrows {
            row.clear();
            for (o, a) in ops.iter().enumerate() {
                for p in a.row_ptr[i]..a.row_ptr[i + 1] {
                    row.push((a.col_idx[p], o, a.val[p]));
                }
            }
            row.sort_by_key(|&(j, o, _)| (j, o));
            for &(j, o, v) in &row {
                if col_idx.len() == row_ptr[i] || *col_idx.last().expect("non-empty") != j {
                    col_idx.push(j);
                    val.extend(std::iter::repeat_n(0.0, n_ops));
                }
                let q = val.len() - n_ops + o;
                val[q] += v;
            }
            row_ptr.push(col_idx.len());
        }
        MultiCsr {
            nrows,
            ncols,
            n_ops,
            row_ptr,
            col_idx,
            val,
        }
    }

    pub fn n_ops(&self) -> usize {
        self.n_ops
    }

    /// [`RowOp::row_acc`] for `N` operators, in tiles of `TILE` columns so that the
    /// accumulators of one tile stay in registers.
    #[inline(always)]
    fn row_acc_n<const N: usize>(&self, i: usize, xt: &[f64], k: usize, acc: &mut [f64]) {
        let entries = self.row_ptr[i]..self.row_ptr[i + 1];
        let full = k / TILE * TILE;
        for t0 in (0..full).step_by(TILE) {
            let mut a = [[0.0f64; TILE]; N];
            for p in entries.clone() {
                let x: &[f64; TILE] = xt[self.col_idx[p] * k + t0..][..TILE]
                    .try_into()
                    .expect("tile");
                let v: &[f64; N] = self.val[p * N..][..N].try_into().expect("values");
                for o in 0..N {
                    for t in 0..TILE {
                        a[o][t] += v[o] * x[t];
                    }
                }
            }
            for (o, ao) in a.iter().enumerate() {
                acc[o * k + t0..][..TILE].copy_from_slice(ao);
            }
        }
        for p in entries {
            let x = &xt[self.col_idx[p] * k..][..k];
            for o in 0..N {
                let v = self.val[p * N + o];
                for t in full..k {
                    acc[o * k + t] += v * x[t];
                }
            }
        }
    }
}

impl RowOp for MultiCsr {
    fn dims(&self) -> (usize, usize, usize) {
        (self.nrows, self.ncols, self.n_ops)
    }

    #[inline(always)]
    fn row_acc(&self, i: usize, xt: &[f64], k: usize, acc: &mut [f64]) {
        match self.n_ops {
            1 => self.row_acc_n::<1>(i, xt, k, acc),
            2 => self.row_acc_n::<2>(i, xt, k, acc),
            3 => self.row_acc_n::<3>(i, xt, k, acc),
            4 => self.row_acc_n::<4>(i, xt, k, acc),
            _ => self.row_acc_n::<MAX_OPS>(i, xt, k, acc),
        }
    }
}

/// Columns per register tile of [`MultiCsr`]'s row kernel.
const TILE: usize = 8;
/// Most operators a [`MultiCsr`] holds (M, K_b, S, C_b, D_b).
const MAX_OPS: usize = 5;

/// For each row i of a chunk of `SPARSE_CHUNK` rows starting at `i0` (clipped to the matrix),
/// the products of row i of every operator with X (row-major, k columns) are formed in
/// `acc` (operator o in `acc[o * k..][..k]`) and handed to `emit(i - i0, acc)`.
#[inline(always)]
fn rows_generic<T: RowOp>(
    ops: &T,
    i0: usize,
    xt: &[f64],
    k: usize,
    acc: &mut [f64],
    emit: &mut dyn FnMut(usize, &[f64]),
) {
    let (nrows, _, n_ops) = ops.dims();
    for i in i0..(i0 + SPARSE_CHUNK).min(nrows) {
        let ao = &mut acc[..n_ops * k];
        ao.iter_mut().for_each(|v| *v = 0.0);
        ops.row_acc(i, xt, k, ao);
        emit(i - i0, acc);
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn rows_avx512<T: RowOp>(
    ops: &T,
    i0: usize,
    xt: &[f64],
    k: usize,
    acc: &mut [f64],
    emit: &mut dyn FnMut(usize, &[f64]),
) {
    rows_generic(ops, i0, xt, k, acc, emit)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn rows_avx2<T: RowOp>(
    ops: &T,
    i0: usize,
    xt: &[f64],
    k: usize,
    acc: &mut [f64],
    emit: &mut dyn FnMut(usize, &[f64]),
) {
    rows_generic(ops, i0, xt, k, acc, emit)
}

/// [`rows_generic`] on the widest available instruction set. The arithmetic is elementwise
/// (no reduction is reordered, and Rust never contracts a * b + c into an FMA), so every path
/// gives the same bits.
fn rows_kernel<T: RowOp>(
    ops: &T,
    i0: usize,
    xt: &[f64],
    k: usize,
    acc: &mut [f64],
    emit: &mut dyn FnMut(usize, &[f64]),
) {
    let (_, ncols, n_ops) = ops.dims();
    assert!(ncols * k <= xt.len() && acc.len() >= n_ops * k);
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx512f") {
            // SAFETY: the required CPU feature was detected at run time.
            unsafe { rows_avx512(ops, i0, xt, k, acc, emit) };
            return;
        }
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: as above.
            unsafe { rows_avx2(ops, i0, xt, k, acc, emit) };
            return;
        }
    }
    rows_generic(ops, i0, xt, k, acc, emit)
}

/// W = sum_o A_o X C_o for complex columns: X is n x 2s real row-major holding s complex
/// columns as (re, im) pairs, `coefs[a][o]` the coefficient of operator o for complex column
/// a, and W (n x 2s, row-major, same pairing) receives column a = sum_o coefs[a][o] A_o x_a.
/// Rows in parallel over fixed chunks, each row summed in storage order.
pub fn combine_mul(ops: &MultiCsr, coefs: &[&[C64]], xt: &[f64], wt: &mut [f64]) {
    let s = coefs.len();
    let k = 2 * s;
    if s == 0 {
        return;
    }
    let n = ops.nrows;
    assert_eq!(wt.len(), n * k, "combine_mul: W has the wrong size");
    assert!(coefs.iter().all(|c| c.len() == ops.n_ops));
    wt.par_chunks_mut(SPARSE_CHUNK * k)
        .enumerate()
        .for_each(|(c, chunk)| {
            let mut acc = vec![0.0; ops.n_ops * k];
            rows_kernel(ops, c * SPARSE_CHUNK, xt, k, &mut acc, &mut |r, acc| {
                let w = &mut chunk[r * k..][..k];
                for (a, co) in coefs.iter().enumerate() {
                    let (mut re, mut im) = (0.0, 0.0);
                    for (o, c) in co.iter().enumerate() {
                        let (x, y) = (acc[o * k + 2 * a], acc[o * k + 2 * a + 1]);
                        re += c.re * x - c.im * y;
                        im += c.re * y + c.im * x;
                    }
                    w[2 * a] = re;
                    w[2 * a + 1] = im;
                }
            });
        });
}

/// out[i * k + t] = x[(i, t)] (x: n x k), parallel over fixed row chunks.
pub fn to_row_major(x: MatRef<'_, f64>, out: &mut [f64]) {
    let (n, k) = (x.nrows(), x.ncols());
    assert_eq!(out.len(), n * k, "to_row_major: wrong output size");
    if k == 0 {
        return;
    }
    out.par_chunks_mut(SPARSE_CHUNK * k)
        .enumerate()
        .for_each(|(c, chunk)| {
            let i0 = c * SPARSE_CHUNK;
            let m = chunk.len() / k;
            for t in 0..k {
                let col = x.col(t).subrows(i0, m);
                for (r, &v) in col.iter().enumerate() {
                    chunk[r * k + t] = v;
                }
            }
        });
}

/// y[(i, t)] = rm[i * k + t] (y: n x k), parallel over fixed row chunks.
pub fn from_row_major(rm: &[f64], y: MatMut<'_, f64>) {
    let k = y.ncols();
    assert_eq!(rm.len(), y.nrows() * k, "from_row_major: wrong input size");
    if k == 0 {
        return;
    }
    y.par_row_chunks_mut(SPARSE_CHUNK)
        .enumerate()
        .for_each(|(c, mut yc)| {
            let i0 = c * SPARSE_CHUNK;
            for t in 0..k {
                for (r, v) in yc.as_mut().col_mut(t).iter_mut().enumerate() {
                    *v = rm[(i0 + r) * k + t];
                }
            }
        });
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
