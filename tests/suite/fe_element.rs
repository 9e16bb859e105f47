//! Element battery for the 20-node serendipity hexahedron (fenris style): partition of unity,
//! nodal interpolation, patch test, zero-energy modes, mass sums, stiffness symmetry/PSD.

use crate::numerics::spmv;
use faer::{Mat, Side};
use rfmlab::fe::assembly::{Assembler, DofMap};
use rfmlab::fe::element::{shape_gradients, shape_values, Integration, NODE_XI, N_DOF, N_NODES};
use rfmlab::fe::geometry::{
    box_element, element_mass, element_stiffness, element_volume, rule_table, strain_at,
    Elasticity, ElementCoords,
};
use rfmlab::fe::mesh::{box_mesh, ClampedFace};

/// Small deterministic generator (xorshift64*), uniform in [-1, 1).
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        let v = self.0.wrapping_mul(0x2545_F491_4F6C_DD1D);
        (v >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    }
}

const MAT: Elasticity = Elasticity { e_pa: 1.0, nu: 0.3 };

/// A distorted element: a box with every node moved by up to `amp`.
fn distorted(rng: &mut Rng, amp: f64) -> ElementCoords {
    let mut c = box_element([0.0, 0.0, 0.0], [1.0, 0.8, 1.2]);
    for x in c.iter_mut() {
        for v in x.iter_mut() {
            *v += amp * rng.next();
        }
    }
    c
}

#[test]
fn partition_of_unity_and_nodal_interpolation() {
    let mut rng = Rng(0x1234_5678);
    for _ in 0..200 {
        let xi = [rng.next(), rng.next(), rng.next()];
        let mut n = [0.0; N_NODES];
        let mut dn = [[0.0; 3]; N_NODES];
        shape_values(xi, &mut n);
        shape_gradients(xi, &mut dn);
        assert!((n.iter().sum::<f64>() - 1.0).abs() < 1e-14);
        for k in 0..3 {
            assert!(dn.iter().map(|d| d[k]).sum::<f64>().abs() < 1e-14);
        }
        // linear completeness: sum N_a xi_a = xi
        for k in 0..3 {
            let s: f64 = n.iter().zip(NODE_XI.iter()).map(|(a, x)| a * x[k]).sum();
            assert!((s - xi[k]).abs() < 1e-14);
        }
    }
    for (j, xj) in NODE_XI.iter().enumerate() {
        let mut n = [0.0; N_NODES];
        shape_values(*xj, &mut n);
        for (i, &v) in n.iter().enumerate() {
            let d = if i == j { 1.0 } else { 0.0 };
            assert!((v - d).abs() < 1e-15, "N_{i}(x_{j}) = {v}");
        }
    }
}

/// u(x) = A x + c, constant strain sym(A).
fn linear_field(rng: &mut Rng) -> ([[f64; 3]; 3], [f64; 3]) {
    let mut a = [[0.0; 3]; 3];
    for r in a.iter_mut() {
        for v in r.iter_mut() {
            *v = rng.next();
        }
    }
    (a, [rng.next(), rng.next(), rng.next()])
}

fn eval(a: &[[f64; 3]; 3], c: &[f64; 3], x: &[f64; 3]) -> [f64; 3] {
    let mut u = *c;
    for i in 0..3 {
        for j in 0..3 {
            u[i] += a[i][j] * x[j];
        }
    }
    u
}

fn voigt(a: &[[f64; 3]; 3]) -> [f64; 6] {
    [
        a[0][0],
        a[1][1],
        a[2][2],
        a[0][1] + a[1][0],
        a[1][2] + a[2][1],
        a[2][0] + a[0][2],
    ]
}

#[test]
fn patch_test_single_distorted_element_constant_strain() {
    let mut rng = Rng(42);
    for _ in 0..10 {
        let c = distorted(&mut rng, 0.15);
        let (a, t) = linear_field(&mut rng);
        let mut u = [0.0; N_DOF];
        for (n, x) in c.iter().enumerate() {
            let v = eval(&a, &t, x);
            u[3 * n..3 * n + 3].copy_from_slice(&v);
        }
        let want = voigt(&a);
        for _ in 0..20 {
            let xi = [rng.next(), rng.next(), rng.next()];
            let eps = strain_at(&c, &u, xi).unwrap();
            for k in 0..6 {
                assert!(
                    (eps[k] - want[k]).abs() < 1e-12,
                    "strain {k}: {} vs {}",
                    eps[k],
                    want[k]
                );
            }
        }
    }
}

