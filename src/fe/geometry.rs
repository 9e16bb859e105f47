//! Physical 20-node hexahedron: isoparametric geometry map, Jacobian, strain-displacement
//! (B) matrix, and element mass and stiffness matrices for isotropic linear elasticity.
//!
//! - Geometry map x(xi) = sum_a N_a(xi) x_a; Jacobian J_kd = dx_d/dxi_k = sum_a dN_a/dxi_k x_ad;
//!   physical gradients dN_a/dx = J^-1 dN_a/dxi.
//! - Stiffness K_e = sum_g B^T D B det J w_g, written per node pair as
//!   K_(3a+i, 3b+j) = sum_g w_g det J (lambda g_ai g_bj + mu g_aj g_bi + mu delta_ij g_a . g_b),
//!   g_a = dN_a/dx, lambda = E nu / ((1 + nu)(1 - 2 nu)), mu = E / (2 (1 + nu)).
//!   This is exactly linear in E at fixed nu, so K_adhesive(E) = E S with S = K at E = 1 Pa.
//! - Consistent mass M_(3a+i, 3b+j) = delta_ij sum_g w_g det J rho N_a N_b, always with the
//!   3 x 3 x 3 rule (exact for a parallelepiped element), whatever the stiffness rule.
//!
//! Element matrices are 60 x 60, row-major, node-major DOFs (3 a + c), written into the
//! caller's buffer; `*_matrix` functions are allocating conveniences.

use super::element::{shape_gradients, shape_values, Integration, N_DOF, N_NODES};
use std::sync::OnceLock;

/// Node coordinates of one element (m), in the reference element's node order.
pub type ElementCoords = [[f64; 3]; N_NODES];

/// Isotropic linear elastic constants.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Elasticity {
    /// Young's modulus E (Pa).
    pub e_pa: f64,
    /// Poisson's ratio nu (-1 < nu < 0.5).
    pub nu: f64,
}

impl Elasticity {
    /// Lame constants (lambda, mu) in Pa.
    pub fn lame(&self) -> (f64, f64) {
        let (e, nu) = (self.e_pa, self.nu);
        (
            e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)),
            e / (2.0 * (1.0 + nu)),
        )
    }

    /// 6 x 6 isotropic elasticity matrix D in Voigt order (xx, yy, zz, xy, yz, zx),
    /// engineering shear strains.
    pub fn d_matrix(&self) -> [[f64; 6]; 6] {
        let (l, m) = self.lame();
        let mut d = [[0.0; 6]; 6];
        for (i, row) in d.iter_mut().enumerate().take(3) {
            for (j, v) in row.iter_mut().enumerate().take(3) {
                *v = l + if i == j { 2.0 * m } else { 0.0 };
            }
        }
        for (i, row) in d.iter_mut().enumerate().skip(3) {
            row[i] = m;
        }
        d
    }
}

/// A Gauss point of the element's rule, evaluated at a physical point with a
/// non-positive Jacobian determinant.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NonPositiveJacobian {
    pub det_j: f64,
}

/// Tabulated shape functions and natural gradients at the Gauss points of a rule.
pub struct RuleTable {
    pub weights: Vec<f64>,
    pub n: Vec<[f64; N_NODES]>,
    pub dn: Vec<[[f64; 3]; N_NODES]>,
}

fn make_table(rule: Integration) -> RuleTable {
    let pts = rule.rule();
    let mut t = RuleTable {
        weights: Vec::with_capacity(pts.len()),
        n: Vec::with_capacity(pts.len()),
        dn: Vec::with_capacity(pts.len()),
    };
    for (xi, w) in pts {
        let mut n = [0.0; N_NODES];
        let mut dn = [[0.0; 3]; N_NODES];
        shape_values(xi, &mut n);
        shape_gradients(xi, &mut dn);
        t.weights.push(w);
        t.n.push(n);
        t.dn.push(dn);
    }
    t
}

/// Cached table for an integration rule.
pub fn rule_table(rule: Integration) -> &'static RuleTable {
    static FULL: OnceLock<RuleTable> = OnceLock::new();
    static REDUCED: OnceLock<RuleTable> = OnceLock::new();
    match rule {
        Integration::Full => FULL.get_or_init(|| make_table(Integration::Full)),
        Integration::Reduced => REDUCED.get_or_init(|| make_table(Integration::Reduced)),
    }
}

/// Geometry map x(xi) = sum_a N_a(xi) x_a.
pub fn map_point(coords: &ElementCoords, xi: [f64; 3]) -> [f64; 3] {
    let mut n = [0.0; N_NODES];
    shape_values(xi, &mut n);
    let mut x = [0.0; 3];
    for (na, xa) in n.iter().zip(coords) {
        for d in 0..3 {
            x[d] += na * xa[d];
        }
    }
    x
}

