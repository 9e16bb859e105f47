//! Modes of the bonded joint: the real generalized eigensolver ([`real_modes`]) and the
//! complex modes of (K_b + E* S + j D_b, M) ([`complex_modes`]).
//!
//! Complex eigenproblem (method.md, IEM section):
//!
//! (K_b + E* S + j D_b - lambda M) phi = 0,   phi^T M phi = 1 (no conjugate),
//!
//! f = sqrt(Re lambda) / (2 pi), modal loss factor eta = Im lambda / Re lambda, and the
//! eigenvalue sensitivities d lambda / dE' = phi^T S phi, d lambda / dE'' = j phi^T S phi.
//! Viscous damping C_b is not part of this (linear) pencil and is ignored here.
//!
//! Method: real modes of (K_b + Re(E*) S, M) (2 n + 8 of them) span a subspace onto which
//! the complex pencil is projected; in that M-orthonormal basis it is the standard complex
//! symmetric eigenproblem (Lambda + j Im(E*) Phi^T S Phi + j Phi^T D_b Phi) y = lambda y,
//! solved densely. Each of the lowest n approximations is then refined on the full model by
//! complex Rayleigh-quotient iteration (the complex-symmetric Rayleigh quotient
//! lambda = phi^T K phi / phi^T M phi, no conjugate; one sparse complex LU per step, symbolic
//! analysis shared) until ||(K - lambda M) phi|| / ||K phi|| <= `ModesParams::tol`, or until
//! the backward error ||(K - lambda M) phi|| / ((||K||_1 + |lambda| ||M||_1) ||phi||) is at
//! the rounding level `ModesParams::backward_tol` after `max_refine` steps (the relative
//! residual's own floor is about eps cond(K), which for a steel beam on a soft adhesive can
//! sit above `tol`; the backward error is scale-free and reachable in floating point whatever
//! the conditioning). While the residual keeps falling (by `PROGRESS` per step) the
//! iterations go on past `max_refine`, up to `EXTRA_REFINE_FACTOR` times it.

pub mod real;

pub use real::{real_modes, EigenParams};

use crate::common::C64;
use crate::fe::model::StructuralModel;
use crate::frf::full::{FullModel, FullParams};
use crate::linalg::spmv_complex;
use faer::Mat;
use rayon::prelude::*;

/// Errors of the modal solvers.
#[derive(Debug, thiserror::Error)]
pub enum ModesError {
    #[error("invalid input to the modal solver: {0}")]
    BadInput(String),
    #[error("factorisation failed: {0}")]
    Factorization(String),
    #[error("{what} did not converge: residual {residual:e} > tolerance {tol:e}; loosen the tolerance (`rfmlab modes --tol`) or refine the mesh (structure.mesh.element_size)")]
    NotConverged {
        what: String,
        residual: f64,
        tol: f64,
    },
}

/// Largest residual of the real eigensolver at which [`complex_modes`] still uses its Ritz
/// vectors as the projection basis when they miss `ModesParams::eigen.tol` (the basis only
/// has to start each Rayleigh-quotient refinement in the right mode's basin).
pub const BASIS_ACCEPT_RESIDUAL: f64 = 1e-3;

/// Tuning knobs of [`complex_modes`].
#[derive(Clone, Debug)]
pub struct ModesParams {
    /// Real eigensolver settings for the projection basis (default [`EigenParams::default`],
    /// whose tolerance is then relaxed to 1e-6: the basis only needs to be good enough
    /// for the refinement to start in the right basin).
    pub eigen: EigenParams,
    /// Size of the real basis: `extra_factor * n + extra` modes (defaults 2 and 8).
    pub extra_factor: usize,
    pub extra: usize,
    /// Target relative residual ||K phi - lambda M phi|| / ||K phi|| of each complex mode
    /// (default 1e-6: this measure has a rounding floor of about eps cond(K), ~1e-7 for a steel
    /// beam on a soft adhesive; the eigenvalue itself converges quadratically and is far more
    /// accurate than the residual suggests).
    pub tol: f64,
    /// Maximum Rayleigh-quotient iterations per mode (default 10; up to
    /// `EXTRA_REFINE_FACTOR` times more while the residual keeps falling).
    pub max_refine: usize,
    /// A mode is also converged when its backward error
    /// ||(K - lambda M) phi|| / ((||K||_1 + |lambda| ||M||_1) ||phi||) is below this
    /// (default 1e-12, a few thousand times the unit roundoff: where the relative residual's
    /// rounding floor lies above `tol`, the pair is then exact for a perturbation of K and M
    /// far below the model's own accuracy).
    pub backward_tol: f64,
    /// A mode is flagged `y_dominant` when the y fraction of its kinetic energy exceeds this
    /// (default 0.8: torsion modes carry 40-60 % of their energy in y but are invisible at centreline
    /// sensors).
    pub y_dominant_threshold: f64,
}

