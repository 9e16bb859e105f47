//! The assembled structural model: sparse M, K_b, S (and optional adherend damping) over the
//! free DOFs, plus the observation points (measurement and excitation DOFs).

use super::error::ModelEditError;
use crate::common::Direction;

/// Real sparse matrix over the free DOFs (constrained DOFs already removed).
pub use crate::linalg::SpMat;

/// A measurement or excitation point: a response (or force) in one direction, as a linear
/// combination of free DOFs. At a node this is a single DOF with weight 1; a point inside an
/// element face uses the shape-function weights (the same weights distribute a point force).
#[derive(Clone, Debug, PartialEq)]
pub struct ObservationPoint {
    /// Point id: the node number used in measured files (UFF rsp_node / ref_node).
    pub id: u32,
    /// Position in metres, when known (None for imported models without coordinates).
    pub position: Option<[f64; 3]>,
    pub direction: Direction,
    /// (free DOF index, weight) pairs; weights include the direction's sign.
    pub dofs: Vec<(usize, f64)>,
    /// Human-readable note, e.g. "snapped to node 412 (0.8 mm away)".
    pub note: String,
}

/// Z(w) = -w^2 M + K_b + j w C_b + j D_b + E* S over the free DOFs.
#[derive(Clone, Debug)]
pub struct StructuralModel {
    /// Mass matrix M (kg).
    pub m: SpMat,
    /// Adherend (and any modulus-independent) stiffness K_b (N/m).
    pub k_b: SpMat,
    /// Adhesive stiffness at unit Young's modulus, S = dK_adhesive/dE (m), so K_adhesive = E S.
    pub s: SpMat,
    /// Optional viscous damping C_b (N s/m), e.g. Rayleigh a M + b K_b.
    pub c_b: Option<SpMat>,
    /// Optional structural (hysteretic) damping D_b (N/m), e.g. g K_b.
    pub d_b: Option<SpMat>,
    /// Observation points (responses); excitation points are among them.
    pub points: Vec<ObservationPoint>,
    /// Where this model came from (mesher settings or imported files).
    pub description: String,
}

impl StructuralModel {
    /// Number of free DOFs.
    pub fn n_dof(&self) -> usize {
        self.m.nrows()
    }

    /// Index of the point with the given id and direction, if present.
    pub fn point_index(&self, id: u32, direction: Direction) -> Option<usize> {
        self.points
            .iter()
            .position(|p| p.id == id && p.direction == direction)
    }
}

impl StructuralModel {
    /// A copy with lumped point masses added at observation points: M' = M + sum m_k w_k w_k^T,
    /// with w_k the point's DOF weights (the mass acts in the point's measured direction only;
    /// cross-axis mass and rotary inertia of the sensor are neglected). `masses` holds
    /// (point index, kg) pairs.
    pub fn with_point_masses(
        &self,
        masses: &[(usize, f64)],
    ) -> Result<StructuralModel, ModelEditError> {
        use faer::sparse::Triplet;
        let n = self.n_dof();
        let mut trip: Vec<Triplet<usize, usize, f64>> = Vec::new();
        let sym = self.m.symbolic();
        let (cp, ri) = (sym.col_ptr(), sym.row_idx());
        let vals = self.m.val();
        for j in 0..n {
            for p in cp[j]..cp[j + 1] {
                trip.push(Triplet::new(ri[p], j, vals[p]));
            }
        }
        trip.extend(self.point_mass_triplets(masses)?);
        let m = SpMat::try_new_from_triplets(n, n, &trip).map_err(|e| ModelEditError::Sparse {
            what: "the mass matrix with point masses",
            detail: format!("{e:?}"),
        })?;
        let mut out = self.clone();
        out.m = m;
        out.description = format!("{} + point masses {:?}", self.description, masses);
        Ok(out)
    }

    /// The mass matrix [`Self::with_point_masses`] adds for `masses`, alone:
    /// `sum m_k w_k w_k^T` (n x n).
    pub fn point_mass_matrix(&self, masses: &[(usize, f64)]) -> Result<SpMat, ModelEditError> {
        let n = self.n_dof();
        SpMat::try_new_from_triplets(n, n, &self.point_mass_triplets(masses)?).map_err(|e| {
            ModelEditError::Sparse {
                what: "the point masses' mass matrix",
                detail: format!("{e:?}"),
            }
        })
    }

