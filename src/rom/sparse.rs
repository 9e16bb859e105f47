//! Full-model sparse kernels used by the ROM build: a union sparsity pattern shared by
//! M, K_b, S, C_b, D_b (symbolic analysis once, values refilled per (w, E)), the real SPD
//! Cholesky of K_b + E_ref S and the complex sparse LU of
//! Z(w, E*) = -w^2 M + K_b + j w C_b + j D_b + E* S used as the certificate's reference.
//!
//! All faer calls use `Par::Seq` explicitly so that results do not depend on the number of
//! threads (callers parallelise over independent frequency lines or moduli instead).

use super::RomError;
use crate::common::C64;
use crate::fe::model::{SpMat, StructuralModel};
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::sparse::linalg::cholesky::{factorize_symbolic_cholesky, LltRef, SymbolicCholesky};
use faer::sparse::linalg::lu::{factorize_symbolic_lu, LuRef, NumericLu, SymbolicLu};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMat};
use faer::{Conj, MatMut, Par, Side};
use std::sync::{Arc, Mutex};

/// The union pattern of several square matrices, and for each matrix the map
/// (source value index, destination value index).
pub(crate) struct UnionPattern {
    pub sym: SymbolicSparseColMat<usize>,
    maps: Vec<Vec<(usize, usize)>>,
}

impl UnionPattern {
    pub fn new(mats: &[&SpMat]) -> Result<Self, RomError> {
        let n = mats[0].nrows();
        for m in mats {
            if m.nrows() != n || m.ncols() != n {
                return Err(RomError::Model(format!(
                    "all model matrices must be {n} x {n}; one is {} x {}",
                    m.nrows(),
                    m.ncols()
                )));
            }
        }
        let mut col_ptr = Vec::with_capacity(n + 1);
        let mut row_idx: Vec<usize> = Vec::new();
        col_ptr.push(0usize);
        let mut buf: Vec<usize> = Vec::new();
        for j in 0..n {
            buf.clear();
            for m in mats {
                let s = m.symbolic();
                buf.extend_from_slice(&s.row_idx()[s.col_range(j)]);
            }
            buf.sort_unstable();
            buf.dedup();
            row_idx.extend_from_slice(&buf);
            col_ptr.push(row_idx.len());
        }
        let mut maps = Vec::with_capacity(mats.len());
        for m in mats {
            let s = m.symbolic();
            let mut map = Vec::new();
            for j in 0..n {
                let dst = &row_idx[col_ptr[j]..col_ptr[j + 1]];
                for p in s.col_range(j) {
                    let i = s.row_idx()[p];
                    let q = dst
                        .binary_search(&i)
                        .map_err(|_| RomError::Model("internal: pattern union failed".into()))?;
                    map.push((p, col_ptr[j] + q));
                }
            }
            maps.push(map);
        }
        let sym = SymbolicSparseColMat::new_checked(n, n, col_ptr, None, row_idx);
        Ok(UnionPattern { sym, maps })
    }

    pub fn nnz(&self) -> usize {
        self.sym.row_idx().len()
    }

    /// vals += coef * mats[k] (real coefficient, real values).
    pub fn add_real(&self, k: usize, mat: &SpMat, coef: f64, vals: &mut [f64]) {
        let v = mat.val();
        for &(p, q) in &self.maps[k] {
            vals[q] += coef * v[p];
        }
    }

    /// vals += coef * mats[k] (complex coefficient).
    pub fn add_cplx(&self, k: usize, mat: &SpMat, coef: C64, vals: &mut [C64]) {
        let v = mat.val();
        for &(p, q) in &self.maps[k] {
            vals[q] += coef * v[p];
        }
    }
}

/// Matrices of the model in a fixed order: 0 M, 1 K_b, 2 S, 3 C_b, 4 D_b (when present).
pub(crate) struct ModelPattern<'a> {
    pub model: &'a StructuralModel,
    pub pat: UnionPattern,
}

