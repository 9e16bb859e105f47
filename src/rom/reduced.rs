//! The reduced model Z_r(w, E*) = -w^2 M_r + K_r + j w C_r + j D_r + E* S_r (dense n_r x n_r)
//! and its reference evaluation by a dense LU per line ([`ReducedModel::lu_sweep`]).
//!
//! With X = Z_r^-1 B_r (all outputs), H_ij = b_i^T x_j, dH_ij/dE' = -x_i^T S_r x_j
//! (paper eq. 44-47 projected), and sh_ij = (V^T S b_i)^T x_j.

use super::dense::DenseLu;
use super::{ModulusRange, RomError};
use crate::common::{C64, J};
use crate::frf::{EngineMode, FrfEngine, FrfError, Sweep};
use faer::Mat;
use rayon::prelude::*;

/// A projected model; implements [`FrfEngine`] by dense LU per line.
#[derive(Clone, Debug)]
pub struct ReducedModel {
    pub(crate) n_r: usize,
    pub(crate) n_out: usize,
    pub(crate) inputs: Vec<usize>,
    pub(crate) m_r: Mat<f64>,
    pub(crate) k_r: Mat<f64>,
    pub(crate) s_r: Mat<f64>,
    pub(crate) c_r: Option<Mat<f64>>,
    pub(crate) d_r: Option<Mat<f64>>,
    /// V^T b_i (n_r x n_out).
    pub(crate) b_r: Mat<f64>,
    /// V^T S b_i (n_r x n_out).
    pub(crate) sb_r: Mat<f64>,
    pub(crate) range: ModulusRange,
    /// V^T M_a V for the x, y, z DOFs (M_a: M restricted to pairs of DOFs of axis a), when
    /// the DOF axes were known: the modes' kinetic-energy split.
    pub(crate) m_axes_r: Option<Box<[Mat<f64>; 3]>>,
}

/// A line's solved loads, each output's slot among them and `H = B_r^T X`
/// ([`ReducedModel::solve_line`]).
pub(crate) type LineSolution = (Vec<Vec<C64>>, Vec<usize>, Vec<C64>);

/// Eigenvalues of M_r below this fraction of its largest are numerically dependent
/// directions of the basis ([`ReducedModel::complex_modes`] drops them). M_r's own rounding
/// is ~1e-16 of its largest eigenvalue, and K_r's rounding seen through a kept direction is
/// ~1e-16 / MASS_RANK_RTOL of the basis' largest eigenvalue: 1e-10 keeps that far below
/// the band's modes.
pub const MASS_RANK_RTOL: f64 = 1e-10;

impl ReducedModel {
    /// The same reduced model with fewer inputs (`inputs` must be among its inputs): the basis
    /// and certificate are unchanged, a sweep then computes only those columns (the
    /// likelihood needs the excitation column alone).
    pub fn with_inputs(&self, inputs: &[usize]) -> Result<ReducedModel, RomError> {
        if let Some(j) = inputs.iter().find(|j| !self.inputs.contains(j)) {
            return Err(RomError::Params(format!(
                "input {j} is not an input of the reduced model ({:?})",
                self.inputs
            )));
        }
        let mut r = self.clone();
        r.inputs = inputs.to_vec();
        Ok(r)
    }

    /// The same reduced model with point masses `(output index, kg)` added along the outputs'
    /// directions: `M_r + sum m (V^T b)(V^T b)^T`, the exact projection of the added masses on
    /// the basis (which was certified without them: accurate while the masses change the
    /// modes' shapes little, as a sensor's grams on a joint do).
    pub fn with_point_masses(&self, masses: &[(usize, f64)]) -> Result<ReducedModel, RomError> {
        if let Some(&(p, _)) = masses.iter().find(|(p, _)| *p >= self.n_out) {
            return Err(RomError::Params(format!(
                "point mass at output {p}: the reduced model has {} outputs",
                self.n_out
            )));
        }
        let mut r = self.clone();
        for &(p, m) in masses {
            for i in 0..self.n_r {
                for j in 0..self.n_r {
                    r.m_r[(i, j)] += m * self.b_r[(i, p)] * self.b_r[(j, p)];
                }
            }
        }
        Ok(r)
    }

    /// Basis size n_r.
    pub fn basis_size(&self) -> usize {
        self.n_r
    }
    /// The modulus range the ROM was built (and certified) for.
    pub fn range(&self) -> ModulusRange {
        self.range
    }

