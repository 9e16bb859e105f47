//! Real and complex modes against dense oracles, and eigenvalue sensitivities against
//! central finite differences. Models: seeded synthetic lattices (rfmlab::fe::synthetic).

use faer::linalg::solvers::DenseSolveCore;
use faer::{Mat, Side};
use rfmlab::common::{C64, J};
use rfmlab::fe::model::{SpMat, StructuralModel};
use rfmlab::fe::synthetic::{add_damping, lattice_model, to_dense, LatticeParams};
use rfmlab::modes::{complex_modes, real_modes, EigenParams, ModesParams};

const E0: C64 = C64::new(6.974e6, 1.4827e6);

fn k_of(model: &StructuralModel, e_re: f64) -> SpMat {
    let n = model.n_dof();
    let mut t = Vec::new();
    for x in model.k_b.triplet_iter() {
        t.push(faer::sparse::Triplet::new(x.row, x.col, *x.val));
    }
    for x in model.s.triplet_iter() {
        t.push(faer::sparse::Triplet::new(x.row, x.col, e_re * *x.val));
    }
    SpMat::try_new_from_triplets(n, n, &t).unwrap()
}

/// Dense oracle: L^-1 A L^-T with M = L L^T (A complex symmetric): its eigenvalues are those
/// of (A, M).
fn dense_complex_eigs(model: &StructuralModel, e: C64) -> Vec<C64> {
    let n = model.n_dof();
    let m = to_dense(&model.m);
    let l = m.llt(Side::Lower).unwrap().L().to_owned();
    let linv = l.partial_piv_lu().inverse();
    let kb = to_dense(&model.k_b);
    let s = to_dense(&model.s);
    let d = model.d_b.as_ref().map(to_dense);
    let a = Mat::<C64>::from_fn(n, n, |i, j| {
        let mut v = C64::new(kb[(i, j)], 0.0) + e * s[(i, j)];
        if let Some(d) = &d {
            v += J * d[(i, j)];
        }
        v
    });
    let linv_c = Mat::<C64>::from_fn(n, n, |i, j| C64::new(linv[(i, j)], 0.0));
    let c = &linv_c * &a * linv_c.transpose();
    let mut ev = c.eigenvalues().unwrap();
    ev.sort_by(|x, y| x.re.total_cmp(&y.re));
    ev
}

#[test]
fn real_modes_match_dense_oracle() {
    let model = lattice_model(&LatticeParams::new(20, 4, 3, 3)).model;
    let k = k_of(&model, E0.re);
    let n = 8;
    let (lam, x) = real_modes(&k, &model.m, n, &EigenParams::default()).unwrap();
    // dense: eigenvalues of L^-1 K L^-T
    let kd = to_dense(&k);
    let md = to_dense(&model.m);
    let l = md.llt(Side::Lower).unwrap().L().to_owned();
    let linv = l.partial_piv_lu().inverse();
    let c = &linv * &kd * linv.transpose();
    let c = Mat::from_fn(c.nrows(), c.ncols(), |i, j| 0.5 * (c[(i, j)] + c[(j, i)]));
    let ev = c.self_adjoint_eigenvalues(Side::Lower).unwrap();
    for i in 0..n {
        let r = (lam[i] - ev[i]).abs() / ev[i];
        assert!(
            r < 1e-10,
            "eigenvalue {i}: {} vs dense {} (rel {r:e})",
            lam[i],
            ev[i]
        );
        if i > 0 {
            assert!(lam[i] >= lam[i - 1]);
        }
    }
    // residuals and M-orthonormality
    let kx = &kd * &x;
    let mx = &md * &x;
    for c in 0..n {
        let r: f64 = (0..kd.nrows())
            .map(|i| (kx[(i, c)] - lam[c] * mx[(i, c)]).powi(2))
            .sum::<f64>()
            .sqrt();
        let kn: f64 = (0..kd.nrows())
            .map(|i| kx[(i, c)].powi(2))
            .sum::<f64>()
            .sqrt();
        assert!(r / kn < 1e-10, "residual of mode {c}: {:e}", r / kn);
    }
    let g = x.transpose() * &mx;
    for i in 0..n {
        for j in 0..n {
            let target = if i == j { 1.0 } else { 0.0 };
            assert!(
                (g[(i, j)] - target).abs() < 1e-10,
                "X^T M X [{i},{j}] = {}",
                g[(i, j)]
            );
        }
    }
}