    /// The entries `m_k w_k w_k^T` of `masses` (point index, kg).
    fn point_mass_triplets(
        &self,
        masses: &[(usize, f64)],
    ) -> Result<Vec<faer::sparse::Triplet<usize, usize, f64>>, ModelEditError> {
        let mut trip = Vec::new();
        for &(k, mass) in masses {
            let pt = self.points.get(k).ok_or(ModelEditError::PointOutOfRange {
                index: k,
                n_points: self.points.len(),
            })?;
            for &(a, wa) in &pt.dofs {
                for &(b, wb) in &pt.dofs {
                    trip.push(faer::sparse::Triplet::new(a, b, mass * wa * wb));
                }
            }
        }
        Ok(trip)
    }
}

/// Copy of `a` padded with `extra` zero rows and columns, plus the `(row, col, value)` entries
/// of `add` (duplicates summed).
fn padded(a: &SpMat, extra: usize, add: &[(usize, usize, f64)]) -> Result<SpMat, ModelEditError> {
    use faer::sparse::Triplet;
    let n = a.nrows();
    let sym = a.symbolic();
    let (cp, ri) = (sym.col_ptr(), sym.row_idx());
    let mut trip: Vec<Triplet<usize, usize, f64>> = Vec::with_capacity(a.val().len() + add.len());
    for j in 0..n {
        for p in cp[j]..cp[j + 1] {
            trip.push(Triplet::new(ri[p], j, a.val()[p]));
        }
    }
    trip.extend(add.iter().map(|&(i, j, v)| Triplet::new(i, j, v)));
    SpMat::try_new_from_triplets(n + extra, n + extra, &trip).map_err(|e| ModelEditError::Sparse {
        what: "a matrix padded with the shaker's DOF",
        detail: format!("{e:?}"),
    })
}

impl StructuralModel {
    /// A copy with a shaker attached at point `drive`: one extra DOF `x_s` (the moving mass
    /// `m_s`, kg) joined to the point by a stinger spring `k_s` (N/m) along the point's
    /// direction, `M' = M + m_s e_s e_s^T`, `K_b' = K_b + k_s (b_d - e_s)(b_d - e_s)^T` (b_d the
    /// point's DOF weights), S and the damping matrices padded with zeros. Returns the model
    /// and the index of a new observation point on the moving mass (id `armature_id`): the
    /// FRF driven there is the response per force on the shaker's side of the stinger.
    pub fn with_shaker(
        &self,
        drive: usize,
        m_s: f64,
        k_s: f64,
        armature_id: u32,
    ) -> Result<(StructuralModel, usize), ModelEditError> {
        let pt = self
            .points
            .get(drive)
            .ok_or(ModelEditError::PointOutOfRange {
                index: drive,
                n_points: self.points.len(),
            })?;
        if !(m_s.is_finite() && m_s >= 0.0 && k_s.is_finite() && k_s > 0.0) {
            return Err(ModelEditError::InvalidParameter(format!(
                "shaker: moving mass {m_s} kg must be >= 0 and stinger stiffness {k_s} N/m > 0"
            )));
        }
        let n = self.n_dof();
        // b = b_d - e_s
        let mut b: Vec<(usize, f64)> = pt.dofs.clone();
        b.push((n, -1.0));
        let mut kb = Vec::with_capacity(b.len() * b.len());
        for &(i, wi) in &b {
            for &(j, wj) in &b {
                kb.push((i, j, k_s * wi * wj));
            }
        }
        let mut out = self.clone();
        out.m = padded(&self.m, 1, &[(n, n, m_s)])?;
        out.k_b = padded(&self.k_b, 1, &kb)?;
        out.s = padded(&self.s, 1, &[])?;
        out.c_b = self.c_b.as_ref().map(|c| padded(c, 1, &[])).transpose()?;
        out.d_b = self.d_b.as_ref().map(|d| padded(d, 1, &[])).transpose()?;
        out.points.push(ObservationPoint {
            id: armature_id,
            position: pt.position,
            direction: pt.direction,
            dofs: vec![(n, 1.0)],
            note: format!(
                "shaker moving mass ({m_s} kg on {k_s:.3e} N/m) at point {}",
                pt.id
            ),
        });
        out.description = format!(
            "{} + shaker ({m_s} kg, {k_s:.3e} N/m) at point {}",
            self.description, pt.id
        );
        Ok((out, self.points.len()))
    }
}
