//! A compliant base: distributed normal and tangential springs under the
//! adhesive's lower face instead of a fixed face (a Winkler foundation; the block the joint
//! is bonded to, or its clamping, is not rigid).
//!
//! ```text
//!   K_b -> K_b + k_n K_n + k_t K_t   over the DOFs with the lower face free
//!   K_n = int_base N^T e_y e_y^T N dA,   K_t = int_base N^T (e_x e_x^T + e_z e_z^T) N dA
//! ```
//!
//! with `k_n`, `k_t` the springs' stiffness per unit area (N/m^3) and `N` the 8-node
//! serendipity shape functions of the adhesive elements' lower faces (the 20-node element's
//! functions on the face eta = -1; the other 12 vanish there), integrated with 3 x 3 Gauss
//! points (exact for the products on a rectangular face). `1^T K_n 1` (the y DOFs) is the
//! base area, like `1^T K_t 1` over x (and z) DOFs: a rigid translation of the face by u
//! stores `k A u^2 / 2`. As `k_n, k_t -> inf` the model tends to the fixed base of
//! [`super::joint::build_joint_model`] (tests/suite/base_springs.rs).
//!
//! The DOF numbering of the model on springs differs from the fixed model's (the face's DOFs
//! exist); observation points are mapped on the same mesh, so responses compare point by
//! point.

use super::assembly::DofMap;
use super::element::{face_nodes, shape_gradients, shape_values, N_NODES};
use super::error::FeError;
use super::joint::{assemble_joint, joint_mesh_from_spec, JointSpec, MeshInfo};
use super::mesh::Region;
use super::model::{SpMat, StructuralModel};
use faer::sparse::Triplet;

/// Spring stiffness per unit area of the base (N/m^3).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BaseSprings {
    /// Normal to the face (y).
    pub normal_n_m3: f64,
    /// In the face's plane (x and z).
    pub tangential_n_m3: f64,
}

/// The joint with its base face free, and the base's unit spring matrices on its DOFs.
#[derive(Clone, Debug)]
pub struct BaseSpringModel {
    /// The joint with the adhesive's lower face free and no springs (singular alone: it
    /// floats).
    pub free: StructuralModel,
    pub info: MeshInfo,
    /// `K_n` for `k_n = 1` N/m^3 (m^2).
    pub k_normal: SpMat,
    /// `K_t` for `k_t = 1` N/m^3 (m^2).
    pub k_tangential: SpMat,
    /// Area of the base face (m^2).
    pub area_m2: f64,
    /// Nodes on the base face.
    pub n_base_nodes: usize,
}

impl BaseSpringModel {
    /// `K_n / r + K_t` scaled so that `k_n K_n + k_t K_t = k_n G` with `r = k_n / k_t`, i.e.
    /// `G = K_n + K_t / r`: the base's spring matrix per unit normal stiffness at a fixed
    /// ratio of normal to tangential stiffness.
    pub fn combined(&self, normal_over_tangential: f64) -> Result<SpMat, FeError> {
        sum(
            &self.k_normal,
            1.0,
            &self.k_tangential,
            1.0 / normal_over_tangential,
        )
    }

    /// The model on `springs`: `K_b + k_n K_n + k_t K_t`.
    pub fn on_springs(&self, springs: &BaseSprings) -> Result<StructuralModel, FeError> {
        let kb = sum(&self.free.k_b, 1.0, &self.k_normal, springs.normal_n_m3)?;
        let kb = sum(&kb, 1.0, &self.k_tangential, springs.tangential_n_m3)?;
        let mut m = self.free.clone();
        m.k_b = kb;
        m.description = format!(
            "{} on base springs k_n = {:.4e} N/m^3, k_t = {:.4e} N/m^3",
            self.free.description, springs.normal_n_m3, springs.tangential_n_m3
        );
        Ok(m)
    }
}

fn sum(a: &SpMat, alpha: f64, b: &SpMat, beta: f64) -> Result<SpMat, FeError> {
    let mut t: Vec<Triplet<usize, usize, f64>> = a
        .triplet_iter()
        .map(|t| Triplet::new(t.row, t.col, alpha * *t.val))
        .collect();
    t.extend(
        b.triplet_iter()
            .map(|t| Triplet::new(t.row, t.col, beta * *t.val)),
    );
    SpMat::try_new_from_triplets(a.nrows(), a.ncols(), &t).map_err(|_| FeError::OutOfMemory {
        key: "structure.mesh".into(),
        what: "the base springs' stiffness".into(),
    })
}

/// Check a spring stiffness (N/m^3): finite and > 0. `key` names the input.
pub fn check_springs(springs: &BaseSprings, key: &str) -> Result<(), FeError> {
    for (k, v) in [
        ("normal", springs.normal_n_m3),
        ("tangential", springs.tangential_n_m3),
    ] {
        if !(v.is_finite() && v > 0.0) {
            return Err(FeError::InvalidMaterial {
                key: format!("{key}.{k}"),
                value: v,
                requirement: "a base spring stiffness per unit area must be finite and > 0 (N/m^3; e.g. 3e10, stiffer than the adhesive layer's E/t of about 2e9)".into(),
            });
        }
    }
    Ok(())
}