/// 2 x 2 x 2 patch of distorted elements: K u at interior nodes for a linear field u,
/// returned as (largest interior force, largest force).
fn patch_residual(rule: Integration, seed: u64, amp: f64) -> (f64, f64) {
    let mut rng = Rng(seed);
    let mut mesh = box_mesh([2.0, 2.0, 2.0], [2, 2, 2], ClampedFace::None);
    let interior: Vec<usize> = (0..mesh.n_nodes())
        .filter(|&n| mesh.nodes[n].iter().all(|&v| v > 1e-9 && v < 2.0 - 1e-9))
        .collect();
    assert_eq!(
        interior.len(),
        7,
        "centre node + 6 mid-edge nodes on interior edges"
    );
    for x in mesh.nodes.iter_mut() {
        for v in x.iter_mut() {
            *v += amp * rng.next();
        }
    }
    let dofs = DofMap::unconstrained(mesh.n_nodes());
    let asm = Assembler::new(&mesh, &dofs);
    let all: Vec<usize> = (0..mesh.n_elements()).collect();
    let k = asm.stiffness(&asm.pattern(&all), |_| MAT, rule).unwrap();
    let (a, t) = linear_field(&mut rng);
    let mut u = vec![0.0; dofs.n_free];
    for (n, x) in mesh.nodes.iter().enumerate() {
        let v = eval(&a, &t, x);
        u[3 * n..3 * n + 3].copy_from_slice(&v);
    }
    let f = spmv(&k, &u);
    let scale = f.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let worst = interior
        .iter()
        .flat_map(|&n| (0..3).map(move |c| 3 * n + c))
        .fold(0.0f64, |m, d| m.max(f[d].abs()));
    (worst, scale)
}

#[test]
fn patch_test_distorted_patch_zero_interior_force() {
    for seed in [1, 2, 3] {
        let (worst, scale) = patch_residual(Integration::Full, seed, 0.12);
        assert!(
            worst <= 1e-12 * scale,
            "full: interior force {worst:e} vs scale {scale:e}"
        );
    }
}

#[test]
fn patch_test_reduced_integration() {
    // Undistorted (parallelepiped) patch: the reduced rule integrates exactly, patch test holds.
    let (worst, scale) = patch_residual(Integration::Reduced, 5, 0.0);
    assert!(
        worst <= 1e-12 * scale,
        "reduced, regular patch: {worst:e} vs {scale:e}"
    );
    // Distorted patch: what is true is that the 2 x 2 x 2 rule does not integrate
    // det J-weighted gradients of a curved/distorted element exactly, so the patch test fails
    // (interior force about 1.6e-2 of the largest force at 12 % node jitter). Full
    // integration passes (previous test): prefer it for distorted meshes.
    let mut worst_rel: f64 = 0.0;
    for seed in [1, 2, 3] {
        let (worst, scale) = patch_residual(Integration::Reduced, seed, 0.12);
        worst_rel = worst_rel.max(worst / scale);
    }
    println!(
        "reduced integration, distorted patch: max interior force / max force = {worst_rel:e}"
    );
    assert!(
        worst_rel > 1e-6,
        "reduced integration unexpectedly passes the distorted patch test"
    );
}

fn dense(ke: &[f64]) -> Mat<f64> {
    Mat::from_fn(N_DOF, N_DOF, |i, j| ke[i * N_DOF + j])
}

fn zero_modes(rule: Integration, seed: u64, amp: f64) -> (usize, f64, f64) {
    let mut rng = Rng(seed);
    let c = distorted(&mut rng, amp);
    let ke = element_stiffness(&c, MAT, rule).unwrap();
    let ev = dense(&ke).self_adjoint_eigenvalues(Side::Lower).unwrap();
    let max = ev[N_DOF - 1];
    let n0 = ev.iter().filter(|&&v| v.abs() < 1e-10 * max).count();
    (n0, ev[0] / max, ev[n0] / max)
}

