//! The full-model FRFs a term ROM's certificate compares with ([`super::term_build`]): at
//! every (term, value) case the modified full model ([`super::term_build::model_with_term`]) on
//! the validation grid of moduli x lines, by sparse LU at every point
//! ([`Reference::SparseLu`]) or by the shifted Krylov solver below ([`Reference::Shifted`], or
//! [`Reference::Iterative`]: a term ROM's cases have no GMRES reference of their own).
//!
//! Shifted Krylov: for a model without viscous damping (C_b absent) the dynamic stiffness of a
//! case at one modulus is Z(w) = A - w^2 M with A = K_b + E* S + j D_b the same at every line,
//! so A - s M = F (I + (sigma - s) T) with F = A - sigma M and T = F^-1 M: every line's system
//! is a shifted system of one operator, and the block Krylov space of T started at F^-1 B
//! (B the unit loads of the inputs) serves all lines ([`shifted_lines`]). It costs one complex
//! sparse LU of F (sigma at the middle of the band in w^2) and a few solves with it per
//! (case, modulus) instead of one LU per line: on the paper's joint on base springs (10,695
//! DOFs, 4 inputs, 25 lines) 40 Krylov vectors resolve every line of every case to a residual
//! of 1e-10, and the 8 cases' reference took 19 s against 248 s for the LU at every point
//! (the same load). Each line is done when its residual, in the norm of the preconditioned
//! system (that of F^-1 (b - Z x), the measure of the LU's refinement step) and estimated by
//! the Arnoldi relation (exact up to rounding), is at most [`SHIFTED_RESIDUAL_TOL`] of
//! ||F^-1 b||: 1e-10 and 1e-13 gave the same FRFs to 1e-13 of their peaks.
//!
//! Where the reference is not that of a sparse LU at the point, the handling is the
//! effect-free ROM's with its GMRES reference ([`super::certify::build_rom`]): the lines the
//! Krylov space does not resolve within [`SHIFTED_MAX_VECTORS`] vectors, and the points where
//! the ROM misses the reference by more than the tolerance when they are at most
//! 1 / `MAX_DIRECT_FRACTION_INV` of all points, are solved by sparse LU
//! ([`CaseRefs::solve_directly`]). The two solvers agree to the full model's attainable
//! accuracy: at the quasi-static line (1 Hz) of the softest modulus, where the LU's own
//! refinement stalls at 1-3e-8 of the largest response, they differ by up to 3e-7 of an FRF's
//! peak (an FRF some 10 times smaller than the largest), both with residuals at rounding
//! level; everywhere else by far less.
//! A model with C_b (Z quadratic in w) gets the sparse LU at every point.
//!
//! The symbolic LU analysis is made once and shared by the cases of the same pattern.

use super::certify::reference_points_with;
use super::dense::DenseLu;
use super::sparse::{FullSolver, ModelPattern, SharedLuSymbolic};
use super::term_build::model_with_term;
use super::terms::TermSpec;
use super::{Reference, RomError};
use crate::common::C64;
use crate::fe::model::StructuralModel;
use crate::linalg::blocked::Csr;
use faer::Mat;
use rayon::prelude::*;

/// Full-model receptances of one case: `[modulus][line][output * n_in + input]`.
pub(crate) type CaseReference = Vec<Vec<Vec<C64>>>;

/// [`shifted_lines`]: a line is resolved when its preconditioned residual is at most this
/// fraction of ||F^-1 b|| (see the module doc).
pub const SHIFTED_RESIDUAL_TOL: f64 = 1e-10;
/// [`shifted_lines`]: the most Krylov vectors per (case, modulus); the lines not resolved
/// by then are solved by sparse LU.
pub const SHIFTED_MAX_VECTORS: usize = 320;

/// The certificate's full-model FRFs of every (term, value) case and how they were made.
pub(crate) struct CaseRefs {
    /// Per case.
    pub h: Vec<CaseReference>,
    /// Per case: the validation points (modulus, line) solved by sparse LU.
    pub direct: Vec<Vec<(usize, usize)>>,
    /// The shifted Krylov solves (None: sparse LU everywhere).
    pub shifted: Option<ShiftedStats>,
    /// The symbolic LU analysis of the effect-free model's pattern.
    symbolic: SharedLuSymbolic,
}

/// How the shifted Krylov solves went, over all cases and moduli.
#[derive(Clone, Debug, Default)]
pub(crate) struct ShiftedStats {
    /// The largest final relative residual of a resolved line.
    pub max_residual: f64,
    /// The largest Krylov space (vectors).
    pub max_vectors: usize,
}

