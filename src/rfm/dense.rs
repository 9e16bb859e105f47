//! A dense reference FRF engine for small models: Z(w) = -w^2 M + K_b + j w C_b + j D_b + E* S
//! is formed densely and inverted per line (faer partial-pivoting LU), so H = Z^-1 is exact to
//! rounding. It implements [`FrfEngine`] with the same conventions as the sparse engines
//! (`crate::frf`, paper eq. 44-47):
//!
//! * `h[l, i, j]     = b_i^T H b_j`
//! * `dh_de[l, i, j] = -(H b_i)^T S (H b_j)`  (dH_ij/dE'; dH_ij/dE'' = j dH_ij/dE')
//! * `sh[l, i, j]    = b_i^T S H b_j`
//!
//! where b_i are the observation-point vectors. It exists for tests and cross-checks (a tiny
//! spring-mass chain, or a small mesh converted with [`DenseEngine::from_structural_model`]);
//! its cost is O(n^3) per line.

use crate::common::{C64, J};
use crate::fe::model::StructuralModel;
use crate::frf::{FrfEngine, FrfError, Sweep};
use faer::linalg::solvers::Solve;
use faer::Mat;

/// Dense model matrices (all n x n, over the free DOFs) and observation points.
#[derive(Clone, Debug)]
pub struct DenseEngine {
    m: Mat<f64>,
    k_b: Mat<f64>,
    s: Mat<f64>,
    c_b: Option<Mat<f64>>,
    d_b: Option<Mat<f64>>,
    /// Observation points as (DOF, weight) lists.
    points: Vec<Vec<(usize, f64)>>,
    /// Indices (into `points`) of the excitation points.
    inputs: Vec<usize>,
}

impl DenseEngine {
    /// Build from dense matrices. `points[i]` lists the (DOF, weight) pairs of observation point
    /// i; `inputs` are indices into `points`.
    pub fn new(
        m: Mat<f64>,
        k_b: Mat<f64>,
        s: Mat<f64>,
        points: Vec<Vec<(usize, f64)>>,
        inputs: Vec<usize>,
    ) -> Result<Self, FrfError> {
        let n = m.nrows();
        for (what, a) in [("M", &m), ("K_b", &k_b), ("S", &s)] {
            if a.nrows() != n || a.ncols() != n {
                return Err(FrfError::Length {
                    what: matrix_name(what),
                    expected: n,
                    got: a.nrows().max(a.ncols()),
                });
            }
        }
        for p in &points {
            if let Some(&(d, _)) = p.iter().find(|(d, _)| *d >= n) {
                return Err(FrfError::Other(format!(
                    "observation point uses DOF {d}, but the model has only {n} DOFs"
                )));
            }
        }
        if let Some(&bad) = inputs.iter().find(|&&i| i >= points.len()) {
            return Err(FrfError::BadInput(bad));
        }
        Ok(DenseEngine {
            m,
            k_b,
            s,
            c_b: None,
            d_b: None,
            points,
            inputs,
        })
    }

    /// Add adherend viscous (C_b) and/or structural (D_b) damping.
    pub fn with_damping(mut self, c_b: Option<Mat<f64>>, d_b: Option<Mat<f64>>) -> Self {
        self.c_b = c_b;
        self.d_b = d_b;
        self
    }

    /// Densify a (small) assembled structural model; `inputs` index `model.points`.
    pub fn from_structural_model(
        model: &StructuralModel,
        inputs: Vec<usize>,
    ) -> Result<Self, FrfError> {
        let points = model.points.iter().map(|p| p.dofs.clone()).collect();
        let e = DenseEngine::new(
            model.m.to_dense(),
            model.k_b.to_dense(),
            model.s.to_dense(),
            points,
            inputs,
        )?;
        Ok(e.with_damping(
            model.c_b.as_ref().map(|c| c.to_dense()),
            model.d_b.as_ref().map(|d| d.to_dense()),
        ))
    }

    /// Number of DOFs.
    pub fn n_dof(&self) -> usize {
        self.m.nrows()
    }