impl Default for ModesParams {
    fn default() -> Self {
        ModesParams {
            eigen: EigenParams {
                tol: 1e-6,
                ..EigenParams::default()
            },
            extra_factor: 2,
            extra: 8,
            tol: 1e-6,
            max_refine: 10,
            backward_tol: 1e-12,
            y_dominant_threshold: 0.8,
        }
    }
}

/// One complex mode (see the module docs for the definitions).
#[derive(Clone, Debug)]
pub struct ComplexMode {
    /// Eigenvalue lambda = w_r^2 (1 + j eta) (rad^2/s^2).
    pub lambda: C64,
    /// sqrt(Re lambda) / (2 pi).
    pub freq_hz: f64,
    /// Im lambda / Re lambda.
    pub loss_factor: f64,
    /// phi^T S phi = d lambda / dE' (phi normalised phi^T M phi = 1, no conjugate).
    pub phi_s_phi: C64,
    /// b_i^T phi for each observation point i of the model.
    pub at_points: Vec<C64>,
    /// Fraction of the kinetic energy phi^H M_aa phi in the x, y, z DOFs (M_aa: the block of
    /// M coupling DOFs of axis a; normalised to sum 1). None when no DOF axes were given.
    pub energy_fraction_xyz: Option<[f64; 3]>,
    /// y fraction > `ModesParams::y_dominant_threshold` (the measurements see y only).
    pub y_dominant: Option<bool>,
    /// Final relative residual ||(K - lambda M) phi|| / ||K phi||, K = K_b + E* S + j D_b.
    pub residual: f64,
    /// Full mode shape over the free DOFs (phi^T M phi = 1).
    pub phi: Vec<C64>,
}

/// K phi with K = K_b + E* S + j D_b, and M phi.
struct Pencil<'a> {
    model: &'a StructuralModel,
    e: C64,
}

impl Pencil<'_> {
    fn k_mul(&self, x: &[C64], out: &mut [C64], tmp: &mut [C64]) {
        spmv_complex(&self.model.k_b, x, out);
        spmv_complex(&self.model.s, x, tmp);
        for (o, t) in out.iter_mut().zip(tmp.iter()) {
            *o += self.e * t;
        }
        if let Some(d) = &self.model.d_b {
            spmv_complex(d, x, tmp);
            for (o, t) in out.iter_mut().zip(tmp.iter()) {
                *o += C64::new(-t.im, t.re);
            }
        }
    }
    fn m_mul(&self, x: &[C64], out: &mut [C64]) {
        spmv_complex(&self.model.m, x, out);
    }
}

fn tdot(a: &[C64], b: &[C64]) -> C64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

fn norm2(a: &[C64]) -> f64 {
    a.iter().map(|x| x.norm_sqr()).sum::<f64>().sqrt()
}

/// Iterations beyond `max_refine` allowed while the residual still falls: up to this factor.
pub const EXTRA_REFINE_FACTOR: usize = 3;
/// A step makes progress when it divides the residual by at least this.
pub const PROGRESS: f64 = 2.0;

/// Largest absolute column sum ||A||_1 of a sparse matrix (an upper bound of ||A||_2 for a
/// symmetric A).
fn norm1(a: &crate::fe::model::SpMat) -> f64 {
    let mut col = vec![0.0f64; a.ncols()];
    for t in a.triplet_iter() {
        col[t.col] += t.val.abs();
    }
    col.into_iter().fold(0.0, f64::max)
}

/// Estimated peak memory (bytes) of [`complex_modes`] for `n_modes` modes of a model of
/// `n_dof` DOFs with the given parameters: the Lanczos basis of the real modes
/// (max(6 p + 60, 120) vectors, p = `extra_factor` n + `extra`), S Phi and D Phi, and the
/// dense complex eigenproblem of size p (about 4 p^2 complex values).
pub fn complex_modes_memory(n_dof: usize, n_modes: usize, params: &ModesParams) -> f64 {
    let nd = n_dof as f64;
    let p = ((params.extra_factor * n_modes + params.extra).max(n_modes) as f64).min(nd);
    let lanczos = (6.0 * p + 60.0).max(120.0).min(nd);
    8.0 * nd * (lanczos + 3.0 * p) + 8.0 * lanczos * lanczos * 2.0 + 16.0 * 4.0 * p * p
}

