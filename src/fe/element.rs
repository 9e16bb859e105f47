//! Reference 20-node serendipity hexahedron on [-1, 1]^3 (shape functions only).
//!
//! Node order (ANSYS SOLID186 / Abaqus C3D20): corners 0-7
//! (-1,-1,-1), (1,-1,-1), (1,1,-1), (-1,1,-1), (-1,-1,1), (1,-1,1), (1,1,1), (-1,1,1);
//! mid-edge nodes 8-11 on the bottom face (zeta = -1) between corners 0-1, 1-2, 2-3, 3-0;
//! 12-15 on the top face between 4-5, 5-6, 6-7, 7-4; 16-19 on the vertical edges 0-4, 1-5,
//! 2-6, 3-7.
//!
//! Shape functions (serendipity, e.g. Zienkiewicz & Taylor, vol. 1, ch. 6), with
//! (xi_i, eta_i, zeta_i) the node's natural coordinates:
//!
//! - corner: N_i = 1/8 (1 + xi xi_i)(1 + eta eta_i)(1 + zeta zeta_i)(xi xi_i + eta eta_i + zeta zeta_i - 2)
//! - mid-edge with xi_i = 0: N_i = 1/4 (1 - xi^2)(1 + eta eta_i)(1 + zeta zeta_i), and likewise
//!   for eta_i = 0 or zeta_i = 0.

/// Number of nodes of the element.
pub const N_NODES: usize = 20;
/// Number of DOFs of the element (3 per node, node-major: DOF 3 a + c is node a, component c).
pub const N_DOF: usize = 3 * N_NODES;

/// Natural coordinates of the 20 nodes, in the order documented at the module level.
pub const NODE_XI: [[f64; 3]; N_NODES] = [
    [-1.0, -1.0, -1.0],
    [1.0, -1.0, -1.0],
    [1.0, 1.0, -1.0],
    [-1.0, 1.0, -1.0],
    [-1.0, -1.0, 1.0],
    [1.0, -1.0, 1.0],
    [1.0, 1.0, 1.0],
    [-1.0, 1.0, 1.0],
    [0.0, -1.0, -1.0],
    [1.0, 0.0, -1.0],
    [0.0, 1.0, -1.0],
    [-1.0, 0.0, -1.0],
    [0.0, -1.0, 1.0],
    [1.0, 0.0, 1.0],
    [0.0, 1.0, 1.0],
    [-1.0, 0.0, 1.0],
    [-1.0, -1.0, 0.0],
    [1.0, -1.0, 0.0],
    [1.0, 1.0, 0.0],
    [-1.0, 1.0, 0.0],
];

/// Gauss-Legendre integration rule over the reference cube.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Integration {
    /// 3 x 3 x 3 points: exact for the stiffness of a parallelepiped element (default; the
    /// reference values of method.md were computed with it).
    #[default]
    Full,
    /// 2 x 2 x 2 points, ANSYS SOLID186's default ("reduced integration"). A single free
    /// element then has 6 spurious zero-energy modes besides the 6 rigid-body modes
    /// (tests/fe_element.rs); they do not propagate in a connected mesh of several elements.
    Reduced,
}

impl Integration {
    /// Number of Gauss points per direction.
    pub fn points_per_direction(self) -> usize {
        match self {
            Integration::Full => 3,
            Integration::Reduced => 2,
        }
    }

    /// The tensor-product rule: (natural coordinates, weight) per point; weights sum to 8.
    pub fn rule(self) -> Vec<([f64; 3], f64)> {
        let (pts, wts): (&[f64], &[f64]) = match self {
            Integration::Full => {
                const A: f64 = 0.774_596_669_241_483_4; // sqrt(3/5)
                (&[-A, 0.0, A], &[5.0 / 9.0, 8.0 / 9.0, 5.0 / 9.0])
            }
            Integration::Reduced => {
                const A: f64 = 0.577_350_269_189_625_8; // 1/sqrt(3)
                (&[-A, A], &[1.0, 1.0])
            }
        };
        let mut out = Vec::with_capacity(pts.len().pow(3));
        for (k, &z) in pts.iter().enumerate() {
            for (j, &y) in pts.iter().enumerate() {
                for (i, &x) in pts.iter().enumerate() {
                    out.push(([x, y, z], wts[i] * wts[j] * wts[k]));
                }
            }
        }
        out
    }
}