impl<'a> ModelPattern<'a> {
    pub fn new(model: &'a StructuralModel) -> Result<Self, RomError> {
        Ok(ModelPattern {
            model,
            pat: UnionPattern::new(&Self::matrices_of(model))?,
        })
    }

    /// The model matrices in the pattern's order: M, K_b, S, then C_b and D_b when present.
    pub fn matrices(&self) -> Vec<&'a SpMat> {
        Self::matrices_of(self.model)
    }

    fn matrices_of(m: &'a StructuralModel) -> Vec<&'a SpMat> {
        let mut v: Vec<&SpMat> = vec![&m.m, &m.k_b, &m.s];
        v.extend(m.c_b.as_ref());
        v.extend(m.d_b.as_ref());
        v
    }

    /// Values of K_b + e S on the union pattern.
    pub fn stiffness_values(&self, e: f64) -> Vec<f64> {
        let mut v = vec![0.0; self.pat.nnz()];
        self.pat.add_real(1, &self.model.k_b, 1.0, &mut v);
        self.pat.add_real(2, &self.model.s, e, &mut v);
        v
    }

    /// The coefficients of the model matrices in Z(w, E*) = -w^2 M + K_b + E* S + j w C_b + j D_b,
    /// in the order of [`Self::matrices`].
    pub fn coefficients(&self, omega: f64, e: C64) -> Vec<C64> {
        let m = self.model;
        let mut c = vec![C64::new(-omega * omega, 0.0), C64::new(1.0, 0.0), e];
        if m.c_b.is_some() {
            c.push(C64::new(0.0, omega));
        }
        if m.d_b.is_some() {
            c.push(C64::new(0.0, 1.0));
        }
        c
    }

    /// Values of Z(w, E*) on the union pattern.
    pub fn dynamic_values(&self, omega: f64, e: C64) -> Vec<C64> {
        let mut v = vec![C64::new(0.0, 0.0); self.pat.nnz()];
        for (k, (a, c)) in self
            .matrices()
            .into_iter()
            .zip(self.coefficients(omega, e))
            .enumerate()
        {
            self.pat.add_cplx(k, a, c, &mut v);
        }
        v
    }
}

/// Sparse Cholesky of the real SPD matrix K_b + E_ref S; symbolic analysis shared.
pub(crate) struct SpdSolver {
    symbolic: std::sync::Arc<SymbolicCholesky<usize>>,
    values: Vec<f64>,
}

/// Columns per independent triangular solve in [`SpdSolver::solve_cols`] (fixed, so that
/// the result does not depend on the thread count).
const SOLVE_GROUP: usize = 32;

impl SpdSolver {
    pub fn symbolic(pat: &ModelPattern<'_>) -> Result<SymbolicCholesky<usize>, RomError> {
        factorize_symbolic_cholesky(
            pat.pat.sym.as_ref(),
            Side::Lower,
            Default::default(),
            Default::default(),
        )
        .map_err(|e| RomError::Factorization(format!("symbolic Cholesky failed: {e:?}")))
    }

