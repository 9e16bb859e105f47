//! Synthetic structural models for tests and benchmarks: a 3D lattice of point masses
//! joined by springs, held only by "adhesive" springs (scaled by E) to the ground under part
//! of its lower face — the same structure as the bonded joint (a free adherend on a
//! viscoelastic layer), at any size, without the mesher.
//!
//! Node (i, j, k), i < nx (the "beam axis" x), j < ny (y, the excitation direction),
//! k < nz (z), has 3 DOFs (x, y, z) numbered 3 * node + axis. Each pair of neighbours along
//! axis e is joined by a spring with stiffness k_ax e e^T + k_sh (I - e e^T) (random within
//! +-20 %, seeded); the mass matrix is lumped node masses plus a consistent coupling
//! m_c/6 [[2, 1], [1, 2]] per spring and axis (so M is SPD but not diagonal). Nodes of layer
//! j = 0 with i < nx_bond are tied to the ground by springs of stiffness s0 (per unit Young's
//! modulus, m) in all three axes: these form S.

use super::model::{ObservationPoint, SpMat, StructuralModel};
use crate::common::{Direction, C64};
use faer::sparse::Triplet;
use rand::{RngExt, SeedableRng};

/// Settings of [`lattice_model`].
#[derive(Clone, Debug)]
pub struct LatticeParams {
    pub nx: usize,
    pub ny: usize,
    pub nz: usize,
    /// Number of bonded node columns along x (default nx / 4, at least 1).
    pub nx_bond: usize,
    /// Node mass (kg), default 1e-3.
    pub node_mass: f64,
    /// Axial spring stiffness (N/m), default 1e6; shear springs are 0.4 of it.
    pub k_axial: f64,
    /// Ground spring per unit modulus (m), default 1e-3 (so E = 7 MPa gives 7e3 N/m).
    pub s0: f64,
    pub seed: u64,
}

impl LatticeParams {
    pub fn new(nx: usize, ny: usize, nz: usize, seed: u64) -> Self {
        LatticeParams {
            nx,
            ny,
            nz,
            nx_bond: (nx / 4).max(1),
            node_mass: 1e-3,
            k_axial: 1e6,
            s0: 1e-3,
            seed,
        }
    }
}

/// A lattice model and the axis (0 = x, 1 = y, 2 = z) of each DOF.
pub struct Lattice {
    pub model: StructuralModel,
    pub dof_axes: Vec<u8>,
}