/// Shape function values N_i(xi) into `n`.
pub fn shape_values(xi: [f64; 3], n: &mut [f64; N_NODES]) {
    let [x, y, z] = xi;
    for (a, node) in NODE_XI.iter().enumerate() {
        let [xa, ya, za] = *node;
        n[a] = if a < 8 {
            0.125
                * (1.0 + x * xa)
                * (1.0 + y * ya)
                * (1.0 + z * za)
                * (x * xa + y * ya + z * za - 2.0)
        } else if xa == 0.0 {
            0.25 * (1.0 - x * x) * (1.0 + y * ya) * (1.0 + z * za)
        } else if ya == 0.0 {
            0.25 * (1.0 + x * xa) * (1.0 - y * y) * (1.0 + z * za)
        } else {
            0.25 * (1.0 + x * xa) * (1.0 + y * ya) * (1.0 - z * z)
        };
    }
}

/// Natural derivatives dN_i/dxi_k(xi) into `dn` (row i = node, column k = xi, eta, zeta).
pub fn shape_gradients(xi: [f64; 3], dn: &mut [[f64; 3]; N_NODES]) {
    let [x, y, z] = xi;
    for (a, node) in NODE_XI.iter().enumerate() {
        let [xa, ya, za] = *node;
        if a < 8 {
            let (px, py, pz) = (1.0 + x * xa, 1.0 + y * ya, 1.0 + z * za);
            let s = x * xa + y * ya + z * za - 2.0;
            // d/dx [px py pz s] = xa py pz s + px py pz xa = xa py pz (s + px)
            dn[a] = [
                0.125 * xa * py * pz * (s + px),
                0.125 * ya * px * pz * (s + py),
                0.125 * za * px * py * (s + pz),
            ];
        } else if xa == 0.0 {
            let (py, pz) = (1.0 + y * ya, 1.0 + z * za);
            let q = 1.0 - x * x;
            dn[a] = [-0.5 * x * py * pz, 0.25 * q * ya * pz, 0.25 * q * py * za];
        } else if ya == 0.0 {
            let (px, pz) = (1.0 + x * xa, 1.0 + z * za);
            let q = 1.0 - y * y;
            dn[a] = [0.25 * xa * q * pz, -0.5 * y * px * pz, 0.25 * px * q * za];
        } else {
            let (px, py) = (1.0 + x * xa, 1.0 + y * ya);
            let q = 1.0 - z * z;
            dn[a] = [0.25 * xa * py * q, 0.25 * px * ya * q, -0.5 * z * px * py];
        }
    }
}

/// The six faces of the reference cube: (axis, side) with side = -1 or +1, and the 8 nodes
/// lying on it (corners first, then mid-edge nodes). On a face, the shape functions of the 12
/// other nodes vanish identically.
pub fn face_nodes(axis: usize, side: f64) -> [usize; 8] {
    let mut out = [0usize; 8];
    let mut k = 0;
    for (a, node) in NODE_XI.iter().enumerate() {
        if node[axis] == side && k < 8 {
            out[k] = a;
            k += 1;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gradients_match_finite_differences() {
        let xi = [0.31, -0.42, 0.17];
        let mut dn = [[0.0; 3]; N_NODES];
        shape_gradients(xi, &mut dn);
        let h = 1e-6;
        for k in 0..3 {
            let (mut p, mut m) = (xi, xi);
            p[k] += h;
            m[k] -= h;
            let (mut np, mut nm) = ([0.0; N_NODES], [0.0; N_NODES]);
            shape_values(p, &mut np);
            shape_values(m, &mut nm);
            for a in 0..N_NODES {
                let fd = (np[a] - nm[a]) / (2.0 * h);
                assert!((fd - dn[a][k]).abs() < 1e-8, "node {a} dir {k}");
            }
        }
    }

    #[test]
    fn rule_weights_sum_to_volume() {
        for r in [Integration::Full, Integration::Reduced] {
            let s: f64 = r.rule().iter().map(|p| p.1).sum();
            assert!((s - 8.0).abs() < 1e-14);
        }
    }
}