    pub fn new(
        symbolic: std::sync::Arc<SymbolicCholesky<usize>>,
        pat: &ModelPattern<'_>,
        e_ref: f64,
    ) -> Result<Self, RomError> {
        let a_vals = pat.stiffness_values(e_ref);
        let a = SparseColMatRef::new(pat.pat.sym.as_ref(), &a_vals);
        let mut values = vec![0.0f64; symbolic.len_val()];
        let mut mem = MemBuffer::try_new(
            symbolic.factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default()),
        )
        .map_err(|_| RomError::Factorization("out of memory for the Cholesky workspace".into()))?;
        symbolic
            .factorize_numeric_llt(
                &mut values,
                a,
                Side::Lower,
                Default::default(),
                Par::Seq,
                MemStack::new(&mut mem),
                Default::default(),
            )
            .map_err(|e| {
                RomError::Factorization(format!(
                    "K_b + {e_ref:.4e} S is not positive definite ({e:?}): is the model constrained (no rigid-body modes)?"
                ))
            })?;
        Ok(SpdSolver { symbolic, values })
    }

    /// Solve (K_b + E_ref S) X = RHS in place, groups of columns in parallel.
    pub fn solve_cols(&self, rhs: MatMut<'_, f64>) {
        use rayon::prelude::*;
        rhs.par_col_chunks_mut(SOLVE_GROUP)
            .for_each(|chunk| self.solve_in_place(chunk));
    }

    /// Solve (K_b + E_ref S) X = RHS in place (columns of a column-major n x k matrix).
    pub fn solve_in_place(&self, rhs: MatMut<'_, f64>) {
        let k = rhs.ncols();
        let mut mem = MemBuffer::new(self.symbolic.solve_in_place_scratch::<f64>(k, Par::Seq));
        LltRef::new(&self.symbolic, &self.values).solve_in_place_with_conj(
            Conj::No,
            rhs,
            Par::Seq,
            MemStack::new(&mut mem),
        );
    }
}

/// Complex sparse LU of Z(w, E*) on the union pattern (reference full-model solve).
pub(crate) struct FullSolver<'a> {
    pat: &'a ModelPattern<'a>,
    symbolic: Arc<SymbolicLu<usize>>,
    /// The storage of factors no longer in use, for the next factorisations: a validation set
    /// of 225 points on the 5 mm joint factors 225 times, and an LU's fresh storage
    /// (100-200 MB) costs page faults and zeroing in the kernel each time.
    spare: Mutex<Vec<LuStorage>>,
}

/// The numeric LU and its factorisation workspace, reused across factorisations of one
/// symbolic analysis (faer refills them in place).
struct LuStorage {
    numeric: NumericLu<usize, C64>,
    work: MemBuffer,
}

/// The most factors' storage a [`FullSolver`] keeps for reuse: one per thread of the pool that
/// factors at the same time (no more memory than the factors in use at once held); more are
/// freed.
fn spare_factors() -> usize {
    rayon::current_num_threads().max(1)
}

/// A symbolic LU analysis with the union pattern it was made for, shared by the models of
/// that pattern (a term ROM's cases: the springs, a strip and the beam's damping keep the
/// model's pattern).
pub(crate) struct SharedLuSymbolic {
    col_ptr: Vec<usize>,
    row_idx: Vec<usize>,
    symbolic: Arc<SymbolicLu<usize>>,
}

impl SharedLuSymbolic {
    pub fn new(pat: &ModelPattern<'_>) -> Result<Self, RomError> {
        Ok(SharedLuSymbolic {
            col_ptr: pat.pat.sym.col_ptr().to_vec(),
            row_idx: pat.pat.sym.row_idx().to_vec(),
            symbolic: Arc::new(lu_symbolic(pat)?),
        })
    }

    /// The solver of `pat`: this analysis when `pat` has its pattern, else a new one.
    pub fn solver_for<'a>(&self, pat: &'a ModelPattern<'a>) -> Result<FullSolver<'a>, RomError> {
        let same = pat.pat.sym.col_ptr() == self.col_ptr.as_slice()
            && pat.pat.sym.row_idx() == self.row_idx.as_slice();
        if same {
            Ok(FullSolver {
                pat,
                symbolic: self.symbolic.clone(),
                spare: Mutex::new(Vec::new()),
            })
        } else {
            FullSolver::new(pat)
        }
    }
}

fn lu_symbolic(pat: &ModelPattern<'_>) -> Result<SymbolicLu<usize>, RomError> {
    factorize_symbolic_lu(pat.pat.sym.as_ref(), Default::default())
        .map_err(|e| RomError::Factorization(format!("symbolic LU failed: {e:?}")))
}

impl<'a> FullSolver<'a> {
    pub fn new(pat: &'a ModelPattern<'a>) -> Result<Self, RomError> {
        Ok(FullSolver {
            pat,
            symbolic: Arc::new(lu_symbolic(pat)?),
            spare: Mutex::new(Vec::new()),
        })
    }