    /// The lowest `n_modes` complex modes of the reduced pencil (K_r + j D_r + E* S_r, M_r)
    /// at a constant modulus (Pa), sorted by Re lambda (viscous C_r is left out, as in
    /// [`crate::modes::complex_modes`]). With M_r = U S U^T (symmetric eigendecomposition)
    /// and W = U_k S_k^-1/2 over the eigenvalues above [`MASS_RANK_RTOL`] of the largest, the
    /// pencil becomes the complex symmetric A = W^T (K_r + j D_r + E* S_r) W, whose
    /// eigenvectors y give phi_r = W y, normalised phi_r^T M_r phi_r = 1 (no conjugate).
    /// Directions of the basis that are numerically dependent (M_r singular to rounding: a
    /// Krylov basis of a joint whose points barely move some modes) are dropped instead of
    /// failing a Cholesky factorisation; they carry no mode. The basis holds the Krylov
    /// sequences of the observation loads, so these are the modes the FRFs see, as accurate
    /// as the certified FRFs around their resonances; modes the points do not excite
    /// (torsion, lateral bending for in-plane loads) are absent.
    pub fn complex_modes(&self, modulus: C64, n_modes: usize) -> Result<Vec<EngineMode>, RomError> {
        let n = self.n_r;
        let eig = self
            .m_r
            .self_adjoint_eigen(faer::Side::Lower)
            .map_err(|e| RomError::Factorization(format!("eigendecomposition of M_r: {e:?}")))?;
        let s_max = (0..n).map(|i| eig.S()[i]).fold(0.0f64, f64::max);
        if s_max <= 0.0 || !s_max.is_finite() {
            return Err(RomError::Factorization(
                "M_r has no positive eigenvalue: the reduced basis is empty or broken".into(),
            ));
        }
        let kept: Vec<usize> = (0..n)
            .filter(|&i| eig.S()[i] > MASS_RANK_RTOL * s_max)
            .collect();
        let r = kept.len();
        let w = Mat::<f64>::from_fn(n, r, |i, c| {
            let k = kept[c];
            eig.U()[(i, k)] / eig.S()[k].sqrt()
        });
        // K = K_r + j D_r + E* S_r, then A = W^T K W (complex symmetric).
        let k = Mat::<C64>::from_fn(n, n, |i, j| {
            let mut v = C64::new(self.k_r[(i, j)], 0.0) + modulus * self.s_r[(i, j)];
            if let Some(d) = &self.d_r {
                v += C64::new(0.0, d[(i, j)]);
            }
            v
        });
        let wc = Mat::<C64>::from_fn(n, r, |i, j| C64::new(w[(i, j)], 0.0));
        let kw = &k * &wc;
        let aw = wc.transpose() * &kw;
        let at = Mat::<C64>::from_fn(r, r, |i, j| 0.5 * (aw[(i, j)] + aw[(j, i)]));
        let evd = at
            .eigen()
            .map_err(|e| RomError::Factorization(format!("reduced complex eigensolver: {e:?}")))?;
        let (vals, vecs) = (evd.S(), evd.U());
        let mut order: Vec<usize> = (0..r).collect();
        order.sort_by(|&x, &y| vals[x].re.total_cmp(&vals[y].re));
        order.truncate(n_modes);
        let mut out = Vec::with_capacity(order.len());
        for idx in order {
            // phi_r = W y
            let phi = Mat::<C64>::from_fn(n, 1, |i, _| {
                (0..r).map(|c| vecs[(c, idx)] * w[(i, c)]).sum::<C64>()
            });
            let mut phi = phi;
            // phi^T m phi (no conjugate)
            let quad = |phi: &Mat<C64>, m: &Mat<f64>| -> C64 {
                let mut acc = C64::new(0.0, 0.0);
                for i in 0..n {
                    let mut row = C64::new(0.0, 0.0);
                    for j in 0..n {
                        row += phi[(j, 0)] * m[(i, j)];
                    }
                    acc += phi[(i, 0)] * row;
                }
                acc
            };
            let norm = quad(&phi, &self.m_r).sqrt();
            if norm.norm() == 0.0 || !norm.re.is_finite() {
                return Err(RomError::Factorization(
                    "a reduced mode has phi^T M phi = 0".into(),
                ));
            }
            for i in 0..n {
                phi[(i, 0)] /= norm;
            }
            let phi_s_phi = quad(&phi, &self.s_r);
            let lambda = quad(&phi, &self.k_r)
                + modulus * phi_s_phi
                + self
                    .d_r
                    .as_ref()
                    .map(|d| J * quad(&phi, d))
                    .unwrap_or_default();
            let at_points = (0..self.n_out)
                .map(|p| (0..n).map(|i| phi[(i, 0)] * self.b_r[(i, p)]).sum())
                .collect();
            // phi^H M_a phi per axis, normalised to sum 1
            let energy_fraction_xyz = self.m_axes_r.as_ref().map(|ma| {
                let mut e = [0.0f64; 3];
                for (a, m) in ma.iter().enumerate() {
                    for i in 0..n {
                        for j in 0..n {
                            e[a] += (phi[(i, 0)].conj() * phi[(j, 0)] * m[(i, j)]).re;
                        }
                    }
                }
                let tot: f64 = e.iter().sum();
                if tot > 0.0 {
                    e.iter_mut().for_each(|x| *x /= tot);
                }
                e
            });
            out.push(EngineMode {
                lambda,
                phi_s_phi,
                at_points,
                energy_fraction_xyz,
            });
        }
        Ok(out)
    }

