//! Reduced basis for the family Z(w, E*) (issue 3, "Reduced basis").
//!
//! For each real E_ref, with K = K_b + E_ref S (SPD, sparse Cholesky, symbolic analysis
//! shared), the block Krylov (load-dependent Ritz) sequence
//!
//! X_0 = K^-1 B,  X_{k+1} = K^-1 M Q_k,
//!
//! where B holds unit loads at all observation points and Q_k the vectors of X_k kept after
//! M-orthogonalisation. Each block is M-orthogonalised against the basis by block classical
//! Gram-Schmidt applied twice (BLAS-3), then within itself by modified Gram-Schmidt twice;
//! a vector whose M-norm falls below `deflation_tol` times its norm before is dropped.
//! The span of the first k blocks is the span of K^-1 (M K^-1)^j B, j < k, which contains
//! the modes of (K, M) seen by B to an accuracy that grows with k (Lanczos), so the basis
//! holds both the static responses and the low modes at every E_ref.

use super::sparse::{spmv_add, ModelPattern, SpdSolver};
use super::RomError;
use faer::linalg::matmul::matmul;
use faer::sparse::linalg::cholesky::SymbolicCholesky;
use faer::{Accum, Mat, Par};

/// Per-E_ref Krylov state.
struct KrylovState {
    e_ref: f64,
    depth: usize,
    /// This sequence's own M-orthonormal blocks Q_0..Q_k (n x sum k), kept independently of
    /// the global deflation so that the Krylov recurrence keeps converging to higher modes
    /// even when its new directions are already (nearly) in V.
    q: Mat<f64>,
    /// Columns of the last block Q_k inside `q`; empty when the sequence is exhausted.
    last: std::ops::Range<usize>,
}

/// Incrementally built M-orthonormal basis V (n x n_r) with MV = M V.
pub struct BasisBuilder<'a> {
    pat: &'a ModelPattern<'a>,
    chol: std::sync::Arc<SymbolicCholesky<usize>>,
    /// Unit loads at the observation points (n x n_out).
    pub b_all: Mat<f64>,
    v: Mat<f64>,
    mv: Mat<f64>,
    tol: f64,
    states: Vec<KrylovState>,
}

impl<'a> BasisBuilder<'a> {
    pub(crate) fn new(pat: &'a ModelPattern<'a>, deflation_tol: f64) -> Result<Self, RomError> {
        let model = pat.model;
        let n = model.n_dof();
        let n_out = model.points.len();
        let mut b_all = Mat::<f64>::zeros(n, n_out);
        for (i, p) in model.points.iter().enumerate() {
            for &(d, w) in &p.dofs {
                if d >= n {
                    return Err(RomError::Model(format!(
                        "observation point {} refers to DOF {d}, but the model has {n} free DOFs",
                        p.id
                    )));
                }
                b_all[(d, i)] += w;
            }
        }
        let chol = std::sync::Arc::new(SpdSolver::symbolic(pat)?);
        Ok(BasisBuilder {
            pat,
            chol,
            b_all,
            v: Mat::zeros(n, 0),
            mv: Mat::zeros(n, 0),
            tol: deflation_tol,
            states: Vec::new(),
        })
    }

    pub fn size(&self) -> usize {
        self.v.ncols()
    }
    pub fn v(&self) -> &Mat<f64> {
        &self.v
    }
    pub fn e_refs(&self) -> Vec<f64> {
        self.states.iter().map(|s| s.e_ref).collect()
    }

    /// M x for a column.
    fn m_times(&self, x: &[f64]) -> Vec<f64> {
        let mut y = vec![0.0; x.len()];
        spmv_add(&self.pat.model.m, x, 1.0, &mut y);
        y
    }

    /// (sqrt(c^T M c), M c), the M-norm clamped at 0 against rounding.
    fn m_norm(&self, c: &[f64]) -> (f64, Vec<f64>) {
        let mc = self.m_times(c);
        let nrm = c
            .iter()
            .zip(&mc)
            .map(|(a, b)| a * b)
            .sum::<f64>()
            .max(0.0)
            .sqrt();
        (nrm, mc)
    }

    /// The M-norms of the columns of `x`.
    fn col_m_norms(&self, x: &Mat<f64>) -> Vec<f64> {
        (0..x.ncols())
            .map(|j| self.m_norm(&x.col(j).iter().copied().collect::<Vec<_>>()).0)
            .collect()
    }

    /// Modified Gram-Schmidt, twice, of each column of `x` against the (q, M q) pairs of
    /// `fixed` and then the columns kept before it; a column is kept, M-normalised, when its
    /// M-norm is still above `tol` times `norm0` (its norm before any orthogonalisation).
    fn gram_schmidt(
        &self,
        x: &Mat<f64>,
        norm0: &[f64],
        fixed: &[(Vec<f64>, Vec<f64>)],
        tol: f64,
    ) -> Vec<(Vec<f64>, Vec<f64>)> {
        let mut kept: Vec<(Vec<f64>, Vec<f64>)> = Vec::new();
        for j in 0..x.ncols() {
            if !(norm0[j] > 0.0 && norm0[j].is_finite()) {
                continue;
            }
            let mut col: Vec<f64> = x.col(j).iter().copied().collect();
            for _ in 0..2 {
                for (q, mq) in fixed.iter().chain(kept.iter()) {
                    let c: f64 = mq.iter().zip(&col).map(|(a, b)| a * b).sum();
                    for (ci, qi) in col.iter_mut().zip(q) {
                        *ci -= c * qi;
                    }
                }
            }
            let (nrm, mcol) = self.m_norm(&col);
            if nrm > tol * norm0[j] {
                let inv = 1.0 / nrm;
                kept.push((
                    col.iter().map(|v| v * inv).collect(),
                    mcol.iter().map(|v| v * inv).collect(),
                ));
            }
        }
        kept
    }