    /// The complex sparse LU of Z(w, E*), kept for several solves. Its storage is a released
    /// factor's when there is one (the values are all refilled: the factor is the same).
    pub fn factor(&self, omega: f64, e: C64) -> Result<FullLu<'_>, RomError> {
        let vals = self.pat.dynamic_values(omega, e);
        let a = SparseColMatRef::new(self.pat.pat.sym.as_ref(), &vals);
        let spare = self
            .spare
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
            .pop();
        let mut storage = match spare {
            Some(s) => s,
            None => LuStorage {
                numeric: NumericLu::<usize, C64>::new(),
                work: MemBuffer::try_new(
                    self.symbolic
                        .factorize_numeric_lu_scratch::<C64>(Par::Seq, Default::default()),
                )
                .map_err(|_| {
                    RomError::Factorization("out of memory for the LU workspace".into())
                })?,
            },
        };
        self.symbolic
            .factorize_numeric_lu(
                &mut storage.numeric,
                a,
                Par::Seq,
                MemStack::new(&mut storage.work),
                Default::default(),
            )
            .map_err(|err| {
                RomError::Factorization(format!(
                    "Z is singular at {:.3} Hz, E* = {e} Pa ({err:?})",
                    omega / (2.0 * std::f64::consts::PI)
                ))
            })?;
        Ok(FullLu {
            symbolic: &self.symbolic,
            spare: &self.spare,
            storage: Some(storage),
            vals,
        })
    }

    /// X = Z(w, E*)^-1 RHS, RHS given as real columns (n x k, column-major).
    /// Z(w, E*)^-1 rhs by sparse LU with two steps of iterative refinement, and the
    /// solution's attainable relative accuracy: the size of the second refinement step,
    /// max |dx| / max |x|. A well-conditioned Z gives a second step near the rounding
    /// error of x; where Z is so ill-conditioned that refinement in double precision
    /// stagnates (a stiff beam held by a soft layer near a resonance), that step measures
    /// how far the full model's own solution can be trusted.
    pub fn solve(
        &self,
        omega: f64,
        e: C64,
        rhs: &faer::Mat<f64>,
    ) -> Result<(faer::Mat<C64>, f64), RomError> {
        let lu = self.factor(omega, e)?;
        let vals = &lu.vals;
        let k = rhs.ncols();
        let mut x = faer::Mat::<C64>::from_fn(rhs.nrows(), k, |i, j| C64::new(rhs[(i, j)], 0.0));
        lu.solve_in_place(x.as_mut());
        let sym = self.pat.pat.sym.as_ref();
        let (n, rows) = (rhs.nrows(), sym.row_idx());
        let mut floor = 0.0;
        // x and r row-major (one row's k values side by side), so that the pass over Z's
        // pattern updates a row's k residuals at once
        let mut xr = vec![C64::new(0.0, 0.0); n * k];
        let mut rr = vec![C64::new(0.0, 0.0); n * k];
        for _ in 0..2 {
            // r = rhs - Z x, then x += Z^-1 r
            for i in 0..n {
                for jc in 0..k {
                    xr[i * k + jc] = x[(i, jc)];
                    rr[i * k + jc] = C64::new(rhs[(i, jc)], 0.0);
                }
            }
            for col in 0..n {
                let xv = &xr[col * k..(col + 1) * k];
                for p in sym.col_range(col) {
                    let v = vals[p];
                    let row = &mut rr[rows[p] * k..(rows[p] + 1) * k];
                    for (ri, &xi) in row.iter_mut().zip(xv) {
                        *ri -= v * xi;
                    }
                }
            }
            let mut r = faer::Mat::<C64>::from_fn(n, k, |i, j| rr[i * k + j]);
            lu.solve_in_place(r.as_mut());
            let (mut dn, mut xn) = (0.0f64, 0.0f64);
            for jc in 0..k {
                for i in 0..rhs.nrows() {
                    dn = dn.max(r[(i, jc)].norm());
                    xn = xn.max(x[(i, jc)].norm());
                    x[(i, jc)] += r[(i, jc)];
                }
            }
            floor = if xn > 0.0 { dn / xn } else { 0.0 };
        }
        Ok((x, floor))
    }
}