#[test]
fn zero_energy_modes_of_a_free_element() {
    for seed in [7, 8, 9] {
        let (n0, min_rel, first_nonzero) = zero_modes(Integration::Full, seed, 0.1);
        assert_eq!(n0, 6, "full integration: exactly the 6 rigid-body modes");
        assert!(
            min_rel > -1e-12,
            "K_e is PSD: smallest eigenvalue / largest = {min_rel:e}"
        );
        assert!(first_nonzero > 1e-4, "no near-mechanism: {first_nonzero:e}");
    }
    // reduced 2x2x2: 8 points x 6 strains = 48 constraints on 54 deformation modes, so at
    // least 6 spurious zero-energy modes on a single element
    for seed in [7, 8, 9] {
        let (n0, min_rel, _) = zero_modes(Integration::Reduced, seed, 0.1);
        println!("reduced, distorted element: {n0} zero eigenvalues");
        assert_eq!(n0, 12, "reduced integration: 6 rigid + 6 spurious modes");
        assert!(min_rel > -1e-12);
    }
    let (n0, _, _) = zero_modes(Integration::Reduced, 9, 0.0);
    assert_eq!(n0, 12, "undistorted element, reduced integration");
}

#[test]
fn spurious_modes_of_reduced_integration_in_a_patch() {
    let mesh = box_mesh([2.0, 2.0, 2.0], [2, 2, 2], ClampedFace::None);
    let dofs = DofMap::unconstrained(mesh.n_nodes());
    let asm = Assembler::new(&mesh, &dofs);
    let all: Vec<usize> = (0..mesh.n_elements()).collect();
    let mut counts = Vec::new();
    for rule in [Integration::Full, Integration::Reduced] {
        let k = asm.stiffness(&asm.pattern(&all), |_| MAT, rule).unwrap();
        let n = dofs.n_free;
        let mut d = Mat::<f64>::zeros(n, n);
        let (sym, val) = k.parts();
        for j in 0..n {
            for p in sym.col_ptr()[j]..sym.col_ptr()[j + 1] {
                d[(sym.row_idx()[p], j)] = val[p];
            }
        }
        let ev = d.self_adjoint_eigenvalues(Side::Lower).unwrap();
        let max = ev[n - 1];
        counts.push(ev.iter().filter(|&&v| v.abs() < 1e-10 * max).count());
    }
    println!(
        "zero-energy modes of a free 2x2x2 patch: full {}, reduced {}",
        counts[0], counts[1]
    );
    assert_eq!(counts[0], 6);
    assert_eq!(
        counts[1], 6,
        "reduced integration: spurious modes do not survive in a 2x2x2 patch"
    );
}

#[test]
fn mass_sums_to_rho_v_and_stiffness_is_symmetric() {
    let mut rng = Rng(99);
    let rho = 7800.0;
    for _ in 0..5 {
        let c = distorted(&mut rng, 0.1);
        let v = element_volume(&c).unwrap();
        let me = element_mass(&c, rho).unwrap();
        for i in 0..3 {
            let mut s = 0.0;
            for a in 0..N_NODES {
                for b in 0..N_NODES {
                    s += me[(3 * a + i) * N_DOF + 3 * b + i];
                }
            }
            assert!(
                (s - rho * v).abs() < 1e-12 * rho * v,
                "direction {i}: {s} vs {}",
                rho * v
            );
        }
        for rule in [Integration::Full, Integration::Reduced] {
            let ke = element_stiffness(&c, MAT, rule).unwrap();
            let max = ke.iter().fold(0.0f64, |m, x| m.max(x.abs()));
            for i in 0..N_DOF {
                for j in 0..N_DOF {
                    assert!((ke[i * N_DOF + j] - ke[j * N_DOF + i]).abs() <= 1e-14 * max);
                }
            }
        }
    }
    // a box element's volume is exact
    let c = box_element([0.0; 3], [0.3, 0.01, 0.02]);
    assert!((element_volume(&c).unwrap() - 6e-5).abs() < 1e-18);
    assert_eq!(rule_table(Integration::Full).weights.len(), 27);
}

#[test]
fn inverted_element_is_an_error_not_a_panic() {
    let mut c = box_element([0.0; 3], [1.0, 1.0, 1.0]);
    for x in c.iter_mut() {
        x[0] = -x[0];
    }
    assert!(element_stiffness(&c, MAT, Integration::Full).is_err());
    assert!(element_mass(&c, 1.0).is_err());
}