    /// M-orthonormalise the columns of `x` against the M-orthonormal columns of `q` and each
    /// other ([`Self::gram_schmidt`]); columns whose M-norm falls below `tol` times their norm
    /// before are dropped.
    fn orthonormalise(&self, q: &Mat<f64>, x: Mat<f64>, tol: f64) -> Mat<f64> {
        let norm0 = self.col_m_norms(&x);
        let qcols: Vec<(Vec<f64>, Vec<f64>)> = (0..q.ncols())
            .map(|j| {
                let c: Vec<f64> = q.col(j).iter().copied().collect();
                let mc = self.m_times(&c);
                (c, mc)
            })
            .collect();
        let kept = self.gram_schmidt(&x, &norm0, &qcols, tol);
        Mat::from_fn(x.nrows(), kept.len(), |i, j| kept[j].0[i])
    }

    /// M-orthogonalise the columns of `x` against V (block classical Gram-Schmidt, twice) and
    /// each other ([`Self::gram_schmidt`]), deflate, and append the kept ones to V.
    fn absorb(&mut self, mut x: Mat<f64>) {
        let n = x.nrows();
        let k = x.ncols();
        let norm0 = self.col_m_norms(&x);
        let r = self.v.ncols();
        if r > 0 {
            for _ in 0..2 {
                let mut c = Mat::<f64>::zeros(r, k);
                matmul(
                    c.as_mut(),
                    Accum::Replace,
                    self.mv.transpose(),
                    x.as_ref(),
                    1.0,
                    Par::Seq,
                );
                matmul(
                    x.as_mut(),
                    Accum::Add,
                    self.v.as_ref(),
                    c.as_ref(),
                    -1.0,
                    Par::Seq,
                );
            }
        }
        let kept = self.gram_schmidt(&x, &norm0, &[], self.tol);
        let r0 = self.v.ncols();
        self.v.resize_with(n, r0 + kept.len(), |_, _| 0.0);
        self.mv.resize_with(n, r0 + kept.len(), |_, _| 0.0);
        for (j, (q, mq)) in kept.iter().enumerate() {
            for i in 0..n {
                self.v[(i, r0 + j)] = q[i];
                self.mv[(i, r0 + j)] = mq[i];
            }
        }
    }

    /// Bring the Krylov sequence at `e_ref` to `depth` blocks (creating it if new).
    pub fn extend(&mut self, e_ref: f64, depth: usize) -> Result<(), RomError> {
        let idx = match self.states.iter().position(|s| s.e_ref == e_ref) {
            Some(i) => i,
            None => {
                self.states.push(KrylovState {
                    e_ref,
                    depth: 0,
                    q: Mat::zeros(self.pat.model.n_dof(), 0),
                    last: 0..0,
                });
                self.states.len() - 1
            }
        };
        if self.states[idx].depth >= depth {
            return Ok(());
        }
        if self.states[idx].depth > 0 && self.states[idx].last.is_empty() {
            return Ok(()); // exhausted
        }
        let chol = self.chol.clone();
        let solver = SpdSolver::new(&chol, self.pat, e_ref)?;
        while self.states[idx].depth < depth {
            let st = &self.states[idx];
            let mut x = if st.depth == 0 {
                self.b_all.clone()
            } else {
                let mut mq = Mat::<f64>::zeros(st.q.nrows(), st.last.len());
                for (jj, j) in st.last.clone().enumerate() {
                    let col: Vec<f64> = st.q.col(j).iter().copied().collect();
                    let y = self.m_times(&col);
                    for (i, v) in y.into_iter().enumerate() {
                        mq[(i, jj)] = v;
                    }
                }
                mq
            };
            solver.solve_in_place(x.as_mut());
            // the sequence's own block: M-orthonormal against its previous blocks, relative
            // deflation at rounding level only (1e-13)
            let own = self.orthonormalise(&self.states[idx].q, x.clone(), 1e-13);
            self.absorb(x);
            let st = &mut self.states[idx];
            st.depth += 1;
            let r0 = st.q.ncols();
            let k = own.ncols();
            let n = st.q.nrows();
            st.q.resize_with(n, r0 + k, |i, j| own[(i, j - r0)]);
            st.last = r0..r0 + k;
            if k == 0 {
                break;
            }
        }
        Ok(())
    }

    /// V^T A V for a sparse A (symmetrised).
    pub(crate) fn project(&self, a: &crate::fe::model::SpMat) -> Mat<f64> {
        let n = self.v.nrows();
        let r = self.v.ncols();
        let mut av = Mat::<f64>::zeros(n, r);
        for j in 0..r {
            let col: Vec<f64> = self.v.col(j).iter().copied().collect();
            let mut y = vec![0.0; n];
            spmv_add(a, &col, 1.0, &mut y);
            for (i, v) in y.into_iter().enumerate() {
                av[(i, j)] = v;
            }
        }
        let mut out = Mat::<f64>::zeros(r, r);
        matmul(
            out.as_mut(),
            Accum::Replace,
            self.v.transpose(),
            av.as_ref(),
            1.0,
            Par::Seq,
        );
        Mat::from_fn(r, r, |i, j| 0.5 * (out[(i, j)] + out[(j, i)]))
    }

    /// V^T X for a dense X (n x k).
    pub(crate) fn project_vecs(&self, x: &Mat<f64>) -> Mat<f64> {
        let mut out = Mat::<f64>::zeros(self.v.ncols(), x.ncols());
        matmul(
            out.as_mut(),
            Accum::Replace,
            self.v.transpose(),
            x.as_ref(),
            1.0,
            Par::Seq,
        );
        out
    }
}
