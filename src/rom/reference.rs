//! Full-model reference FRFs for the certificate without a complex factorisation.
//!
//! A complex sparse LU of Z(w, E*) costs about 0.3 s and 100 MB on the 5 mm mesh and 37 s
//! and 4 GB on the 2.5 mm mesh, once per validation point. Instead each validation point's
//! full-model system Z x = b (one per line, modulus and input) is solved by GMRES with the
//! ROM as a coarse space (deflation) and a real Cholesky factor as preconditioner:
//!
//! - start from the ROM's (Galerkin) solution x0 = V Z_r^-1 V^T b, so r0 = b - Z x0 has
//!   V^T r0 = 0;
//! - right preconditioner Q = Pi P^-1 with P = K_b + e S, the basis's real Cholesky factor
//!   at the E_ref e nearest to |E*| (log scale), and Pi p = p - V Z_r^-1 V^T Z p, which
//!   removes from p what the ROM already resolves (the band's modes), so that Z Q acts on
//!   the stiff, high-order remainder where Z ~ K_b + E* S and P^-1 Z is close to identity;
//! - Arnoldi with modified Gram-Schmidt twice and complex Givens rotations; converged when
//!   the residual ||b - Z x|| <= `tol` ||b|| (the GMRES estimate, exact up to rounding);
//! - only the outputs B_out^T x are kept: x = x0 + sum_i y_i Q u_i, so each Q u_i is reduced
//!   to its values at the observation points as soon as it is made.
//!
//! Systems of one modulus run in lockstep so that the preconditioner solves and sparse
//! products are blocked over their columns. All kernels are deterministic over fixed chunks
//! ([`crate::linalg::blocked`]).
//!
//! Accuracy: on a near-resonant, lightly damped validation point (E'' = 0.01 MPa, eta 0.002)
//! Z is so ill-conditioned that the sparse LU's own residual is ~1e-8 ||b|| and its FRF is off
//! by a few 1e-8 of the peak; GMRES drives the residual to `tol` there as well (test
//! `rom_joint::gmres_reference_agrees_with_sparse_lu_at_10mm`).

use super::basis::BasisBuilder;
use super::reduced::ReducedModel;
use super::RomError;
use crate::common::C64;
use crate::linalg::blocked::{nn_acc, tn};
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::lu::partial_pivoting::{factor, solve};
use faer::{Conj, Mat, Par};
use rayon::prelude::*;

/// How the reference solves went.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ReferenceStats {
    /// Largest number of GMRES iterations over all validation points.
    pub max_iterations: usize,
    /// Largest final relative residual ||b - Z x|| / ||b||.
    pub max_residual: f64,
    /// Points that did not reach the tolerance within the iteration limit.
    pub not_converged: usize,
}

/// h[m][l][i * n_in + j]: receptance of output i to input j at modulus m, line l.
pub(crate) type Receptances = Vec<Vec<Vec<C64>>>;

/// One active system and its new Arnoldi vector and outputs.
type Step<'a> = (&'a mut Gmres, (Vec<C64>, Vec<C64>));

/// Systems solved together (columns of the blocked kernels; bounds the Arnoldi memory).
const SYSTEMS_PER_BATCH: usize = 32;

/// Dense complex LU with partial pivoting (faer's blocked kernel, sequential). Not
/// [`super::dense::DenseLu`]: the reduced systems at lightly damped, near-resonant validation
/// points are ill-conditioned enough that the two LUs' rounding moves the 10 mm joint's worst
/// certificate error by about 2e-8; the stated numbers and the LU comparison test were
/// measured with this one.
struct DenseLu {
    lu: Mat<C64>,
    fwd: Vec<usize>,
    bwd: Vec<usize>,
}