/// Build the joint of `spec` with its base face free, and the base's unit spring matrices.
pub fn base_spring_model(spec: &JointSpec) -> Result<BaseSpringModel, FeError> {
    let (mut mesh, layout) = joint_mesh_from_spec(spec)?;
    let y_base = -layout.adhesive_thickness_m;
    let tol = 1e-9 * layout.adhesive_thickness_m;
    mesh.fixed.iter_mut().for_each(|f| *f = false);
    let (mut free, info, dofs) = assemble_joint(spec, &mesh, &layout)?;
    free.description = format!("{} (base face free)", free.description);
    let face = face_nodes(1, -1.0);
    let mut tn: Vec<Triplet<usize, usize, f64>> = Vec::new();
    let mut tt: Vec<Triplet<usize, usize, f64>> = Vec::new();
    let mut area = 0.0;
    let mut base_nodes = std::collections::BTreeSet::new();
    const A: f64 = 0.774_596_669_241_483_4; // sqrt(3/5)
    let gauss = [(-A, 5.0 / 9.0), (0.0, 8.0 / 9.0), (A, 5.0 / 9.0)];
    for e in mesh.elements_in(Region::Adhesive) {
        let conn = &mesh.elements[e];
        if !face
            .iter()
            .all(|&a| (mesh.nodes[conn[a]][1] - y_base).abs() <= tol)
        {
            continue;
        }
        let c = mesh.element_coords(e);
        let mut ke = [[0.0f64; 8]; 8];
        for &(xi, wx) in &gauss {
            for &(zeta, wz) in &gauss {
                let p = [xi, -1.0, zeta];
                let mut n = [0.0; N_NODES];
                let mut dn = [[0.0; 3]; N_NODES];
                shape_values(p, &mut n);
                shape_gradients(p, &mut dn);
                // Tangent vectors dx/dxi and dx/dzeta; dA = |t_xi x t_zeta| dxi dzeta.
                let mut t1 = [0.0; 3];
                let mut t3 = [0.0; 3];
                for a in 0..N_NODES {
                    for d in 0..3 {
                        t1[d] += dn[a][0] * c[a][d];
                        t3[d] += dn[a][2] * c[a][d];
                    }
                }
                let cr = [
                    t1[1] * t3[2] - t1[2] * t3[1],
                    t1[2] * t3[0] - t1[0] * t3[2],
                    t1[0] * t3[1] - t1[1] * t3[0],
                ];
                let da = (cr[0] * cr[0] + cr[1] * cr[1] + cr[2] * cr[2]).sqrt() * wx * wz;
                area += da;
                for (i, &a) in face.iter().enumerate() {
                    for (j, &b) in face.iter().enumerate() {
                        ke[i][j] += n[a] * n[b] * da;
                    }
                }
            }
        }
        for (i, &a) in face.iter().enumerate() {
            base_nodes.insert(conn[a]);
            for (j, &b) in face.iter().enumerate() {
                push(&mut tn, &dofs, conn[a], conn[b], 1, ke[i][j]);
                for comp in [0, 2] {
                    push(&mut tt, &dofs, conn[a], conn[b], comp, ke[i][j]);
                }
            }
        }
    }
    if base_nodes.is_empty() {
        return Err(FeError::Unconstrained {
            key: "structure.adhesive.length".into(),
            fix: "no adhesive element touches the base face: give the adhesive a positive length and thickness".into(),
        });
    }
    let n = dofs.n_free;
    let mk = |t: &[Triplet<usize, usize, f64>]| {
        SpMat::try_new_from_triplets(n, n, t).map_err(|_| FeError::OutOfMemory {
            key: "structure.mesh".into(),
            what: "the base springs' stiffness".into(),
        })
    };
    Ok(BaseSpringModel {
        k_normal: mk(&tn)?,
        k_tangential: mk(&tt)?,
        free,
        info,
        area_m2: area,
        n_base_nodes: base_nodes.len(),
    })
}

fn push(
    t: &mut Vec<Triplet<usize, usize, f64>>,
    dofs: &DofMap,
    a: usize,
    b: usize,
    comp: usize,
    v: f64,
) {
    if let (Some(i), Some(j)) = (dofs.dof(a, comp), dofs.dof(b, comp)) {
        t.push(Triplet::new(i, j, v));
    }
}

/// The joint of `spec` on base springs (the model `rfmlab simulate` uses for test data with
/// a compliant base). `key` names the springs' input for errors.
pub fn joint_model_on_springs(
    spec: &JointSpec,
    springs: &BaseSprings,
    key: &str,
) -> Result<StructuralModel, FeError> {
    check_springs(springs, key)?;
    base_spring_model(spec)?.on_springs(springs)
}
