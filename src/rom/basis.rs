//! Reduced basis for the family Z(w, E*).
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

use super::sparse::{ModelPattern, SpdSolver};
use super::RomError;
use crate::linalg::blocked::{nn_acc, tn, Csr, MultiCsr};
use faer::sparse::linalg::cholesky::SymbolicCholesky;
use faer::Mat;
use rayon::prelude::*;
use std::sync::Arc;

/// Per-E_ref Krylov state.
struct KrylovState {
    e_ref: f64,
    depth: usize,
    /// This sequence's own M-orthonormal blocks Q_0..Q_k (n x sum k) and M Q, kept
    /// independently of the global deflation so that the Krylov recurrence keeps converging
    /// to higher modes even when its new directions are already (nearly) in V.
    q: Mat<f64>,
    mq: Mat<f64>,
    /// Columns of the last block Q_k inside `q`; empty when the sequence is exhausted.
    last: std::ops::Range<usize>,
}

/// A sequence's new blocks: the raw K^-1 M Q_k (before the global M-orthogonalisation).
type RawBlocks = Vec<Mat<f64>>;

/// Incrementally built M-orthonormal basis V (n x n_r) with the products A V and the
/// projections V^T A V of every model matrix A (M, K_b, S, C_b, D_b in the order of
/// [`ModelPattern`]), so that reducing the model and extending the basis never revisit the
/// columns already there.
pub struct BasisBuilder<'a> {
    pat: &'a ModelPattern<'a>,
    chol: Arc<SymbolicCholesky<usize>>,
    /// Row-major copies of the model matrices (same order as `av`).
    ops: Vec<Csr>,
    multi: std::sync::OnceLock<MultiCsr>,
    /// Unit loads at the observation points (n x n_out).
    pub b_all: Mat<f64>,
    /// Columns of `b_all` whose Krylov sequences build the basis (`None`: all).
    starts: Option<Vec<usize>>,
    v: Mat<f64>,
    /// A V for each model matrix; `av[0]` is M V.
    av: Vec<Mat<f64>>,
    /// V^T A V for each model matrix (upper blocks computed, lower mirrored).
    proj: Vec<Mat<f64>>,
    tol: f64,
    states: Vec<KrylovState>,
    /// Cholesky factors of K_b + e S, kept while the basis grows (a later enrichment level
    /// continues the same sequences); [`Self::drop_factors`] releases them.
    factors: Vec<(f64, Arc<SpdSolver>)>,
}

