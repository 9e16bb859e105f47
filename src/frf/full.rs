//! Full-model FRF engine: sparse LU of the dynamic stiffness per frequency line.
//!
//! Dynamic stiffness (method.md, "Dynamic stiffness"):
//!
//! Z(w) = -w^2 M + K_b + j w C_b + j D_b + E*(w) S.
//!
//! Per frequency line the engine solves Z X = B, where column i of B is the observation
//! vector b_i of observation point i (its DOF weights), and reads
//!
//! * receptance h_ij = b_i^T X_j for the input points j (H = Z^-1 is symmetric, so the
//!   solution for b_j is receptance column j);
//! * the sensitivity (paper eq. 44-47) dh_ij/dE' = -b_i^T Z^-1 S Z^-1 b_j = -X_i^T S X_j,
//!   with dh_ij/dE'' = j dh_ij/dE' (not stored);
//! * sh_ij = b_i^T S X_j, used by the RFM fill of unmeasured entries.
//!
//! Accelerance is -w^2 h: callers convert.
//!
//! Implementation: Z lives on the union sparsity pattern of M, K_b, S, C_b, D_b, built once in
//! [`FullModel::new`] together with the coefficient of each matrix in each slot, so per line
//! only the values are refilled (one pass over the pattern). The symbolic LU analysis
//! (COLAMD ordering, elimination tree, supernodal structure) is done once per model; each
//! line does a numeric LU with partial pivoting reusing it. Lines are independent and are
//! distributed with rayon; faer runs with `Par::Seq` inside each line, so the results are
//! bit-identical with any number of threads.

use super::{FrfEngine, FrfError, Sweep};
use crate::common::C64;
use crate::fe::model::{SpMat, StructuralModel};
use crate::linalg::UnionPattern;
use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::reborrow::{Reborrow, ReborrowMut};
use faer::sparse::linalg::lu::{factorize_symbolic_lu, NumericLu, SymbolicLu};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMat};
use faer::{Conj, Mat, MatMut, Par};
use rayon::prelude::*;

/// Tuning knobs of the full-model engine.
#[derive(Clone, Debug)]
pub struct FullParams {
    /// Distribute frequency lines over the rayon thread pool (default `true`). Results are
    /// bit-identical either way.
    pub parallel: bool,
    /// A line is reported as [`FrfError::Singular`] when the lower bound
    /// ||Z||_1 ||x_i||_1 / ||b_i||_1 of the 1-norm condition number of Z exceeds this
    /// (default 1e15, i.e. about 4 eps^-1 / 20: the solution would have no correct digit).
    /// Non-finite solutions (an exactly zero pivot) are always reported.
    pub max_condition: f64,
}

impl Default for FullParams {
    fn default() -> Self {
        FullParams {
            parallel: true,
            max_condition: 1e15,
        }
    }
}

/// The full FE model prepared for repeated FRF evaluation (owns its data; cheap to
/// construct: one pass over the matrices plus one symbolic LU analysis).
#[derive(Debug)]
pub struct FullModel {
    n: usize,
    /// Union pattern of all matrices (sorted, diagonal included).
    pattern: SymbolicSparseColMat<usize>,
    /// Coefficients of M, K_b, S, C_b, D_b in each slot of the union pattern.
    m: Vec<f64>,
    k: Vec<f64>,
    s: Vec<f64>,
    c: Option<Vec<f64>>,
    d: Option<Vec<f64>>,
    /// S on its own pattern, for S X products.
    s_mat: SpMat,
    /// Observation vectors b_i as (dof, weight) lists.
    obs: Vec<Vec<(usize, f64)>>,
    inputs: Vec<usize>,
    symbolic: SymbolicLu<usize>,
    params: FullParams,
}

/// Per-thread scratch space of one line solve.
struct Workspace {
    values: Vec<C64>,
    numeric: NumericLu<usize, C64>,
    factor_buf: MemBuffer,
    solve_buf: MemBuffer,
}

/// The results of one line: h, dh, sh as n_out x n_in row-major blocks.
struct LineResult {
    h: Vec<C64>,
    dh: Vec<C64>,
    sh: Vec<C64>,
}

fn check_size(what: &'static str, a: &SpMat, n: usize) -> Result<(), FrfError> {
    if a.nrows() != n || a.ncols() != n {
        return Err(FrfError::Other(format!(
            "matrix {what} is {}x{} but M is {n}x{n}: all model matrices must be square over the same free DOFs",
            a.nrows(),
            a.ncols()
        )));
    }
    Ok(())
}