    /// A(w) + e S_r as a row-major complex matrix. Every reduced matrix is symmetric, so
    /// row i is read from column i (contiguous in faer's storage), and the result is
    /// complex symmetric (row- and column-major storage coincide).
    pub(crate) fn z_r(&self, omega: f64, e: C64) -> Vec<C64> {
        let n = self.n_r;
        let mut z = vec![C64::new(0.0, 0.0); n * n];
        let w2 = omega * omega;
        for i in 0..n {
            for j in 0..n {
                let mut re = -w2 * self.m_r[(j, i)] + self.k_r[(j, i)];
                let mut im = 0.0;
                if let Some(c) = &self.c_r {
                    im += omega * c[(j, i)];
                }
                if let Some(d) = &self.d_r {
                    im += d[(j, i)];
                }
                let s = self.s_r[(j, i)];
                re += e.re * s;
                im += e.im * s;
                z[i * n + j] = C64::new(re, im);
            }
        }
        z
    }

    /// Factor `z` (the reduced system of line `omega` at modulus `e`, complex symmetric,
    /// row-major) and solve for the loads the line needs: the inputs' columns of B_r, and every
    /// output's when `all_outputs` (derivatives). Returns the solutions, each output's slot
    /// among them (`usize::MAX` when not solved) and `H = B_r^T X` (n_out x n_in row-major).
    pub(crate) fn solve_line(
        &self,
        z: Vec<C64>,
        omega: f64,
        e: C64,
        all_outputs: bool,
    ) -> Result<LineSolution, FrfError> {
        let n = self.n_r;
        let no = self.n_out;
        let ni = self.inputs.len();
        let lu = DenseLu::factor_symmetric(n, z).ok_or(FrfError::Singular {
            freq_hz: omega / std::f64::consts::TAU,
            modulus: e,
        })?;
        let cols: Vec<usize> = if all_outputs {
            (0..no).collect()
        } else {
            self.inputs.clone()
        };
        let mut x: Vec<Vec<C64>> = Vec::with_capacity(cols.len());
        let mut slot = vec![usize::MAX; no];
        for &c in &cols {
            let mut b: Vec<C64> = (0..n).map(|k| C64::new(self.b_r[(k, c)], 0.0)).collect();
            lu.solve(&mut b);
            slot[c] = x.len();
            x.push(b);
        }
        let mut h = vec![C64::new(0.0, 0.0); no * ni];
        for i in 0..no {
            for (jj, &j) in self.inputs.iter().enumerate() {
                let xj = &x[slot[j]];
                h[i * ni + jj] = (0..n).map(|k| xj[k] * self.b_r[(k, i)]).sum();
            }
        }
        Ok((x, slot, h))
    }