/// The validation grid and the loads of a reference.
pub(crate) struct Grid<'g> {
    pub inputs: &'g [usize],
    pub moduli: &'g [C64],
    pub lines: &'g [f64],
}

impl CaseRefs {
    /// The reference of every case (`cases` = (term index, value)) of `model` with `terms`:
    /// the shifted Krylov solver with the LU where it does not resolve a line
    /// ([`Reference::Shifted`] or [`Reference::Iterative`], a model without C_b), else the sparse
    /// LU at every point.
    pub fn new(
        model: &StructuralModel,
        terms: &[TermSpec],
        cases: &[(usize, f64)],
        g: &Grid<'_>,
        reference: Reference,
    ) -> Result<CaseRefs, RomError> {
        let mut out = CaseRefs {
            h: Vec::with_capacity(cases.len()),
            direct: Vec::with_capacity(cases.len()),
            shifted: None,
            symbolic: SharedLuSymbolic::new(&ModelPattern::new(model)?)?,
        };
        let shifted = matches!(reference, Reference::Iterative { .. } | Reference::Shifted)
            && model.c_b.is_none();
        if shifted {
            out.shifted = Some(ShiftedStats::default());
        }
        let all: Vec<(usize, usize)> = (0..g.moduli.len())
            .flat_map(|m| (0..g.lines.len()).map(move |l| (m, l)))
            .collect();
        for (c, &(k, v)) in cases.iter().enumerate() {
            let case = model_with_term(model, &terms[k], v)?;
            if !shifted {
                let h =
                    reference_points_with(&case, g.inputs, g.moduli, g.lines, &all, &out.symbolic)?;
                let mut per_modulus = vec![Vec::with_capacity(g.lines.len()); g.moduli.len()];
                for (&(m, _), (hv, _)) in all.iter().zip(h) {
                    per_modulus[m].push(hv);
                }
                out.h.push(per_modulus);
                out.direct.push(all.clone());
                continue;
            }
            let pat = ModelPattern::new(&case)?;
            let solver = out.symbolic.solver_for(&pat)?;
            let per_modulus: Vec<ShiftedLines> = g
                .moduli
                .par_iter()
                .map(|&e| {
                    shifted_lines(
                        &solver,
                        &case,
                        g.inputs,
                        e,
                        g.lines,
                        SHIFTED_RESIDUAL_TOL,
                        SHIFTED_MAX_VECTORS,
                    )
                })
                .collect::<Result<_, _>>()?;
            let st = out.shifted.as_mut().expect("shifted statistics");
            let mut h = Vec::with_capacity(g.moduli.len());
            let mut missing = Vec::new();
            for (m, r) in per_modulus.into_iter().enumerate() {
                st.max_residual = st.max_residual.max(r.max_residual);
                st.max_vectors = st.max_vectors.max(r.vectors);
                let mut lines = Vec::with_capacity(g.lines.len());
                for (l, x) in r.h.into_iter().enumerate() {
                    lines.push(x.unwrap_or_else(|| {
                        missing.push((m, l));
                        Vec::new()
                    }));
                }
                h.push(lines);
            }
            out.h.push(h);
            out.direct.push(Vec::new());
            // the lines it did not resolve, solved directly instead
            out.solve_directly(model, terms, cases, c, &missing, g)?;
        }
        Ok(out)
    }

    /// Case `c`'s reference at `points` (modulus, line) by sparse LU, the points recorded as
    /// direct.
    pub fn solve_directly(
        &mut self,
        model: &StructuralModel,
        terms: &[TermSpec],
        cases: &[(usize, f64)],
        c: usize,
        points: &[(usize, usize)],
        g: &Grid<'_>,
    ) -> Result<(), RomError> {
        if points.is_empty() {
            return Ok(());
        }
        let (k, v) = cases[c];
        let m = model_with_term(model, &terms[k], v)?;
        let lu = reference_points_with(&m, g.inputs, g.moduli, g.lines, points, &self.symbolic)?;
        for (&(mi, l), (h, _)) in points.iter().zip(lu) {
            self.h[c][mi][l] = h;
        }
        self.direct[c].extend_from_slice(points);
        Ok(())
    }
}

/// [`shifted_lines`]' result for one (case, modulus): per line its receptances (n_out x n_in
/// row-major; None where not resolved), the largest relative residual of a resolved line and
/// the Krylov space's size.
pub(crate) struct ShiftedLines {
    pub h: Vec<Option<Vec<C64>>>,
    pub max_residual: f64,
    pub vectors: usize,
}

/// A resolved line of [`shifted_lines`]: its receptances and relative residual.
type ResolvedLine = (Vec<C64>, f64);