impl FullModel {
    /// Prepare `model` for FRF evaluation with excitation at the observation points
    /// `inputs` (indices into `model.points`).
    pub fn new(
        model: &StructuralModel,
        inputs: &[usize],
        params: FullParams,
    ) -> Result<Self, FrfError> {
        let n = model.n_dof();
        check_size("M", &model.m, n)?;
        check_size("K_b", &model.k_b, n)?;
        check_size("S", &model.s, n)?;
        if let Some(c) = &model.c_b {
            check_size("C_b", c, n)?;
        }
        if let Some(d) = &model.d_b {
            check_size("D_b", d, n)?;
        }
        if n == 0 {
            return Err(FrfError::Other(
                "the model has no free DOFs: nothing to solve".into(),
            ));
        }
        for &j in inputs {
            if j >= model.points.len() {
                return Err(FrfError::BadInput(j));
            }
        }
        let mut obs = Vec::with_capacity(model.points.len());
        for p in &model.points {
            for &(dof, w) in &p.dofs {
                if dof >= n || !w.is_finite() {
                    return Err(FrfError::Other(format!(
                        "observation point {} ({}) refers to DOF {dof} with weight {w}, but the model has {n} free DOFs",
                        p.id, p.direction
                    )));
                }
            }
            obs.push(p.dofs.clone());
        }

        let mut mats: Vec<&SpMat> = vec![&model.m, &model.k_b, &model.s];
        if let Some(c) = &model.c_b {
            mats.push(c);
        }
        if let Some(d) = &model.d_b {
            mats.push(d);
        }
        let union = UnionPattern::new(n, &mats);
        let nnz = union.nnz();
        let coef = |k: usize, a: &SpMat| {
            let mut v = vec![0.0; nnz];
            union.scatter(k, a, &mut v);
            v
        };
        let m = coef(0, &model.m);
        let k = coef(1, &model.k_b);
        let s = coef(2, &model.s);
        let mut next = 3;
        let c = model.c_b.as_ref().map(|c| {
            let v = coef(next, c);
            next += 1;
            v
        });
        let d = model.d_b.as_ref().map(|d| coef(next, d));
        for (name, v) in [("M", &m), ("K_b", &k), ("S", &s)] {
            if v.iter().any(|x| !x.is_finite()) {
                return Err(FrfError::Other(format!(
                    "matrix {name} has a non-finite entry"
                )));
            }
        }

        let symbolic = factorize_symbolic_lu(union.symbolic.as_ref(), Default::default())
            .map_err(|e| FrfError::Other(format!("symbolic LU analysis failed: {e:?}")))?;

        Ok(FullModel {
            n,
            pattern: union.symbolic,
            m,
            k,
            s,
            c,
            d,
            s_mat: model.s.clone(),
            obs,
            inputs: inputs.to_vec(),
            symbolic,
            params,
        })
    }

    /// Number of free DOFs.
    pub fn n_dof(&self) -> usize {
        self.n
    }

    fn workspace(&self, rhs_cols: usize) -> Result<Workspace, FrfError> {
        let oom = |_| FrfError::Other("out of memory allocating LU workspace".into());
        let freq: StackReq = self
            .symbolic
            .factorize_numeric_lu_scratch::<C64>(Par::Seq, Default::default());
        let sreq: StackReq = self
            .symbolic
            .solve_in_place_scratch::<C64>(rhs_cols.max(1), Par::Seq);
        Ok(Workspace {
            values: vec![C64::new(0.0, 0.0); self.m.len()],
            numeric: NumericLu::new(),
            factor_buf: MemBuffer::try_new(freq).map_err(oom)?,
            solve_buf: MemBuffer::try_new(sreq).map_err(oom)?,
        })
    }

    /// Fill Z(w) values on the union pattern.
    fn fill(&self, omega: f64, e: C64, values: &mut [C64]) {
        let w2 = omega * omega;
        for (slot, z) in values.iter_mut().enumerate() {
            let re = self.k[slot] - w2 * self.m[slot] + e.re * self.s[slot];
            let mut im = e.im * self.s[slot];
            if let Some(c) = &self.c {
                im += omega * c[slot];
            }
            if let Some(d) = &self.d {
                im += d[slot];
            }
            *z = C64::new(re, im);
        }
    }

    /// Fill the modal pencil K_b + j D_b + E* S - lambda M on the union pattern (C_b ignored).
    fn fill_pencil(&self, lambda: C64, e: C64, values: &mut [C64]) {
        for (slot, z) in values.iter_mut().enumerate() {
            let mut v = C64::new(self.k[slot], 0.0) + e * self.s[slot] - lambda * self.m[slot];
            if let Some(d) = &self.d {
                v.im += d[slot];
            }
            *z = v;
        }
    }