impl DenseLu {
    fn new(mut a: Mat<C64>) -> Option<DenseLu> {
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

    /// Solve A x = b in place.
    fn solve(&self, b: &mut [C64]) {
        let n = self.lu.nrows();
        let mut mem = MemBuffer::new(solve::solve_in_place_scratch::<usize, C64>(n, 1, Par::Seq));
        let perm = faer::perm::PermRef::new_checked(&self.fwd, &self.bwd, n);
        solve::solve_in_place_with_conj(
            self.lu.as_ref(),
            self.lu.as_ref(),
            perm,
            Conj::No,
            faer::MatMut::from_column_major_slice_mut(b, n, 1),
            Par::Seq,
            MemStack::new(&mut mem),
        );
    }
}

/// Column `s` of a complex block stored as (re, im) column pairs of a real matrix.
fn get(m: &Mat<f64>, s: usize) -> Vec<C64> {
    (0..m.nrows())
        .map(|i| C64::new(m[(i, 2 * s)], m[(i, 2 * s + 1)]))
        .collect()
}

/// sum_k A_k V (coef_k(s) c_s) subtracted from `out` (n x 2S), c_s complex d-vectors.
fn sub_zv(basis: &BasisBuilder<'_>, coefs: &[Vec<C64>], cs: &[Vec<C64>], out: &mut Mat<f64>) {
    let d = basis.size();
    for k in 0..basis.n_ops() {
        let g = Mat::<f64>::from_fn(d, 2 * cs.len(), |i, col| {
            let v = coefs[col / 2][k] * cs[col / 2][i];
            if col % 2 == 0 {
                v.re
            } else {
                v.im
            }
        });
        nn_acc(out.as_mut(), basis.av(k).as_ref(), g.as_ref(), -1.0);
    }
}

/// One system's GMRES state.
struct Gmres {
    /// Arnoldi vectors u_0..u_j.
    u: Vec<Vec<C64>>,
    /// Hessenberg columns (after rotation): h[j] has j + 2 entries.
    h: Vec<Vec<C64>>,
    rot: Vec<(f64, C64)>,
    g: Vec<C64>,
    /// Outputs of Q u_j at the observation points.
    o: Vec<Vec<C64>>,
    b_norm: f64,
    done: bool,
}

impl Gmres {
    fn residual(&self) -> f64 {
        self.g.last().map(|v| v.norm()).unwrap_or(0.0)
    }

    /// Arnoldi step with w = Z Q u_j (MGS twice), Givens update; marks convergence.
    fn step(&mut self, mut w: Vec<C64>, tol: f64) {
        let j = self.h.len();
        let mut col = vec![C64::new(0.0, 0.0); j + 2];
        for _ in 0..2 {
            for (i, ui) in self.u.iter().enumerate() {
                let hij: C64 = ui.iter().zip(&w).map(|(a, b)| a.conj() * b).sum();
                for (x, a) in w.iter_mut().zip(ui) {
                    *x -= hij * a;
                }
                col[i] += hij;
            }
        }
        let hn = w.iter().map(|z| z.norm_sqr()).sum::<f64>().sqrt();
        col[j + 1] = C64::new(hn, 0.0);
        let inv = if hn > 0.0 { 1.0 / hn } else { 0.0 };
        w.iter_mut().for_each(|z| *z *= inv);
        self.u.push(w);
        for (k, &(c, sn)) in self.rot.iter().enumerate() {
            let (x, y) = (col[k], col[k + 1]);
            col[k] = c * x + sn * y;
            col[k + 1] = -sn.conj() * x + c * y;
        }
        let (a, b) = (col[j], col[j + 1]);
        let rr = (a.norm_sqr() + b.norm_sqr()).sqrt();
        let (c, sn) = if rr == 0.0 {
            (1.0, C64::new(0.0, 0.0))
        } else if a.norm() == 0.0 {
            (0.0, C64::new(1.0, 0.0))
        } else {
            (a.norm() / rr, (a / a.norm()) * b.conj() / rr)
        };
        col[j] = c * a + sn * b;
        col[j + 1] = C64::new(0.0, 0.0);
        self.rot.push((c, sn));
        let gj = self.g[j];
        self.g[j] = c * gj;
        self.g.push(-sn.conj() * gj);
        self.h.push(col);
        if self.residual() <= tol * self.b_norm || hn == 0.0 {
            self.done = true;
        }
    }