/// Lowest `n_modes` complex modes of (K_b + E* S + j D_b, M) for the complex modulus
/// `modulus` (Pa), sorted by Re lambda. `dof_axes` (0 = x, 1 = y, 2 = z per free DOF), when
/// given, enables the kinetic-energy classification. See the module docs for the method.
pub fn complex_modes(
    model: &StructuralModel,
    modulus: C64,
    n_modes: usize,
    dof_axes: Option<&[u8]>,
    params: &ModesParams,
) -> Result<Vec<ComplexMode>, ModesError> {
    let nd = model.n_dof();
    if let Some(ax) = dof_axes {
        if ax.len() != nd || ax.iter().any(|&a| a > 2) {
            return Err(ModesError::BadInput(format!(
                "dof_axes must have one entry 0, 1 or 2 per free DOF ({nd}); got {} entries",
                ax.len()
            )));
        }
    }
    if !modulus.re.is_finite() || modulus.re <= 0.0 || !modulus.im.is_finite() {
        return Err(ModesError::BadInput(format!(
            "the storage modulus must be positive and finite, got E* = {modulus} Pa"
        )));
    }
    if n_modes == 0 {
        return Ok(Vec::new());
    }
    let n_basis = (params.extra_factor * n_modes + params.extra)
        .max(n_modes)
        .min(nd);
    // 1. real basis
    let k_re = real::sp_add(&model.k_b, &model.s, modulus.re)?;
    let (lam_r, phi_r) = match real_modes(&k_re, &model.m, n_basis, &params.eigen) {
        Ok(v) => v,
        // the Krylov residual stalled above the basis tolerance but below
        // BASIS_ACCEPT_RESIDUAL (slender beams, clustered modes): the same run, stopped at
        // the residual it reached, is a basis good enough for the refinement below, which
        // converges every complex mode to `params.tol` on its own
        Err(ModesError::NotConverged { residual, .. })
            if residual.is_finite()
                && residual > params.eigen.tol
                && residual <= BASIS_ACCEPT_RESIDUAL =>
        {
            let eigen = EigenParams {
                tol: residual * (1.0 + 1e-9),
                ..params.eigen.clone()
            };
            real_modes(&k_re, &model.m, n_basis, &eigen)?
        }
        Err(e) => return Err(e),
    };
    // 2. projected complex pencil A = Lambda + j Im(E) Phi^T S Phi + j Phi^T D Phi (symmetric)
    let p = n_basis;
    let mut sphi = Mat::<f64>::zeros(nd, p);
    let mut dphi = model.d_b.as_ref().map(|_| Mat::<f64>::zeros(nd, p));
    let mut col = vec![0.0; nd];
    let mut out = vec![0.0; nd];
    for c in 0..p {
        for r in 0..nd {
            col[r] = phi_r[(r, c)];
        }
        crate::linalg::spmv_real(&model.s, &col, &mut out);
        for r in 0..nd {
            sphi[(r, c)] = out[r];
        }
        if let (Some(d), Some(dp)) = (&model.d_b, dphi.as_mut()) {
            crate::linalg::spmv_real(d, &col, &mut out);
            for r in 0..nd {
                dp[(r, c)] = out[r];
            }
        }
    }
    let ps = phi_r.transpose() * &sphi;
    let pd = dphi.as_ref().map(|dp| phi_r.transpose() * dp);
    let a = Mat::<C64>::from_fn(p, p, |i, j| {
        let mut v = C64::new(if i == j { lam_r[i] } else { 0.0 }, 0.0);
        v += C64::new(0.0, modulus.im * 0.5 * (ps[(i, j)] + ps[(j, i)]));
        if let Some(pd) = &pd {
            v += C64::new(0.0, 0.5 * (pd[(i, j)] + pd[(j, i)]));
        }
        v
    });
    let evd = a
        .eigen()
        .map_err(|e| ModesError::Factorization(format!("dense complex eigensolver: {e:?}")))?;
    let s = evd.S();
    let u = evd.U();
    let mut order: Vec<usize> = (0..p).collect();
    order.sort_by(|&x, &y| s[x].re.total_cmp(&s[y].re));
    order.truncate(n_modes);

    // 3. refinement on the full model
    let full = FullModel::new(model, &[], FullParams::default())
        .map_err(|e| ModesError::BadInput(e.to_string()))?;
    let pencil = Pencil { model, e: modulus };
    let norm_k = norm1(&model.k_b)
        + modulus.norm() * norm1(&model.s)
        + model.d_b.as_ref().map_or(0.0, norm1);
    let norm_m = norm1(&model.m);
    let hard_limit = params.max_refine.max(1) * EXTRA_REFINE_FACTOR;
    // modes are refined independently: in parallel over modes, sequential inside
    let refine = |idx: usize| -> Result<ComplexMode, ModesError> {
        let mut tmp = vec![C64::new(0.0, 0.0); nd];
        let mut kphi = vec![C64::new(0.0, 0.0); nd];
        let mut mphi = vec![C64::new(0.0, 0.0); nd];
        // initial vector phi = Phi_r y
        let mut phi: Vec<C64> = (0..nd)
            .map(|r| (0..p).map(|i| u[(i, idx)] * phi_r[(r, i)]).sum())
            .collect();
        let mut lambda: C64;
        let mut residual: f64;
        let mut backward: f64;
        let mut previous = f64::INFINITY;
        let mut it = 0usize;
        loop {
            // normalise phi^T M phi = 1, Rayleigh quotient, residual
            pencil.m_mul(&phi, &mut mphi);
            let nrm = tdot(&phi, &mphi).sqrt();
            if nrm.norm() == 0.0 || !nrm.re.is_finite() {
                return Err(ModesError::Factorization(
                    "mode refinement produced a vector with phi^T M phi = 0".into(),
                ));
            }
            let inv = C64::new(1.0, 0.0) / nrm;
            phi.iter_mut().for_each(|v| *v *= inv);
            mphi.iter_mut().for_each(|v| *v *= inv);
            pencil.k_mul(&phi, &mut kphi, &mut tmp);
            lambda = tdot(&phi, &kphi); // phi^T M phi = 1
            let r: Vec<C64> = kphi
                .iter()
                .zip(&mphi)
                .map(|(k, m)| k - lambda * m)
                .collect();
            let rn = norm2(&r);
            residual = rn / norm2(&kphi).max(f64::MIN_POSITIVE);
            backward =
                rn / ((norm_k + lambda.norm() * norm_m) * norm2(&phi)).max(f64::MIN_POSITIVE);
            // up to max_refine: the relative residual alone (as tight as it can be); beyond
            // it, a pair at the rounding level is accepted, and the iteration goes on only
            // while the residual still falls
            if residual <= params.tol {
                break;
            }
            if it >= params.max_refine {
                let progressing = residual * PROGRESS <= previous;
                if backward <= params.backward_tol || !progressing || it >= hard_limit {
                    break;
                }
            }
            previous = residual;
            it += 1;
            // (K - lambda M) x = M phi
            let mut rhs = Mat::<C64>::from_fn(nd, 1, |i, _| mphi[i]);
            match full.solve_pencil_in_place(lambda, modulus, rhs.as_mut()) {
                Ok(()) => phi = (0..nd).map(|i| rhs[(i, 0)]).collect(),
                Err(_) => break, // lambda is an eigenvalue to machine precision
            }
        }
        if residual > params.tol && backward > params.backward_tol {
            return Err(ModesError::NotConverged {
                what: format!(
                    "complex mode near {:.4} Hz (Rayleigh-quotient refinement, {it} iterations, backward error {backward:.1e})",
                    lambda.re.max(0.0).sqrt() / (2.0 * std::f64::consts::PI),
                ),
                residual,
                tol: params.tol,
            });
        }
        // outputs
        let sp = {
            spmv_complex(&model.s, &phi, &mut tmp);
            tdot(&phi, &tmp)
        };
        let at_points = model
            .points
            .iter()
            .map(|pt| pt.dofs.iter().map(|&(d, w)| phi[d] * w).sum())
            .collect();
        let (energy, ydom) = match dof_axes {
            Some(ax) => {
                let mut e = [0.0f64; 3];
                for t in model.m.triplet_iter() {
                    if ax[t.row] == ax[t.col] {
                        e[ax[t.row] as usize] += (phi[t.row].conj() * phi[t.col] * *t.val).re;
                    }
                }
                let tot: f64 = e.iter().sum();
                if tot > 0.0 {
                    e.iter_mut().for_each(|v| *v /= tot);
                }
                (Some(e), Some(e[1] > params.y_dominant_threshold))
            }
            None => (None, None),
        };
        Ok(ComplexMode {
            lambda,
            freq_hz: lambda.re.max(0.0).sqrt() / (2.0 * std::f64::consts::PI),
            loss_factor: lambda.im / lambda.re,
            phi_s_phi: sp,
            at_points,
            energy_fraction_xyz: energy,
            y_dominant: ydom,
            residual,
            phi,
        })
    };
    let mut modes: Vec<ComplexMode> = order
        .par_iter()
        .map(|&idx| refine(idx))
        .collect::<Result<Vec<_>, _>>()?;
    modes.sort_by(|a, b| a.lambda.re.total_cmp(&b.lambda.re));
    // two starting guesses that converged to the same eigenvalue would be a silent error
    for w in modes.windows(2) {
        if (w[1].lambda - w[0].lambda).norm() <= 1e-8 * w[0].lambda.norm() {
            return Err(ModesError::NotConverged {
                what: format!(
                    "complex modes: two approximations converged to the same eigenvalue {} (ask for a different number of modes, `rfmlab modes --count`)",
                    w[0].lambda
                ),
                residual: 0.0,
                tol: params.tol,
            });
        }
    }
    Ok(modes)
}