    /// Solve (K_b + j D_b + E* S - lambda M) X = B in place (used by the complex-mode
    /// refinement; no conditioning check because lambda is meant to approach an eigenvalue).
    /// Errors only on a failed factorisation or a non-finite solution.
    pub fn solve_pencil_in_place(
        &self,
        lambda: C64,
        modulus_pa: C64,
        mut rhs: MatMut<'_, C64>,
    ) -> Result<(), FrfError> {
        let singular = || FrfError::Singular {
            freq_hz: lambda.re.max(0.0).sqrt() / (2.0 * std::f64::consts::PI),
            modulus: modulus_pa,
        };
        if rhs.nrows() != self.n {
            return Err(FrfError::Length {
                what: "right-hand side rows",
                expected: self.n,
                got: rhs.nrows(),
            });
        }
        let mut ws = self.workspace(rhs.ncols())?;
        self.fill_pencil(lambda, modulus_pa, &mut ws.values);
        let z = SparseColMatRef::new(self.pattern.as_ref(), &ws.values);
        let lu = self
            .symbolic
            .factorize_numeric_lu(
                &mut ws.numeric,
                z,
                Par::Seq,
                MemStack::new(&mut ws.factor_buf),
                Default::default(),
            )
            .map_err(|_| singular())?;
        lu.solve_in_place_with_conj(
            Conj::No,
            rhs.rb_mut(),
            Par::Seq,
            MemStack::new(&mut ws.solve_buf),
        );
        if rhs
            .rb()
            .col_iter()
            .any(|c| c.iter().any(|v| !v.re.is_finite() || !v.im.is_finite()))
        {
            return Err(singular());
        }
        Ok(())
    }

    /// 1-norm of Z from its values on the pattern.
    fn norm1(&self, values: &[C64]) -> f64 {
        let cp = self.pattern.col_ptr();
        let mut best = 0.0f64;
        for j in 0..self.n {
            let s: f64 = values[cp[j]..cp[j + 1]].iter().map(|z| z.norm()).sum();
            best = best.max(s);
        }
        best
    }

    /// Factorise Z(w) and solve Z X = B in place (B: n x k). Checks for singularity.
    fn solve_in_place(
        &self,
        omega: f64,
        e: C64,
        ws: &mut Workspace,
        mut rhs: MatMut<'_, C64>,
    ) -> Result<(), FrfError> {
        let singular = || FrfError::Singular {
            freq_hz: omega / (2.0 * std::f64::consts::PI),
            modulus: e,
        };
        self.fill(omega, e, &mut ws.values);
        let z = SparseColMatRef::new(self.pattern.as_ref(), &ws.values);
        let b_norms: Vec<f64> = (0..rhs.ncols())
            .map(|j| rhs.rb().col(j).iter().map(|v| v.norm()).sum::<f64>())
            .collect();
        let lu = self
            .symbolic
            .factorize_numeric_lu(
                &mut ws.numeric,
                z,
                Par::Seq,
                MemStack::new(&mut ws.factor_buf),
                Default::default(),
            )
            .map_err(|_| singular())?;
        lu.solve_in_place_with_conj(
            Conj::No,
            rhs.rb_mut(),
            Par::Seq,
            MemStack::new(&mut ws.solve_buf),
        );
        let z_norm = self.norm1(&ws.values);
        for (j, &bn) in b_norms.iter().enumerate() {
            let xn: f64 = rhs.rb().col(j).iter().map(|v| v.norm()).sum();
            if !xn.is_finite() {
                return Err(singular());
            }
            if bn > 0.0 && z_norm * xn / bn > self.params.max_condition {
                return Err(singular());
            }
        }
        Ok(())
    }

    /// Solve Z(w) X = B for a dense right-hand side B (n x k) and return X. This is the
    /// general entry point (RFM uses it for whole receptance columns).
    pub fn solve(
        &self,
        omega_rad_s: f64,
        modulus_pa: C64,
        rhs: &Mat<C64>,
    ) -> Result<Mat<C64>, FrfError> {
        if rhs.nrows() != self.n {
            return Err(FrfError::Length {
                what: "right-hand side rows",
                expected: self.n,
                got: rhs.nrows(),
            });
        }
        let mut ws = self.workspace(rhs.ncols())?;
        let mut x = rhs.clone();
        self.solve_in_place(omega_rad_s, modulus_pa, &mut ws, x.as_mut())?;
        Ok(x)
    }

    /// The dense n x n_out matrix B whose column i is the observation vector b_i.
    pub fn observation_matrix(&self) -> Mat<C64> {
        let mut b = Mat::<C64>::zeros(self.n, self.obs.len());
        for (i, dofs) in self.obs.iter().enumerate() {
            for &(dof, w) in dofs {
                b[(dof, i)] += C64::new(w, 0.0);
            }
        }
        b
    }