    /// Mass matrix.
    pub fn m(&self) -> &Mat<f64> {
        &self.m
    }
    /// Modulus-independent stiffness.
    pub fn k_b(&self) -> &Mat<f64> {
        &self.k_b
    }
    /// Adhesive stiffness at unit modulus.
    pub fn s(&self) -> &Mat<f64> {
        &self.s
    }

    /// Z(w) = -w^2 M + K_b + j w C_b + j D_b + E* S.
    pub fn dynamic_stiffness(&self, omega_rad_s: f64, modulus_pa: C64) -> Mat<C64> {
        let n = self.n_dof();
        let w2 = omega_rad_s * omega_rad_s;
        Mat::from_fn(n, n, |r, c| {
            let mut z =
                C64::new(self.k_b[(r, c)] - w2 * self.m[(r, c)], 0.0) + modulus_pa * self.s[(r, c)];
            if let Some(cb) = &self.c_b {
                z += J * (omega_rad_s * cb[(r, c)]);
            }
            if let Some(db) = &self.d_b {
                z += J * db[(r, c)];
            }
            z
        })
    }

    /// Full receptance matrix H = Z^-1 (n x n).
    pub fn receptance_matrix(
        &self,
        omega_rad_s: f64,
        modulus_pa: C64,
    ) -> Result<Mat<C64>, FrfError> {
        let n = self.n_dof();
        let z = self.dynamic_stiffness(omega_rad_s, modulus_pa);
        let lu = z.partial_piv_lu();
        let h = lu.solve(Mat::<C64>::identity(n, n));
        // Singularity check: non-finite entries or a large residual of Z H = I.
        let singular = || FrfError::Singular {
            freq_hz: omega_rad_s / (2.0 * std::f64::consts::PI),
            modulus: modulus_pa,
        };
        if !h.as_ref().is_all_finite() {
            return Err(singular());
        }
        let r = &z * &h - Mat::<C64>::identity(n, n);
        if r.norm_max() > 1e-6 {
            return Err(singular());
        }
        Ok(h)
    }

    /// b_i as a dense vector.
    fn point_vector(&self, i: usize) -> Vec<f64> {
        let mut v = vec![0.0; self.n_dof()];
        for &(d, w) in &self.points[i] {
            v[d] += w;
        }
        v
    }
}

fn matrix_name(what: &str) -> &'static str {
    match what {
        "M" => "dense M (rows or columns)",
        "K_b" => "dense K_b (rows or columns)",
        _ => "dense S (rows or columns)",
    }
}

impl FrfEngine for DenseEngine {
    fn n_out(&self) -> usize {
        self.points.len()
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
        let n = self.n_dof();
        let n_out = self.points.len();
        let n_in = self.inputs.len();
        *out = Sweep::zeros(omega_rad_s.len(), n_out, n_in, with_derivatives);
        let b: Vec<Vec<f64>> = (0..n_out).map(|i| self.point_vector(i)).collect();
        for (l, (&w, &e)) in omega_rad_s.iter().zip(modulus_pa).enumerate() {
            let h = self.receptance_matrix(w, e)?;
            // hb[i] = H b_i (n entries), for every observation point.
            let hb: Vec<Vec<C64>> = b
                .iter()
                .map(|bi| {
                    (0..n)
                        .map(|r| (0..n).map(|c| h[(r, c)] * bi[c]).sum())
                        .collect()
                })
                .collect();
            // shb[i] = S H b_i.
            let shb: Vec<Vec<C64>> = if with_derivatives {
                hb.iter()
                    .map(|x| {
                        (0..n)
                            .map(|r| (0..n).map(|c| x[c] * self.s[(r, c)]).sum())
                            .collect()
                    })
                    .collect()
            } else {
                Vec::new()
            };
            for i in 0..n_out {
                for (jj, &j) in self.inputs.iter().enumerate() {
                    let k = out.idx(l, i, jj);
                    out.h[k] = (0..n).map(|r| hb[j][r] * b[i][r]).sum();
                    if with_derivatives {
                        out.dh_de[k] = -(0..n).map(|r| hb[i][r] * shb[j][r]).sum::<C64>();
                        out.sh[k] = (0..n).map(|r| shb[j][r] * b[i][r]).sum();
                    }
                }
            }
        }
        Ok(())
    }
}
