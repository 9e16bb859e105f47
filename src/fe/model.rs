//! The assembled structural model: sparse M, K_b, S (and optional adherend damping) over the
//! free DOFs, plus the observation points (measurement and excitation DOFs).

use crate::common::Direction;
use faer::sparse::SparseColMat;

/// Real sparse matrix over the free DOFs (constrained DOFs already removed).
pub type SpMat = SparseColMat<usize, f64>;

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
    pub fn with_point_masses(&self, masses: &[(usize, f64)]) -> Result<StructuralModel, String> {
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
        for &(k, mass) in masses {
            let pt = self.points.get(k).ok_or_else(|| {
                format!(
                    "point index {k} is out of range ({} points)",
                    self.points.len()
                )
            })?;
            for &(a, wa) in &pt.dofs {
                for &(b, wb) in &pt.dofs {
                    trip.push(Triplet::new(a, b, mass * wa * wb));
                }
            }
        }
        let m = SpMat::try_new_from_triplets(n, n, &trip)
            .map_err(|e| format!("cannot add point masses: {e:?}"))?;
        let mut out = self.clone();
        out.m = m;
        out.description = format!("{} + point masses {:?}", self.description, masses);
        Ok(out)
    }
}