    /// y with H y = g (upper triangular, one unknown per step).
    fn coefficients(&self) -> Vec<C64> {
        let k = self.rot.len();
        let mut y = vec![C64::new(0.0, 0.0); k];
        for i in (0..k).rev() {
            let mut acc = self.g[i];
            for j in i + 1..k {
                acc -= self.h[j][i] * y[j];
            }
            y[i] = acc / self.h[i][i];
        }
        y
    }
}

/// Full-model receptances h[m][l] (n_out x n_in row-major) on the validation set; `rom` is
/// the reduced model of `basis` (its coarse space).
pub(crate) fn reference(
    basis: &BasisBuilder<'_>,
    rom: &ReducedModel,
    inputs: &[usize],
    moduli: &[C64],
    lines: &[f64],
    tol: f64,
    max_iter: usize,
) -> Result<(Receptances, ReferenceStats), RomError> {
    let model = basis.model();
    let n_ops = basis.n_ops();
    let n = model.n_dof();
    let d = basis.size();
    let n_out = model.points.len();
    let n_in = inputs.len();
    let v = basis.v();
    let bw = &rom.b_r; // V^T B_all (d x n_out), inputs are columns of it
    let out_of = |x: &[C64]| -> Vec<C64> {
        model
            .points
            .iter()
            .map(|p| p.dofs.iter().map(|&(dof, w)| x[dof] * w).sum())
            .collect()
    };
    let mut stats = ReferenceStats::default();
    let mut out = vec![vec![vec![C64::new(0.0, 0.0); n_out * n_in]; lines.len()]; moduli.len()];
    for (m, &e) in moduli.iter().enumerate() {
        let pre = basis.nearest_factor(e.norm()).ok_or_else(|| {
            RomError::Params("the basis keeps no Cholesky factor for the reference".into())
        })?;
        let coef_l: Vec<Vec<C64>> = lines
            .iter()
            .map(|&w| basis.pattern().coefficients(w, e))
            .collect();
        let lus: Vec<DenseLu> = lines
            .par_iter()
            .map(|&w| {
                let z = rom.z_r(w, e);
                DenseLu::new(Mat::from_fn(d, d, |i, j| z[i * d + j])).ok_or_else(|| {
                    RomError::Factorization(format!(
                        "the reduced system is singular at {:.3} Hz, E* = {e} Pa",
                        w / (2.0 * std::f64::consts::PI)
                    ))
                })
            })
            .collect::<Result<_, _>>()?;
        let systems: Vec<(usize, usize)> = (0..lines.len())
            .flat_map(|l| (0..n_in).map(move |jj| (l, jj)))
            .collect();
        for batch in systems.chunks(SYSTEMS_PER_BATCH) {
            let ns = batch.len();
            let coefs: Vec<Vec<C64>> = batch.iter().map(|&(l, _)| coef_l[l].clone()).collect();
            // ROM solution and its residual
            let y0: Vec<Vec<C64>> = batch
                .iter()
                .map(|&(l, jj)| {
                    let mut y: Vec<C64> =
                        (0..d).map(|i| C64::new(bw[(i, inputs[jj])], 0.0)).collect();
                    lus[l].solve(&mut y);
                    y
                })
                .collect();
            let h0: Vec<Vec<C64>> = y0
                .iter()
                .map(|y| {
                    (0..n_out)
                        .map(|i| (0..d).map(|t| y[t] * bw[(t, i)]).sum())
                        .collect()
                })
                .collect();
            let mut r = Mat::<f64>::zeros(n, 2 * ns);
            for (s, &(_, jj)) in batch.iter().enumerate() {
                r.col_mut(2 * s).copy_from(basis.b_all.col(inputs[jj]));
            }
            sub_zv(basis, &coefs, &y0, &mut r);
            let mut st: Vec<Gmres> = (0..ns)
                .map(|s| {
                    let r0 = get(&r, s);
                    let beta = r0.iter().map(|z| z.norm_sqr()).sum::<f64>().sqrt();
                    let b_norm = basis.b_all.col(inputs[batch[s].1]).norm_l2();
                    let inv = if beta > 0.0 { 1.0 / beta } else { 0.0 };
                    Gmres {
                        u: vec![r0.into_iter().map(|z| z * inv).collect()],
                        h: Vec::new(),
                        rot: Vec::new(),
                        g: vec![C64::new(beta, 0.0)],
                        o: Vec::new(),
                        b_norm,
                        done: !(beta > tol * b_norm),
                    }
                })
                .collect();
            drop(r);
            let mut it = 0;
            loop {
                let act: Vec<usize> = (0..ns).filter(|&s| !st[s].done).collect();
                if act.is_empty() || it >= max_iter {
                    break;
                }
                let na = act.len();
                // p = P^-1 u_j for the active systems
                let mut p = Mat::<f64>::from_fn(n, 2 * na, |i, col| {
                    let z = st[act[col / 2]].u[it][i];
                    if col % 2 == 0 {
                        z.re
                    } else {
                        z.im
                    }
                });
                pre.solve_cols(p.as_mut());
                let ap: Vec<Mat<f64>> = (0..n_ops).map(|k| basis.op_mul(k, p.as_ref())).collect();
                let acoef: Vec<Vec<C64>> = act.iter().map(|&s| coefs[s].clone()).collect();
                let mut w = Mat::<f64>::zeros(n, 2 * na);
                w.par_col_chunks_mut(2).enumerate().for_each(|(a, mut wa)| {
                    for (k, apk) in ap.iter().enumerate() {
                        let c = acoef[a][k];
                        for i in 0..n {
                            let (x, y) = (apk[(i, 2 * a)], apk[(i, 2 * a + 1)]);
                            wa[(i, 0)] += c.re * x - c.im * y;
                            wa[(i, 1)] += c.re * y + c.im * x;
                        }
                    }
                });
                drop(ap);
                // coarse part c = Z_r^-1 V^T Z p; w = Z p - Z V c; outputs of p - V c
                let t = tn(v.as_ref(), w.as_ref());
                let cs: Vec<Vec<C64>> = act
                    .iter()
                    .enumerate()
                    .map(|(a, &s)| {
                        let mut x = get(&t, a);
                        lus[batch[s].0].solve(&mut x);
                        x
                    })
                    .collect();
                sub_zv(basis, &acoef, &cs, &mut w);
                let ws: Vec<(Vec<C64>, Vec<C64>)> = (0..na)
                    .into_par_iter()
                    .map(|a| {
                        let pa = get(&p, a);
                        let mut o = out_of(&pa);
                        for (i, oi) in o.iter_mut().enumerate() {
                            *oi -= (0..d).map(|tt| cs[a][tt] * bw[(tt, i)]).sum::<C64>();
                        }
                        (get(&w, a), o)
                    })
                    .collect();
                drop(p);
                drop(w);
                let mut work: Vec<Step<'_>> = st.iter_mut().filter(|g| !g.done).zip(ws).collect();
                work.par_iter_mut().for_each(|(g, (wv, o))| {
                    g.o.push(std::mem::take(o));
                    g.step(std::mem::take(wv), tol);
                });
                it += 1;
            }
            // x = x0 + sum_j y_j Q u_j
            for (s, g) in st.iter().enumerate() {
                let y = g.coefficients();
                let (l, jj) = batch[s];
                for i in 0..n_out {
                    out[m][l][i * n_in + jj] =
                        h0[s][i] + y.iter().zip(&g.o).map(|(yj, oj)| yj * oj[i]).sum::<C64>();
                }
                let res = g.residual() / g.b_norm;
                stats.max_residual = stats.max_residual.max(res);
                stats.max_iterations = stats.max_iterations.max(y.len());
                if res > tol {
                    stats.not_converged += 1;
                }
            }
        }
    }
    Ok((out, stats))
}