    /// Per-line results (h, dh, sh), each n_out x n_in row-major.
    pub(crate) fn lu_line(
        &self,
        omega: f64,
        e: C64,
        with_derivatives: bool,
    ) -> Result<[Vec<C64>; 3], FrfError> {
        let n = self.n_r;
        let no = self.n_out;
        let ni = self.inputs.len();
        let (x, slot, h) = self.solve_line(self.z_r(omega, e), omega, e, with_derivatives)?;
        let mut dh = Vec::new();
        let mut sh = Vec::new();
        if with_derivatives {
            dh = vec![C64::new(0.0, 0.0); no * ni];
            sh = vec![C64::new(0.0, 0.0); no * ni];
            for (jj, &j) in self.inputs.iter().enumerate() {
                let xj = &x[slot[j]];
                // S_r x_j
                let sx: Vec<C64> = (0..n)
                    .map(|a| (0..n).map(|b| xj[b] * self.s_r[(a, b)]).sum())
                    .collect();
                for i in 0..no {
                    let xi = &x[slot[i]];
                    dh[i * ni + jj] = -(0..n).map(|k| xi[k] * sx[k]).sum::<C64>();
                    sh[i * ni + jj] = (0..n).map(|k| xj[k] * self.sb_r[(k, i)]).sum();
                }
            }
        }
        Ok([h, dh, sh])
    }

    /// Reference sweep: a dense LU of the n_r x n_r reduced system on every line
    /// (O(N_f n_r^3)); lines in parallel, results independent of the thread count.
    pub fn lu_sweep(
        &self,
        omega_rad_s: &[f64],
        modulus_pa: &[C64],
        with_derivatives: bool,
    ) -> Result<Sweep, FrfError> {
        let mut s = Sweep::default();
        self.lu_sweep_into(omega_rad_s, modulus_pa, with_derivatives, &mut s)?;
        Ok(s)
    }

    fn lu_sweep_into(
        &self,
        omega: &[f64],
        modulus: &[C64],
        with_derivatives: bool,
        out: &mut Sweep,
    ) -> Result<(), FrfError> {
        if modulus.len() != omega.len() {
            return Err(FrfError::Length {
                what: "modulus_pa",
                expected: omega.len(),
                got: modulus.len(),
            });
        }
        let lines: Vec<[Vec<C64>; 3]> = omega
            .par_iter()
            .zip(modulus.par_iter())
            .map(|(&w, &e)| self.lu_line(w, e, with_derivatives))
            .collect::<Result<_, _>>()?;
        *out = Sweep::zeros(omega.len(), self.n_out, self.inputs.len(), with_derivatives);
        let blk = self.n_out * self.inputs.len();
        for (l, [h, dh, sh]) in lines.into_iter().enumerate() {
            out.h[l * blk..(l + 1) * blk].copy_from_slice(&h);
            if with_derivatives {
                out.dh_de[l * blk..(l + 1) * blk].copy_from_slice(&dh);
                out.sh[l * blk..(l + 1) * blk].copy_from_slice(&sh);
            }
        }
        Ok(())
    }
}

impl FrfEngine for ReducedModel {
    fn n_out(&self) -> usize {
        self.n_out
    }
    fn inputs(&self) -> &[usize] {
        &self.inputs
    }
    fn sweep_into(
        &self,
        omega_rad_s: &[f64],
        modulus_pa: &[C64],
        with_derivatives: bool,
        out: &mut Sweep,
    ) -> Result<(), FrfError> {
        self.lu_sweep_into(omega_rad_s, modulus_pa, with_derivatives, out)
    }
    fn complex_modes(
        &self,
        modulus_pa: C64,
        n_modes: usize,
    ) -> Option<Result<Vec<EngineMode>, FrfError>> {
        Some(ReducedModel::complex_modes(self, modulus_pa, n_modes).map_err(FrfError::from))
    }
    fn complex_modes_with_masses(
        &self,
        modulus_pa: C64,
        n_modes: usize,
        masses: &[(usize, f64)],
    ) -> Option<Result<Vec<EngineMode>, FrfError>> {
        if let Some(&(p, _)) = masses.iter().find(|(p, _)| *p >= self.n_out) {
            return Some(Err(FrfError::BadInput(p)));
        }
        let r = match self.with_point_masses(masses) {
            Ok(r) => r,
            Err(e) => return Some(Err(FrfError::from(e))),
        };
        Some(ReducedModel::complex_modes(&r, modulus_pa, n_modes).map_err(FrfError::from))
    }
}

/// Check that `inputs` index observation points.
pub(crate) fn check_inputs(inputs: &[usize], n_out: usize) -> Result<(), RomError> {
    if inputs.is_empty() {
        return Err(RomError::Params("no input (excitation) point given".into()));
    }
    if let Some(&bad) = inputs.iter().find(|&&i| i >= n_out) {
        return Err(RomError::Params(format!(
            "input index {bad} is not an observation point (the model has {n_out})"
        )));
    }
    Ok(())
}