/// Jacobian J_kd = dx_d / dxi_k from natural gradients.
pub fn jacobian(coords: &ElementCoords, dn: &[[f64; 3]; N_NODES]) -> [[f64; 3]; 3] {
    let mut j = [[0.0; 3]; 3];
    for (g, xa) in dn.iter().zip(coords) {
        for k in 0..3 {
            for d in 0..3 {
                j[k][d] += g[k] * xa[d];
            }
        }
    }
    j
}

/// Determinant and inverse of a 3 x 3 matrix (inverse is None when det = 0).
pub fn det_inv3(m: &[[f64; 3]; 3]) -> (f64, Option<[[f64; 3]; 3]>) {
    let c00 = m[1][1] * m[2][2] - m[1][2] * m[2][1];
    let c01 = m[1][2] * m[2][0] - m[1][0] * m[2][2];
    let c02 = m[1][0] * m[2][1] - m[1][1] * m[2][0];
    let det = m[0][0] * c00 + m[0][1] * c01 + m[0][2] * c02;
    if det == 0.0 || !det.is_finite() {
        return (det, None);
    }
    let r = 1.0 / det;
    let inv = [
        [
            c00 * r,
            (m[0][2] * m[2][1] - m[0][1] * m[2][2]) * r,
            (m[0][1] * m[1][2] - m[0][2] * m[1][1]) * r,
        ],
        [
            c01 * r,
            (m[0][0] * m[2][2] - m[0][2] * m[2][0]) * r,
            (m[0][2] * m[1][0] - m[0][0] * m[1][2]) * r,
        ],
        [
            c02 * r,
            (m[0][1] * m[2][0] - m[0][0] * m[2][1]) * r,
            (m[0][0] * m[1][1] - m[0][1] * m[1][0]) * r,
        ],
    ];
    (det, Some(inv))
}

/// Physical gradients g_a = dN_a/dx from natural ones; returns det J.
pub fn physical_gradients_from(
    coords: &ElementCoords,
    dn: &[[f64; 3]; N_NODES],
    g: &mut [[f64; 3]; N_NODES],
) -> Result<f64, NonPositiveJacobian> {
    let j = jacobian(coords, dn);
    let (det_j, inv) = det_inv3(&j);
    let inv = match inv {
        Some(inv) if det_j > 0.0 => inv,
        _ => return Err(NonPositiveJacobian { det_j }),
    };
    for (ga, d) in g.iter_mut().zip(dn) {
        for (r, gr) in ga.iter_mut().enumerate() {
            *gr = inv[r][0] * d[0] + inv[r][1] * d[1] + inv[r][2] * d[2];
        }
    }
    Ok(det_j)
}

/// Physical gradients at natural coordinates xi; returns det J.
pub fn physical_gradients(
    coords: &ElementCoords,
    xi: [f64; 3],
    g: &mut [[f64; 3]; N_NODES],
) -> Result<f64, NonPositiveJacobian> {
    let mut dn = [[0.0; 3]; N_NODES];
    shape_gradients(xi, &mut dn);
    physical_gradients_from(coords, &dn, g)
}

/// Strain-displacement matrix B (6 x 60), Voigt order (xx, yy, zz, xy, yz, zx) with
/// engineering shear strains, from physical gradients.
pub fn b_matrix(g: &[[f64; 3]; N_NODES], b: &mut [[f64; N_DOF]; 6]) {
    for row in b.iter_mut() {
        row.fill(0.0);
    }
    for (a, ga) in g.iter().enumerate() {
        let c = 3 * a;
        b[0][c] = ga[0];
        b[1][c + 1] = ga[1];
        b[2][c + 2] = ga[2];
        b[3][c] = ga[1];
        b[3][c + 1] = ga[0];
        b[4][c + 1] = ga[2];
        b[4][c + 2] = ga[1];
        b[5][c] = ga[2];
        b[5][c + 2] = ga[0];
    }
}

/// Strain eps = B(xi) u_e at natural coordinates xi for element displacements u_e (node-major).
pub fn strain_at(
    coords: &ElementCoords,
    u_e: &[f64; N_DOF],
    xi: [f64; 3],
) -> Result<[f64; 6], NonPositiveJacobian> {
    let mut g = [[0.0; 3]; N_NODES];
    physical_gradients(coords, xi, &mut g)?;
    let mut b = [[0.0; N_DOF]; 6];
    b_matrix(&g, &mut b);
    let mut eps = [0.0; 6];
    for (e, row) in eps.iter_mut().zip(&b) {
        *e = row.iter().zip(u_e).map(|(x, y)| x * y).sum();
    }
    Ok(eps)
}