/// Build the lattice model (see module docs). Observation points: the y DOFs of the top-layer
/// (j = ny - 1) nodes on the mid line k = nz / 2 at i = nx/3, nx/2, 2nx/3, nx - 1, with ids
/// 1..=4, plus (id 5) a point between two top nodes in -y with weights (-0.5, -0.5).
pub fn lattice_model(p: &LatticeParams) -> Lattice {
    let (nx, ny, nz) = (p.nx, p.ny, p.nz);
    let node = |i: usize, j: usize, k: usize| (i * ny + j) * nz + k;
    let n_nodes = nx * ny * nz;
    let n = 3 * n_nodes;
    let mut rng = rand::rngs::StdRng::seed_from_u64(p.seed);
    let mut kt: Vec<Triplet<usize, usize, f64>> = Vec::new();
    let mut mt: Vec<Triplet<usize, usize, f64>> = Vec::new();
    let mut st: Vec<Triplet<usize, usize, f64>> = Vec::new();
    for a in 0..n_nodes {
        let m = p.node_mass * rng.random_range(0.8..1.2);
        for ax in 0..3 {
            mt.push(Triplet::new(3 * a + ax, 3 * a + ax, m));
        }
    }
    for i in 0..nx {
        for j in 0..ny {
            for k in 0..nz {
                let a = node(i, j, k);
                let nbrs = [
                    (i + 1 < nx).then(|| (node(i + 1, j, k), 0usize)),
                    (j + 1 < ny).then(|| (node(i, j + 1, k), 1usize)),
                    (k + 1 < nz).then(|| (node(i, j, k + 1), 2usize)),
                ];
                for (b, e) in nbrs.into_iter().flatten() {
                    let f = rng.random_range(0.8..1.2);
                    let mc = 0.1 * p.node_mass * rng.random_range(0.8..1.2);
                    for ax in 0..3 {
                        let kk = if ax == e { p.k_axial } else { 0.4 * p.k_axial } * f;
                        let (da, db) = (3 * a + ax, 3 * b + ax);
                        kt.push(Triplet::new(da, da, kk));
                        kt.push(Triplet::new(db, db, kk));
                        kt.push(Triplet::new(da, db, -kk));
                        kt.push(Triplet::new(db, da, -kk));
                        mt.push(Triplet::new(da, da, mc / 3.0));
                        mt.push(Triplet::new(db, db, mc / 3.0));
                        mt.push(Triplet::new(da, db, mc / 6.0));
                        mt.push(Triplet::new(db, da, mc / 6.0));
                    }
                }
                if j == 0 && i < p.nx_bond {
                    for ax in 0..3 {
                        let s = p.s0 * rng.random_range(0.8..1.2) * if ax == 1 { 2.0 } else { 1.0 };
                        st.push(Triplet::new(3 * a + ax, 3 * a + ax, s));
                    }
                }
            }
        }
    }
    let build = |t: &[Triplet<usize, usize, f64>]| -> SpMat {
        SpMat::try_new_from_triplets(n, n, t).expect("valid lattice triplets")
    };
    let top = ny - 1;
    let kmid = nz / 2;
    let mut points = Vec::new();
    for (id, i) in [nx / 3, nx / 2, 2 * nx / 3, nx - 1].into_iter().enumerate() {
        points.push(ObservationPoint {
            id: id as u32 + 1,
            position: Some([i as f64, top as f64, kmid as f64]),
            direction: Direction::PY,
            dofs: vec![(3 * node(i, top, kmid) + 1, 1.0)],
            note: String::new(),
        });
    }
    let (i0, i1) = (nx / 2, (nx / 2 + 1).min(nx - 1));
    points.push(ObservationPoint {
        id: 5,
        position: None,
        direction: Direction::new(crate::common::Axis::Y, -1),
        dofs: vec![
            (3 * node(i0, top, kmid) + 1, -0.5),
            (3 * node(i1, top, kmid) + 1, -0.5),
        ],
        note: "between two nodes".into(),
    });
    let dof_axes = (0..n).map(|d| (d % 3) as u8).collect();
    Lattice {
        model: StructuralModel {
            m: build(&mt),
            k_b: build(&kt),
            s: build(&st),
            c_b: None,
            d_b: None,
            points,
            description: format!("synthetic lattice {nx}x{ny}x{nz}, seed {}", p.seed),
        },
        dof_axes,
    }
}

/// Add Rayleigh viscous damping C_b = alpha M + beta K_b and structural damping D_b = g K_b.
pub fn add_damping(model: &mut StructuralModel, alpha: f64, beta: f64, g: f64) {
    let n = model.n_dof();
    let mut ct = Vec::new();
    let mut dt = Vec::new();
    for t in model.m.triplet_iter() {
        ct.push(Triplet::new(t.row, t.col, alpha * *t.val));
    }
    for t in model.k_b.triplet_iter() {
        ct.push(Triplet::new(t.row, t.col, beta * *t.val));
        dt.push(Triplet::new(t.row, t.col, g * *t.val));
    }
    model.c_b = SpMat::try_new_from_triplets(n, n, &ct).ok();
    model.d_b = SpMat::try_new_from_triplets(n, n, &dt).ok();
}

/// Dense copy of a sparse real matrix as complex (test oracle helper).
pub fn to_dense_c64(a: &SpMat) -> faer::Mat<C64> {
    let mut d = faer::Mat::<C64>::zeros(a.nrows(), a.ncols());
    for t in a.triplet_iter() {
        d[(t.row, t.col)] += C64::new(*t.val, 0.0);
    }
    d
}

/// Dense copy of a sparse real matrix (test oracle helper).
pub fn to_dense(a: &SpMat) -> faer::Mat<f64> {
    let mut d = faer::Mat::<f64>::zeros(a.nrows(), a.ncols());
    for t in a.triplet_iter() {
        d[(t.row, t.col)] += *t.val;
    }
    d
}