    /// Receptance columns over all free DOFs: X = Z(w)^-1 B, one column per observation
    /// point (column j is receptance column of point j, and by symmetry of H also row j).
    pub fn receptance_columns(
        &self,
        omega_rad_s: f64,
        modulus_pa: C64,
    ) -> Result<Mat<C64>, FrfError> {
        self.solve(omega_rad_s, modulus_pa, &self.observation_matrix())
    }

    fn line(
        &self,
        omega: f64,
        e: C64,
        with_derivatives: bool,
        ws: &mut Workspace,
    ) -> Result<LineResult, FrfError> {
        let n_out = self.obs.len();
        let n_in = self.inputs.len();
        let mut x = self.observation_matrix();
        self.solve_in_place(omega, e, ws, x.as_mut())?;
        let read = |dofs: &[(usize, f64)], v: &dyn Fn(usize) -> C64| -> C64 {
            dofs.iter().map(|&(d, w)| v(d) * w).sum()
        };
        let mut h = vec![C64::new(0.0, 0.0); n_out * n_in];
        for i in 0..n_out {
            for (jj, &j) in self.inputs.iter().enumerate() {
                h[i * n_in + jj] = read(&self.obs[i], &|d| x[(d, j)]);
            }
        }
        let (mut dh, mut sh) = (Vec::new(), Vec::new());
        if with_derivatives {
            dh = vec![C64::new(0.0, 0.0); n_out * n_in];
            sh = vec![C64::new(0.0, 0.0); n_out * n_in];
            let mut sx = vec![C64::new(0.0, 0.0); self.n];
            for (jj, &j) in self.inputs.iter().enumerate() {
                let xj: Vec<C64> = x.col(j).iter().copied().collect();
                crate::linalg::spmv_complex(&self.s_mat, &xj, &mut sx);
                for i in 0..n_out {
                    sh[i * n_in + jj] = read(&self.obs[i], &|d| sx[d]);
                    let mut acc = C64::new(0.0, 0.0);
                    for (r, &v) in sx.iter().enumerate() {
                        acc += x[(r, i)] * v;
                    }
                    dh[i * n_in + jj] = -acc;
                }
            }
        }
        Ok(LineResult { h, dh, sh })
    }
}

impl FrfEngine for FullModel {
    fn n_out(&self) -> usize {
        self.obs.len()
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
        crate::frf::check_line_lengths(omega_rad_s, modulus_pa)?;
        let n_lines = omega_rad_s.len();
        let n_out = self.obs.len();
        let n_in = self.inputs.len();
        let rhs_cols = n_out;
        let results: Vec<Result<LineResult, FrfError>> = if self.params.parallel {
            (0..n_lines)
                .into_par_iter()
                .map_init(
                    || self.workspace(rhs_cols),
                    |ws, l| match ws {
                        Ok(ws) => self.line(omega_rad_s[l], modulus_pa[l], with_derivatives, ws),
                        Err(e) => Err(FrfError::Other(e.to_string())),
                    },
                )
                .collect()
        } else {
            let mut ws = self.workspace(rhs_cols)?;
            (0..n_lines)
                .map(|l| self.line(omega_rad_s[l], modulus_pa[l], with_derivatives, &mut ws))
                .collect()
        };
        *out = Sweep::zeros(n_lines, n_out, n_in, with_derivatives);
        let block = n_out * n_in;
        for (l, r) in results.into_iter().enumerate() {
            let r = r?;
            out.h[l * block..(l + 1) * block].copy_from_slice(&r.h);
            if with_derivatives {
                out.dh_de[l * block..(l + 1) * block].copy_from_slice(&r.dh);
                out.sh[l * block..(l + 1) * block].copy_from_slice(&r.sh);
            }
        }
        Ok(())
    }
}

/// Receptance column of observation point `input` over ALL free DOFs at one frequency:
/// x = Z(w)^-1 b_input. Builds a [`FullModel`] (symbolic analysis included), so for many
/// lines prefer [`FullModel::receptance_columns`].
pub fn receptance_column(
    model: &StructuralModel,
    omega_rad_s: f64,
    modulus_pa: C64,
    input: usize,
) -> Result<Vec<C64>, FrfError> {
    let fm = FullModel::new(model, &[input], FullParams::default())?;
    let mut b = Mat::<C64>::zeros(fm.n, 1);
    for &(dof, w) in &fm.obs[input] {
        b[(dof, 0)] += C64::new(w, 0.0);
    }
    let x = fm.solve(omega_rad_s, modulus_pa, &b)?;
    Ok(x.col(0).iter().copied().collect())
}
