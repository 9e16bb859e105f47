//! Dense complex LU of the reduced systems: faer's blocked kernel with partial pivoting, run
//! sequentially (`Par::Seq`) so that results are bit-identical whatever the thread count (the
//! lines of a sweep are what runs in parallel).

use crate::common::C64;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::lu::partial_pivoting::{factor, solve};
use faer::{Conj, Mat, MatMut, Par};

/// P A = L U of an n x n complex matrix.
pub(crate) struct DenseLu {
    lu: Mat<C64>,
    fwd: Vec<usize>,
    bwd: Vec<usize>,
}

impl DenseLu {
    /// Factor a row-major n x n matrix; None when a pivot is zero or not finite.
    pub fn factor(n: usize, a: Vec<C64>) -> Option<DenseLu> {
        assert_eq!(a.len(), n * n);
        DenseLu::from_mat(Mat::from_fn(n, n, |i, j| a[i * n + j]))
    }

    /// Factor a complex symmetric (A = A^T, not Hermitian) n x n matrix, whose row-major
    /// storage is its column-major storage (read contiguously); None when a pivot is zero or
    /// not finite.
    pub fn factor_symmetric(n: usize, a: Vec<C64>) -> Option<DenseLu> {
        assert_eq!(a.len(), n * n);
        DenseLu::from_mat(Mat::from_fn(n, n, |i, j| a[j * n + i]))
    }

    /// Factor a square matrix; None when a pivot is zero or not finite.
    pub fn from_mat(mut a: Mat<C64>) -> Option<DenseLu> {
        let n = a.nrows();
        let mut fwd = vec![0usize; n];
        let mut bwd = vec![0usize; n];
        let mut mem = MemBuffer::new(factor::lu_in_place_scratch::<usize, C64>(
            n,
            n,
            Par::Seq,
            Default::default(),
        ));
        factor::lu_in_place(
            a.as_mut(),
            &mut fwd,
            &mut bwd,
            Par::Seq,
            MemStack::new(&mut mem),
            Default::default(),
        );
        let ok = (0..n).all(|i| {
            let d = a[(i, i)];
            d.norm() > 0.0 && d.re.is_finite() && d.im.is_finite()
        });
        ok.then_some(DenseLu { lu: a, fwd, bwd })
    }

    /// Solve A X = B in place for the columns of `b` (n x k), all at once.
    pub fn solve_columns(&self, b: &mut Mat<C64>) {
        let n = self.lu.nrows();
        let k = b.ncols();
        let mut mem = MemBuffer::new(solve::solve_in_place_scratch::<usize, C64>(n, k, Par::Seq));
        let perm = faer::perm::PermRef::new_checked(&self.fwd, &self.bwd, n);
        solve::solve_in_place_with_conj(
            self.lu.as_ref(),
            self.lu.as_ref(),
            perm,
            Conj::No,
            b.as_mut(),
            Par::Seq,
            MemStack::new(&mut mem),
        );
    }

    /// Solve A x = b in place.
    pub fn solve(&self, b: &mut [C64]) {
        let n = self.lu.nrows();
        let mut mem = MemBuffer::new(solve::solve_in_place_scratch::<usize, C64>(n, 1, Par::Seq));
        let perm = faer::perm::PermRef::new_checked(&self.fwd, &self.bwd, n);
        solve::solve_in_place_with_conj(
            self.lu.as_ref(),
            self.lu.as_ref(),
            perm,
            Conj::No,
            MatMut::from_column_major_slice_mut(b, n, 1),
            Par::Seq,
            MemStack::new(&mut mem),
        );
    }
}