fn check_complex(model: &StructuralModel, axes: &[u8]) {
    let n = 6;
    // This lattice is well conditioned, so the refinement can reach a 1e-10 residual (the
    // default 1e-6 allows for the rounding floor of stiff-on-soft joints).
    let params = ModesParams {
        tol: 1e-10,
        ..ModesParams::default()
    };
    let modes = complex_modes(model, E0, n, Some(axes), &params).unwrap();
    assert_eq!(modes.len(), n);
    let dense = dense_complex_eigs(model, E0);
    for (i, md) in modes.iter().enumerate() {
        let r = (md.lambda - dense[i]).norm() / dense[i].norm();
        eprintln!(
            "mode {i}: {:.3} Hz, eta {:.4}, rel err {r:.1e}, residual {:.1e}, energy {:?}",
            md.freq_hz, md.loss_factor, md.residual, md.energy_fraction_xyz
        );
        assert!(r < 1e-8, "mode {i}: {} vs dense {}", md.lambda, dense[i]);
        assert!(md.residual < 1e-10);
        assert!(
            (md.freq_hz - md.lambda.re.sqrt() / (2.0 * std::f64::consts::PI)).abs()
                < 1e-12 * md.freq_hz
        );
        assert!((md.loss_factor - md.lambda.im / md.lambda.re).abs() < 1e-14);
        // phi^T M phi = 1 (no conjugate), and at_points reads phi
        let mut mphi = vec![C64::new(0.0, 0.0); model.n_dof()];
        rfmlab::linalg::spmv_complex(&model.m, &md.phi, &mut mphi);
        let norm: C64 = md.phi.iter().zip(&mphi).map(|(a, b)| a * b).sum();
        assert!((norm - 1.0).norm() < 1e-12);
        for (p, v) in model.points.iter().zip(&md.at_points) {
            let want: C64 = p.dofs.iter().map(|&(d, w)| md.phi[d] * w).sum();
            assert!((want - v).norm() <= 1e-14 * want.norm().max(1e-300));
        }
        let e = md.energy_fraction_xyz.unwrap();
        assert!((e.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        assert_eq!(md.y_dominant, Some(e[1] > 0.5));
    }
}

#[test]
fn complex_modes_match_dense_oracle() {
    let lat = lattice_model(&LatticeParams::new(12, 3, 2, 7));
    check_complex(&lat.model, &lat.dof_axes);
}

#[test]
fn complex_modes_with_structural_adherend_damping() {
    let mut lat = lattice_model(&LatticeParams::new(12, 3, 2, 8));
    add_damping(&mut lat.model, 0.0, 0.0, 0.002);
    check_complex(&lat.model, &lat.dof_axes);
}

/// d lambda / dE' = phi^T S phi and d lambda / dE'' = j phi^T S phi, by central differences
/// (relative step 1e-6 on E'), to 1e-6 relative.
#[test]
fn eigenvalue_sensitivity_matches_finite_differences() {
    let lat = lattice_model(&LatticeParams::new(12, 3, 2, 9));
    let model = &lat.model;
    let n = 5;
    let p = ModesParams::default();
    let base = complex_modes(model, E0, n, None, &p).unwrap();
    let h = 1e-6 * E0.re;
    for (dir, label) in [(C64::new(1.0, 0.0), "E'"), (J, "E''")] {
        let plus = complex_modes(model, E0 + dir * h, n, None, &p).unwrap();
        let minus = complex_modes(model, E0 - dir * h, n, None, &p).unwrap();
        for i in 0..n {
            let fd = (plus[i].lambda - minus[i].lambda) / (2.0 * h);
            let an = dir * base[i].phi_s_phi;
            let r = (fd - an).norm() / an.norm();
            eprintln!("mode {i} d lambda/d{label}: rel err {r:.1e}");
            assert!(r < 1e-6, "mode {i} d lambda / d{label}: FD {fd} vs {an}");
        }
    }
}

#[test]
fn bad_inputs_are_errors_not_panics() {
    let lat = lattice_model(&LatticeParams::new(6, 2, 2, 1));
    let p = ModesParams::default();
    assert!(complex_modes(&lat.model, C64::new(-1.0, 0.0), 2, None, &p).is_err());
    assert!(complex_modes(&lat.model, E0, 2, Some(&[0u8; 3]), &p).is_err());
    // K_b alone (free-free lattice) is not positive definite
    assert!(real_modes(&lat.model.k_b, &lat.model.m, 2, &EigenParams::default()).is_err());
    assert!(real_modes(
        &lat.model.k_b,
        &lat.model.m,
        10_000,
        &EigenParams::default()
    )
    .is_err());
}