/// Append the columns of `x` to `m` (same row count).
fn append_cols(m: &mut Mat<f64>, x: &Mat<f64>) {
    let (n, r0) = (m.nrows(), m.ncols());
    m.resize_with(n, r0 + x.ncols(), |i, j| x[(i, j - r0)]);
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
        let chol = Arc::new(SpdSolver::symbolic(pat)?);
        let ops: Vec<Csr> = pat.matrices().iter().map(|a| Csr::from_csc(a)).collect();
        let nop = ops.len();
        Ok(BasisBuilder {
            pat,
            chol,
            ops,
            multi: std::sync::OnceLock::new(),
            b_all,
            starts: None,
            v: Mat::zeros(n, 0),
            av: (0..nop).map(|_| Mat::zeros(n, 0)).collect(),
            proj: (0..nop).map(|_| Mat::zeros(0, 0)).collect(),
            tol: deflation_tol,
            states: Vec::new(),
            factors: Vec::new(),
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
    /// A V for model matrix `k` (0 M, 1 K_b, 2 S, then C_b, D_b when present).
    pub(crate) fn av(&self, k: usize) -> &Mat<f64> {
        &self.av[k]
    }
    /// M X (exact, sparse product).
    fn m_times(&self, x: &Mat<f64>) -> Mat<f64> {
        self.ops[0].mul(x.as_ref())
    }

    /// The kept Cholesky factor of K_b + e S whose e is nearest to `target` on a log scale
    /// (None when none is kept).
    pub(crate) fn nearest_factor(&self, target: f64) -> Option<Arc<SpdSolver>> {
        let t = target.max(f64::MIN_POSITIVE);
        self.factors
            .iter()
            .min_by(|a, b| (a.0 / t).ln().abs().total_cmp(&(b.0 / t).ln().abs()))
            .map(|(_, f)| f.clone())
    }
    /// The model matrices on their union pattern, row-major (order of
    /// [`ModelPattern::matrices`]), made on first use.
    pub(crate) fn multi_op(&self) -> &MultiCsr {
        self.multi.get_or_init(|| MultiCsr::new(&self.ops))
    }
    pub(crate) fn n_ops(&self) -> usize {
        self.ops.len()
    }
    pub(crate) fn model(&self) -> &crate::fe::model::StructuralModel {
        self.pat.model
    }
    pub(crate) fn pattern(&self) -> &ModelPattern<'a> {
        self.pat
    }

    /// Drop the kept factors (memory).
    pub(crate) fn drop_factors(&mut self) {
        self.factors.clear();
    }

    /// M-orthonormalise the columns of `x` (with `mx` = M x) against the M-orthonormal
    /// columns of `q` (with `mq` = M q): block classical Gram-Schmidt twice, then modified
    /// Gram-Schmidt twice within the block. A column is kept, M-normalised, when its M-norm
    /// is still above `tol` times its M-norm before. Returns (Q, M Q) of the kept columns,
    /// M Q recomputed exactly.
    fn orthonormalise(
        &self,
        q: &Mat<f64>,
        mq: &Mat<f64>,
        mut x: Mat<f64>,
        mut mx: Mat<f64>,
        tol: f64,
    ) -> (Mat<f64>, Mat<f64>) {
        // sqrt(x_j^T M x_j), clamped at 0 against rounding
        let m_norm = |x: &Mat<f64>, mx: &Mat<f64>, j: usize| {
            x.col(j)
                .iter()
                .zip(mx.col(j).iter())
                .map(|(a, b)| a * b)
                .sum::<f64>()
                .max(0.0)
                .sqrt()
        };
        let k = x.ncols();
        let norm0: Vec<f64> = (0..k).map(|j| m_norm(&x, &mx, j)).collect();
        if q.ncols() > 0 {
            for _ in 0..2 {
                let c = tn(mq.as_ref(), x.as_ref());
                nn_acc(x.as_mut(), q.as_ref(), c.as_ref(), -1.0);
                nn_acc(mx.as_mut(), mq.as_ref(), c.as_ref(), -1.0);
            }
        }
        let mut kept: Vec<usize> = Vec::new();
        for j in 0..k {
            if !(norm0[j] > 0.0 && norm0[j].is_finite()) {
                continue;
            }
            for _ in 0..2 {
                for &i in &kept {
                    let c: f64 = mx
                        .col(i)
                        .iter()
                        .zip(x.col(j).iter())
                        .map(|(a, b)| a * b)
                        .sum();
                    let (xi, xj) = x.two_cols_mut(i, j);
                    for (a, b) in xj.iter_mut().zip(xi.iter()) {
                        *a -= c * b;
                    }
                    let (mi, mj) = mx.two_cols_mut(i, j);
                    for (a, b) in mj.iter_mut().zip(mi.iter()) {
                        *a -= c * b;
                    }
                }
            }
            let nrm = m_norm(&x, &mx, j);
            if nrm > tol * norm0[j] {
                let inv = 1.0 / nrm;
                x.col_mut(j).iter_mut().for_each(|v| *v *= inv);
                mx.col_mut(j).iter_mut().for_each(|v| *v *= inv);
                kept.push(j);
            }
        }
        let out = Mat::from_fn(x.nrows(), kept.len(), |i, j| x[(i, kept[j])]);
        let m_out = self.m_times(&out);
        (out, m_out)
    }

    /// M-orthogonalise the columns of `x` against V and each other ([`Self::orthonormalise`]),
    /// deflate with `deflation_tol`, append the kept ones to V and update A V and V^T A V.
    /// Returns the number of columns kept.
    pub(crate) fn absorb(&mut self, x: Mat<f64>) -> usize {
        let mx = self.m_times(&x);
        let (q, mq) = self.orthonormalise(&self.v, &self.av[0], x, mx, self.tol);
        let k = q.ncols();
        if k == 0 {
            return 0;
        }
        let r0 = self.v.ncols();
        let aq: Vec<Mat<f64>> = (0..self.ops.len())
            .map(|i| {
                if i == 0 {
                    mq.clone()
                } else {
                    self.ops[i].mul(q.as_ref())
                }
            })
            .collect();
        for (i, a_q) in aq.iter().enumerate() {
            let top = tn(self.v.as_ref(), a_q.as_ref()); // V^T A Q (r0 x k)
            let corner = tn(q.as_ref(), a_q.as_ref()); // Q^T A Q
            let p = &mut self.proj[i];
            p.resize_with(r0 + k, r0 + k, |_, _| 0.0);
            for c in 0..k {
                for r in 0..r0 {
                    p[(r, r0 + c)] = top[(r, c)];
                    p[(r0 + c, r)] = top[(r, c)];
                }
                for r in 0..k {
                    p[(r0 + r, r0 + c)] = 0.5 * (corner[(r, c)] + corner[(c, r)]);
                }
            }
        }
        append_cols(&mut self.v, &q);
        for (i, a_q) in aq.iter().enumerate() {
            append_cols(&mut self.av[i], a_q);
        }
        k
    }

    /// Bring the Krylov sequences at several E_ref to their depths (creating new ones). The
    /// sequences are independent of V and of each other, so they run in parallel; their
    /// blocks are then absorbed into V in the order of `targets` (block order within each),
    /// so V is the same as when the sequences are extended one after the other.
    pub fn extend_all(&mut self, targets: &[(f64, usize)]) -> Result<(), RomError> {
        let mut work: Vec<(usize, usize)> = Vec::new(); // (state index, depth)
        for &(e_ref, depth) in targets {
            let idx = match self.states.iter().position(|s| s.e_ref == e_ref) {
                Some(i) => i,
                None => {
                    let n = self.pat.model.n_dof();
                    self.states.push(KrylovState {
                        e_ref,
                        depth: 0,
                        q: Mat::zeros(n, 0),
                        mq: Mat::zeros(n, 0),
                        last: 0..0,
                    });
                    self.states.len() - 1
                }
            };
            let st = &self.states[idx];
            if st.depth >= depth || (st.depth > 0 && st.last.is_empty()) {
                continue; // deep enough, or exhausted
            }
            work.push((idx, depth));
        }
        // factors first (two at a time at most: each is a few hundred MB on a fine mesh)
        let missing: Vec<f64> = work
            .iter()
            .map(|&(i, _)| self.states[i].e_ref)
            .filter(|e| !self.factors.iter().any(|(x, _)| x == e))
            .collect();
        for pair in missing.chunks(2) {
            let made: Vec<Result<SpdSolver, RomError>> = pair
                .par_iter()
                .map(|&e| SpdSolver::new(self.chol.clone(), self.pat, e))
                .collect();
            for (&e, f) in pair.iter().zip(made) {
                self.factors.push((e, Arc::new(f?)));
            }
        }
        let jobs: Vec<(usize, usize, Arc<SpdSolver>, KrylovState)> = work
            .iter()
            .map(|&(i, depth)| {
                let e = self.states[i].e_ref;
                let f = self
                    .factors
                    .iter()
                    .find(|(x, _)| *x == e)
                    .map(|(_, f)| f.clone())
                    .expect("factor made above");
                let st = std::mem::replace(
                    &mut self.states[i],
                    KrylovState {
                        e_ref: e,
                        depth: 0,
                        q: Mat::zeros(0, 0),
                        mq: Mat::zeros(0, 0),
                        last: 0..0,
                    },
                );
                (i, depth, f, st)
            })
            .collect();
        let this = &*self;
        let done: Vec<(usize, KrylovState, RawBlocks)> = jobs
            .into_par_iter()
            .map(|(i, depth, f, mut st)| {
                let raw = this.run_sequence(&mut st, depth, &f);
                (i, st, raw)
            })
            .collect();
        let mut all_raw: Vec<(usize, RawBlocks)> = Vec::new();
        for (i, st, raw) in done {
            self.states[i] = st;
            all_raw.push((i, raw));
        }
        // absorb in the order of `targets`
        for &(i, _) in &work {
            if let Some(pos) = all_raw.iter().position(|(j, _)| *j == i) {
                let (_, raw) = all_raw.swap_remove(pos);
                for x in raw {
                    self.absorb(x);
                }
            }
        }
        Ok(())
    }

    /// Build the basis from the Krylov sequences of the loads at these observation points only
    /// (the others are still projected: their FRFs ride on the basis).
    pub(crate) fn restrict_starts(&mut self, outputs: &[usize]) {
        self.starts = Some(outputs.to_vec());
    }

    /// Continue one Krylov sequence to `depth` blocks; returns its new raw blocks.
    fn run_sequence(&self, st: &mut KrylovState, depth: usize, f: &SpdSolver) -> RawBlocks {
        let mut raw = Vec::new();
        while st.depth < depth {
            let mut x = if st.depth == 0 {
                match &self.starts {
                    None => self.b_all.clone(),
                    Some(c) => {
                        Mat::from_fn(self.b_all.nrows(), c.len(), |i, j| self.b_all[(i, c[j])])
                    }
                }
            } else {
                Mat::from_fn(st.q.nrows(), st.last.len(), |i, j| {
                    st.mq[(i, st.last.start + j)]
                })
            };
            f.solve_cols(x.as_mut());
            // the sequence's own block: M-orthonormal against its previous blocks, relative
            // deflation at rounding level only (1e-13)
            let mx = self.m_times(&x);
            let (own, m_own) = self.orthonormalise(&st.q, &st.mq, x.clone(), mx, 1e-13);
            raw.push(x);
            st.depth += 1;
            let r0 = st.q.ncols();
            let k = own.ncols();
            append_cols(&mut st.q, &own);
            append_cols(&mut st.mq, &m_own);
            st.last = r0..r0 + k;
            if k == 0 {
                break;
            }
        }
        raw
    }

    /// V^T A V for model matrix `k`.
    pub(crate) fn project_op(&self, k: usize) -> Mat<f64> {
        self.proj[k].clone()
    }

    /// V^T A V for a sparse A that is not one of the model matrices (symmetrised).
    pub(crate) fn project(&self, a: &crate::fe::model::SpMat) -> Mat<f64> {
        let av = Csr::from_csc(a).mul(self.v.as_ref());
        symmetric_part(&tn(self.v.as_ref(), av.as_ref()))
    }

    /// V^T X for a dense X (n x k).
    pub(crate) fn project_vecs(&self, x: &Mat<f64>) -> Mat<f64> {
        tn(self.v.as_ref(), x.as_ref())
    }
}

/// `(A + A^T) / 2` of a square matrix (projections that must be exactly symmetric: the
/// line solves read rows from columns).
pub(crate) fn symmetric_part(a: &Mat<f64>) -> Mat<f64> {
    let n = a.nrows();
    Mat::from_fn(n, n, |i, j| 0.5 * (a[(i, j)] + a[(j, i)]))
}