/// A complex sparse LU of Z(w, E*) ([`FullSolver::factor`]).
pub(crate) struct FullLu<'s> {
    symbolic: &'s SymbolicLu<usize>,
    /// Where the storage goes back when the factor is dropped.
    spare: &'s Mutex<Vec<LuStorage>>,
    /// The factor (taken back on drop).
    storage: Option<LuStorage>,
    /// Z's values on the union pattern.
    vals: Vec<C64>,
}

impl Drop for FullLu<'_> {
    fn drop(&mut self) {
        if let Some(s) = self.storage.take() {
            let mut spare = self
                .spare
                .lock()
                .unwrap_or_else(|poisoned| poisoned.into_inner());
            if spare.len() < spare_factors() {
                spare.push(s);
            }
        }
    }
}

impl FullLu<'_> {
    /// Solve Z X = RHS in place (complex columns).
    pub fn solve_in_place(&self, rhs: MatMut<'_, C64>) {
        let k = rhs.ncols();
        let mut mem = MemBuffer::new(self.symbolic.solve_in_place_scratch::<C64>(k, Par::Seq));
        let numeric = &self
            .storage
            .as_ref()
            .expect("a factor until dropped")
            .numeric;
        LuRef::new_unchecked(self.symbolic, numeric).solve_in_place_with_conj(
            Conj::No,
            rhs,
            Par::Seq,
            MemStack::new(&mut mem),
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fe::joint::{build_joint_model, JointSpec, MeshParams, MeshSize};

    /// A factor made in a released factor's storage is the factor made in fresh storage: the
    /// same solutions, bit for bit, whatever the point the storage was last used for.
    #[test]
    fn a_factor_in_reused_storage_is_the_fresh_factor() {
        let spec = JointSpec {
            mesh: MeshParams {
                size: MeshSize::ElementSize(0.02),
                ..MeshParams::default()
            },
            ..JointSpec::paper()
        };
        let (model, _) = build_joint_model(&spec).unwrap();
        let pat = ModelPattern::new(&model).unwrap();
        let n = model.n_dof();
        let rhs = faer::Mat::<f64>::from_fn(n, 2, |i, j| ((i * 7 + j * 3) % 11) as f64 - 5.0);
        let (a, b) = (
            (2.0 * std::f64::consts::PI * 40.0, C64::new(6.7e6, 0.9e6)),
            (2.0 * std::f64::consts::PI * 310.0, C64::new(9.1e6, 2.4e6)),
        );
        let fresh = |(w, e): (f64, C64)| FullSolver::new(&pat).unwrap().solve(w, e, &rhs).unwrap();
        let solver = FullSolver::new(&pat).unwrap();
        let first = solver.solve(a.0, a.1, &rhs).unwrap();
        let other = solver.solve(b.0, b.1, &rhs).unwrap();
        let again = solver.solve(a.0, a.1, &rhs).unwrap();
        assert_eq!(solver.spare.lock().unwrap().len(), 1, "one storage, reused");
        let bits = |m: &faer::Mat<C64>| -> Vec<(u64, u64)> {
            (0..m.ncols())
                .flat_map(|j| (0..m.nrows()).map(move |i| (i, j)))
                .map(|(i, j)| (m[(i, j)].re.to_bits(), m[(i, j)].im.to_bits()))
                .collect()
        };
        assert_eq!(bits(&first.0), bits(&again.0));
        assert_eq!(first.1.to_bits(), again.1.to_bits());
        assert_eq!(bits(&first.0), bits(&fresh(a).0));
        assert_eq!(bits(&other.0), bits(&fresh(b).0));
        assert_ne!(bits(&first.0), bits(&other.0));
    }
}
