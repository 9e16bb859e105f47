//! Small sparse linear-algebra helpers shared by the FRF engine, the eigensolver and the
//! Matrix Market reader: matrix-vector products of a real CSC matrix with real or complex
//! vectors, the union sparsity pattern of several matrices with maps from each source entry
//! to its slot, and a symmetry check.
//!
//! All loops are sequential and in a fixed order, so results are bit-identical whatever the
//! number of threads of the caller.

pub mod blocked;
pub mod dense;

use crate::common::C64;
/// A real sparse matrix in compressed sparse column form (the FE matrices, the load vectors).
pub type SpMat = faer::sparse::SparseColMat<usize, f64>;
use faer::sparse::SymbolicSparseColMat;

/// y = A x for a real sparse A and a real x (y is overwritten).
///
/// Panics only on a length mismatch, which is a programming error of the caller.
pub fn spmv_real(a: &SpMat, x: &[f64], y: &mut [f64]) {
    assert_eq!(x.len(), a.ncols());
    assert_eq!(y.len(), a.nrows());
    y.iter_mut().for_each(|v| *v = 0.0);
    let row_idx = a.symbolic().row_idx();
    let val = a.val();
    for (j, &xj) in x.iter().enumerate() {
        if xj == 0.0 {
            continue;
        }
        for p in a.symbolic().col_range(j) {
            y[row_idx[p]] += val[p] * xj;
        }
    }
}

/// y = A x for a real sparse A and a complex x (y is overwritten).
pub fn spmv_complex(a: &SpMat, x: &[C64], y: &mut [C64]) {
    assert_eq!(x.len(), a.ncols());
    assert_eq!(y.len(), a.nrows());
    y.iter_mut().for_each(|v| *v = C64::new(0.0, 0.0));
    let row_idx = a.symbolic().row_idx();
    let val = a.val();
    for (j, &xj) in x.iter().enumerate() {
        if xj.re == 0.0 && xj.im == 0.0 {
            continue;
        }
        for p in a.symbolic().col_range(j) {
            y[row_idx[p]] += xj * val[p];
        }
    }
}

/// x^T A y (no conjugation) for real sparse A and complex x, y.
pub fn bilinear_complex(a: &SpMat, x: &[C64], y: &[C64]) -> C64 {
    let row_idx = a.symbolic().row_idx();
    let val = a.val();
    let mut acc = C64::new(0.0, 0.0);
    for (j, &yj) in y.iter().enumerate() {
        let mut col = C64::new(0.0, 0.0);
        for p in a.symbolic().col_range(j) {
            col += x[row_idx[p]] * val[p];
        }
        acc += col * yj;
    }
    acc
}

/// Largest |A_ij - A_ji| relative to max |A_ij| (0 for a symmetric matrix).
pub fn asymmetry(a: &SpMat) -> f64 {
    let n = a.ncols();
    let mut max_abs = 0.0f64;
    let mut entries: Vec<(usize, usize, f64)> = Vec::with_capacity(a.val().len());
    let row_idx = a.symbolic().row_idx();
    for j in 0..n {
        for p in a.symbolic().col_range(j) {
            entries.push((row_idx[p], j, a.val()[p]));
            max_abs = max_abs.max(a.val()[p].abs());
        }
    }
    if max_abs == 0.0 {
        return 0.0;
    }
    // sum duplicates, then compare (i,j) with (j,i)
    let mut map = std::collections::HashMap::with_capacity(entries.len());
    for (i, j, v) in entries {
        *map.entry((i, j)).or_insert(0.0) += v;
    }
    let mut worst = 0.0f64;
    for (&(i, j), &v) in &map {
        let vt = map.get(&(j, i)).copied().unwrap_or(0.0);
        worst = worst.max((v - vt).abs());
    }
    worst / max_abs
}

/// The union sparsity pattern of several same-size square matrices (sorted rows, diagonal
/// always present), and for each source matrix the slot of each of its stored entries.
#[derive(Clone, Debug)]
pub struct UnionPattern {
    /// The union pattern (sorted row indices per column).
    pub symbolic: SymbolicSparseColMat<usize>,
    /// `slots[k][p]` is the slot in the union pattern of entry `p` of source matrix `k`
    /// (in that matrix's storage order).
    pub slots: Vec<Vec<usize>>,
}

impl UnionPattern {
    /// Build the union of the patterns of `mats` (all n x n; the caller checks sizes).
    pub fn new(n: usize, mats: &[&SpMat]) -> Self {
        let mut col_ptr = Vec::with_capacity(n + 1);
        let mut row_idx: Vec<usize> = Vec::new();
        col_ptr.push(0usize);
        let mut scratch: Vec<usize> = Vec::new();
        for j in 0..n {
            scratch.clear();
            scratch.push(j); // keep the diagonal in the pattern
            for a in mats {
                scratch.extend_from_slice(&a.symbolic().row_idx()[a.symbolic().col_range(j)]);
            }
            scratch.sort_unstable();
            scratch.dedup();
            row_idx.extend_from_slice(&scratch);
            col_ptr.push(row_idx.len());
        }
        let slots = mats
            .iter()
            .map(|a| {
                let ri = a.symbolic().row_idx();
                let mut s = vec![usize::MAX; a.val().len()];
                for j in 0..n {
                    let col = &row_idx[col_ptr[j]..col_ptr[j + 1]];
                    for p in a.symbolic().col_range(j) {
                        // present by construction
                        let k = col.binary_search(&ri[p]).unwrap_or(0);
                        s[p] = col_ptr[j] + k;
                    }
                }
                s
            })
            .collect();
        let symbolic = SymbolicSparseColMat::new_checked(n, n, col_ptr, None, row_idx);
        UnionPattern { symbolic, slots }
    }

    /// Number of stored entries of the union pattern.
    pub fn nnz(&self) -> usize {
        self.symbolic.row_idx().len()
    }

    /// Scatter-add the values of source matrix `k` into `dst` (one value per slot).
    pub fn scatter(&self, k: usize, a: &SpMat, dst: &mut [f64]) {
        for (p, &v) in a.val().iter().enumerate() {
            let slot = self.slots[k][p];
            if slot != usize::MAX {
                dst[slot] += v;
            }
        }
    }
}