/// Element volume, integral of det J with the 3 x 3 x 3 rule.
pub fn element_volume(coords: &ElementCoords) -> Result<f64, NonPositiveJacobian> {
    let t = rule_table(Integration::Full);
    let mut v = 0.0;
    for (w, dn) in t.weights.iter().zip(&t.dn) {
        let (det, _) = det_inv3(&jacobian(coords, dn));
        if det <= 0.0 {
            return Err(NonPositiveJacobian { det_j: det });
        }
        v += w * det;
    }
    Ok(v)
}

/// Element stiffness K_e (60 x 60, row-major) into `ke` for isotropic elasticity.
pub fn element_stiffness_into(
    coords: &ElementCoords,
    mat: Elasticity,
    rule: Integration,
    ke: &mut [f64],
) -> Result<(), NonPositiveJacobian> {
    assert_eq!(
        ke.len(),
        N_DOF * N_DOF,
        "element stiffness buffer must hold 60 x 60"
    );
    ke.fill(0.0);
    let (lam, mu) = mat.lame();
    let t = rule_table(rule);
    let mut g = [[0.0; 3]; N_NODES];
    for (w, dn) in t.weights.iter().zip(&t.dn) {
        let det = physical_gradients_from(coords, dn, &mut g)?;
        let f = w * det;
        let (fl, fm) = (f * lam, f * mu);
        for (a, &ga) in g.iter().enumerate() {
            for (b, &gb) in g.iter().enumerate().skip(a) {
                let dot = fm * (ga[0] * gb[0] + ga[1] * gb[1] + ga[2] * gb[2]);
                for i in 0..3 {
                    let row = (3 * a + i) * N_DOF + 3 * b;
                    for j in 0..3 {
                        let mut v = fl * ga[i] * gb[j] + fm * ga[j] * gb[i];
                        if i == j {
                            v += dot;
                        }
                        ke[row + j] += v;
                    }
                }
            }
        }
    }
    // mirror the upper block triangle (a < b) to the lower one
    for a in 0..N_NODES {
        for b in (a + 1)..N_NODES {
            for i in 0..3 {
                for j in 0..3 {
                    ke[(3 * b + j) * N_DOF + 3 * a + i] = ke[(3 * a + i) * N_DOF + 3 * b + j];
                }
            }
        }
    }
    Ok(())
}

/// Consistent element mass M_e (60 x 60, row-major) into `me`, 3 x 3 x 3 rule.
pub fn element_mass_into(
    coords: &ElementCoords,
    rho_kg_m3: f64,
    me: &mut [f64],
) -> Result<(), NonPositiveJacobian> {
    assert_eq!(
        me.len(),
        N_DOF * N_DOF,
        "element mass buffer must hold 60 x 60"
    );
    me.fill(0.0);
    let t = rule_table(Integration::Full);
    for ((w, dn), n) in t.weights.iter().zip(&t.dn).zip(&t.n) {
        let (det, _) = det_inv3(&jacobian(coords, dn));
        if det <= 0.0 || !det.is_finite() {
            return Err(NonPositiveJacobian { det_j: det });
        }
        let f = w * det * rho_kg_m3;
        for a in 0..N_NODES {
            for b in a..N_NODES {
                let v = f * n[a] * n[b];
                for i in 0..3 {
                    me[(3 * a + i) * N_DOF + 3 * b + i] += v;
                }
            }
        }
    }
    for a in 0..N_NODES {
        for b in (a + 1)..N_NODES {
            for i in 0..3 {
                me[(3 * b + i) * N_DOF + 3 * a + i] = me[(3 * a + i) * N_DOF + 3 * b + i];
            }
        }
    }
    Ok(())
}

/// Allocating form of [`element_stiffness_into`].
pub fn element_stiffness(
    coords: &ElementCoords,
    mat: Elasticity,
    rule: Integration,
) -> Result<Vec<f64>, NonPositiveJacobian> {
    let mut ke = vec![0.0; N_DOF * N_DOF];
    element_stiffness_into(coords, mat, rule, &mut ke)?;
    Ok(ke)
}

/// Allocating form of [`element_mass_into`].
pub fn element_mass(
    coords: &ElementCoords,
    rho_kg_m3: f64,
) -> Result<Vec<f64>, NonPositiveJacobian> {
    let mut me = vec![0.0; N_DOF * N_DOF];
    element_mass_into(coords, rho_kg_m3, &mut me)?;
    Ok(me)
}

/// Coordinates of the axis-aligned box [x0, x1] x [y0, y1] x [z0, z1] as one element
/// (mid-edge nodes at the edge midpoints).
pub fn box_element(lo: [f64; 3], hi: [f64; 3]) -> ElementCoords {
    let mut c = [[0.0; 3]; N_NODES];
    for (a, xi) in super::element::NODE_XI.iter().enumerate() {
        for d in 0..3 {
            c[a][d] = lo[d] + 0.5 * (xi[d] + 1.0) * (hi[d] - lo[d]);
        }
    }
    c
}