/// An orthonormal basis Q (complex, Euclidean) grown a block at a time, with B_out^T Q.
struct Arnoldi {
    /// n x capacity; the first `m` columns hold Q.
    q: Mat<C64>,
    m: usize,
    /// B_out^T Q (n_out x capacity).
    outs: Mat<C64>,
}

impl Arnoldi {
    /// Orthonormalise the columns of `w` against Q (classical Gram-Schmidt twice as block
    /// products, then modified Gram-Schmidt twice within the block) and append those whose
    /// norm stays above 1e-12 of their norm before, at most `limit` vectors in all. Returns the
    /// coefficients of `w` on Q after the append (rows: Q's vectors, columns: w's).
    fn absorb(&mut self, model: &StructuralModel, mut w: Mat<C64>, limit: usize) -> Mat<C64> {
        use faer::linalg::matmul::matmul;
        use faer::{Accum, Par};
        let (n, k, m0) = (w.nrows(), w.ncols(), self.m);
        let one = C64::new(1.0, 0.0);
        let mut coef = Mat::<C64>::zeros(m0 + k, k);
        let norm0: Vec<f64> = (0..k).map(|j| w.col(j).norm_l2()).collect();
        if m0 > 0 {
            let q = self.q.as_ref().subcols(0, m0);
            for _ in 0..2 {
                let mut c = Mat::<C64>::zeros(m0, k);
                matmul(
                    c.as_mut(),
                    Accum::Replace,
                    q.adjoint(),
                    w.as_ref(),
                    one,
                    Par::Seq,
                );
                matmul(w.as_mut(), Accum::Add, q, c.as_ref(), -one, Par::Seq);
                for j in 0..k {
                    for i in 0..m0 {
                        coef[(i, j)] += c[(i, j)];
                    }
                }
            }
        }
        for j in 0..k {
            for _ in 0..2 {
                for i in m0..self.m {
                    let c: C64 = self
                        .q
                        .col(i)
                        .iter()
                        .zip(w.col(j).iter())
                        .map(|(a, b)| a.conj() * b)
                        .sum();
                    for (x, a) in w.col_mut(j).iter_mut().zip(self.q.col(i).iter()) {
                        *x -= c * a;
                    }
                    coef[(i, j)] += c;
                }
            }
            let nrm = w.col(j).norm_l2();
            if nrm > 1e-12 * norm0[j] && nrm > 0.0 && self.m < limit {
                if self.m == self.q.ncols() {
                    // double the storage (amortised copies)
                    let cap = (2 * self.m).max(16);
                    let mut q = Mat::<C64>::zeros(n, cap);
                    q.as_mut()
                        .subcols_mut(0, self.m)
                        .copy_from(self.q.as_ref().subcols(0, self.m));
                    self.q = q;
                    let mut o = Mat::<C64>::zeros(self.outs.nrows(), cap);
                    o.as_mut()
                        .subcols_mut(0, self.m)
                        .copy_from(self.outs.as_ref().subcols(0, self.m));
                    self.outs = o;
                }
                let inv = 1.0 / nrm;
                for (x, a) in self.q.col_mut(self.m).iter_mut().zip(w.col(j).iter()) {
                    *x = a * inv;
                }
                for (o, pt) in model.points.iter().enumerate() {
                    self.outs[(o, self.m)] = pt
                        .dofs
                        .iter()
                        .map(|&(d, wt)| self.q[(d, self.m)] * wt)
                        .sum();
                }
                coef[(self.m, j)] = C64::new(nrm, 0.0);
                self.m += 1;
            }
        }
        coef.as_ref().subrows(0, self.m).to_owned()
    }
}

/// The shifted Krylov solver of one (case, modulus) at every line (the module doc): the full
/// model's Z(w) = A - w^2 M (A = K_b + E* S + j D_b; the model has no C_b) solved for all
/// `lines` from one complex LU of F = A - sigma M (sigma the middle of the lines' range of
/// w^2) and the block Krylov space of T = F^-1 M started at R0 = F^-1 B: A - s M =
/// F (I + (sigma - s) T), so with the Arnoldi relation T Q_a = Q H every line's solution is
/// the Galerkin (FOM) one x = Q_a y, (I + (sigma - s) H_a) y = Q_a^H R0, whose residual
/// F^-1 (b - Z x) = -(sigma - s) Q H_(rest, a) y is known without forming x. A line is done
/// when that residual is at most `tol` of ||F^-1 b|| for every input; the lines are checked
/// as the space grows by half, and those not resolved within `max_vectors` vectors are None.
/// Sequential but for the lines' reduced solves (each its own), so the result does not
/// depend on the thread count.
pub(crate) fn shifted_lines(
    solver: &FullSolver<'_>,
    model: &StructuralModel,
    inputs: &[usize],
    e: C64,
    lines: &[f64],
    tol: f64,
    max_vectors: usize,
) -> Result<ShiftedLines, RomError> {
    let n = model.n_dof();
    let n_out = model.points.len();
    let p = inputs.len();
    let zero = C64::new(0.0, 0.0);
    let mut out = ShiftedLines {
        h: vec![None; lines.len()],
        max_residual: 0.0,
        vectors: 0,
    };
    let (lo, hi) = lines
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(a, b), &w| (a.min(w), b.max(w)));
    let sigma = 0.5 * (lo * lo + hi * hi);
    // (a singular F leaves every line to the sparse LU at the line)
    let Ok(lu) = solver.factor(sigma.sqrt(), e) else {
        return Ok(out);
    };
    let mass = Csr::from_csc(&model.m);
    let mut r0 = Mat::<C64>::zeros(n, p);
    for (jj, &j) in inputs.iter().enumerate() {
        for &(d, w) in &model.points[j].dofs {
            r0[(d, jj)] += C64::new(w, 0.0);
        }
    }
    lu.solve_in_place(r0.as_mut());
    let r0_norms: Vec<f64> = (0..p).map(|c| r0.col(c).norm_l2()).collect();
    let limit = max_vectors.max(p);
    let mut kr = Arnoldi {
        q: Mat::zeros(n, 0),
        m: 0,
        outs: Mat::zeros(n_out, 0),
    };
    let beta = kr.absorb(model, r0, limit);
    // H (rows: Q's vectors, columns: the vectors whose T-image is in Q)
    let mut h = Mat::<C64>::zeros(0, 0);
    let mut applied = 0usize;
    let mut next_check = (4 * p).max(8);
    loop {
        // the next block: T Q[:, applied..m]
        let (a0, m0) = (applied, kr.m);
        if a0 == m0 {
            break; // an invariant space: the last check saw every line it can resolve
        }
        let k = m0 - a0;
        let q = kr.q.as_ref().subcols(a0, k);
        let split = Mat::<f64>::from_fn(n, 2 * k, |r, c| {
            let z = q[(r, c % k)];
            if c < k {
                z.re
            } else {
                z.im
            }
        });
        let mq = mass.mul(split.as_ref());
        let mut w = Mat::<C64>::from_fn(n, k, |r, c| C64::new(mq[(r, c)], mq[(r, k + c)]));
        lu.solve_in_place(w.as_mut());
        let coef = kr.absorb(model, w, limit);
        let m = kr.m;
        h.resize_with(m, m0, |_, _| zero);
        for c in 0..k {
            for r in 0..m {
                h[(r, a0 + c)] = coef[(r, c)];
            }
        }
        applied = m0;
        let last = m == applied || m >= limit;
        if applied < next_check && !last {
            continue;
        }
        next_check = applied + applied / 2;
        let a = applied;
        let pending: Vec<usize> = (0..lines.len()).filter(|&l| out.h[l].is_none()).collect();
        let solved: Vec<(usize, Option<ResolvedLine>)> = pending
            .par_iter()
            .map(|&l| {
                let s = lines[l] * lines[l];
                let shift = sigma - s;
                let mut zr = vec![zero; a * a];
                for i in 0..a {
                    for j in 0..a {
                        zr[i * a + j] = h[(i, j)] * shift;
                    }
                    zr[i * a + i] += 1.0;
                }
                let Some(f) = DenseLu::factor(a, zr) else {
                    return (l, None);
                };
                let mut hl = vec![zero; n_out * p];
                let mut res = 0.0f64;
                for c in 0..p {
                    let mut y: Vec<C64> = (0..a)
                        .map(|i| if i < beta.nrows() { beta[(i, c)] } else { zero })
                        .collect();
                    f.solve(&mut y);
                    let r2: f64 = (a..m)
                        .map(|i| (0..a).map(|j| h[(i, j)] * y[j]).sum::<C64>().norm_sqr())
                        .sum();
                    let rel = shift.abs() * r2.sqrt() / r0_norms[c].max(f64::MIN_POSITIVE);
                    res = res.max(if rel.is_nan() { f64::INFINITY } else { rel });
                    for o in 0..n_out {
                        hl[o * p + c] = (0..a).map(|j| kr.outs[(o, j)] * y[j]).sum();
                    }
                }
                (l, (res <= tol).then_some((hl, res)))
            })
            .collect();
        for (l, r) in solved {
            if let Some((hl, res)) = r {
                out.max_residual = out.max_residual.max(res);
                out.h[l] = Some(hl);
            }
        }
        if last || out.h.iter().all(|x| x.is_some()) {
            break;
        }
    }
    out.vectors = kr.m;
    Ok(out)
}
