//! Full-model FRF engine against a dense oracle, finite differences and across thread counts.
//!
//! Models: the synthetic mass-spring lattice of `rfmlab::fe::synthetic` (a free adherend
//! held by "adhesive" springs scaled by E), seeded.

use crate::numerics::sweep_difference;
use faer::linalg::solvers::Solve;
use faer::Mat;
use rfmlab::common::{C64, J};
use rfmlab::fe::model::StructuralModel;
use rfmlab::fe::synthetic::{add_damping, lattice_model, to_dense_c64, LatticeParams};
use rfmlab::frf::full::{receptance_column, FullModel, FullParams};
use rfmlab::frf::{FrfEngine, FrfError};

const E0: C64 = C64::new(7.0e6, 1.4e6);

fn small_model(damped: bool) -> StructuralModel {
    let mut m = lattice_model(&LatticeParams::new(8, 3, 2, 11)).model;
    // a point on a bonded DOF (node (0,0,0), y), where S X is not zero
    let mut p = m.points[0].clone();
    p.id = 6;
    p.dofs = vec![(1, 1.0), (4, 0.3)];
    m.points.push(p);
    if damped {
        // Rayleigh (alpha M + beta K_b) and structural (g K_b) adherend damping
        add_damping(&mut m, 5.0, 2e-6, 0.01);
    }
    m
}

/// Dense complex Z(w).
fn dense_z(model: &StructuralModel, w: f64, e: C64) -> Mat<C64> {
    let n = model.n_dof();
    let m = to_dense_c64(&model.m);
    let k = to_dense_c64(&model.k_b);
    let s = to_dense_c64(&model.s);
    let c = model.c_b.as_ref().map(to_dense_c64);
    let d = model.d_b.as_ref().map(to_dense_c64);
    Mat::from_fn(n, n, |r, q| {
        let mut z = k[(r, q)] - m[(r, q)] * (w * w) + e * s[(r, q)];
        if let Some(c) = &c {
            z += J * w * c[(r, q)];
        }
        if let Some(d) = &d {
            z += J * d[(r, q)];
        }
        z
    })
}

fn obs_matrix(model: &StructuralModel) -> Mat<C64> {
    let mut b = Mat::<C64>::zeros(model.n_dof(), model.points.len());
    for (i, p) in model.points.iter().enumerate() {
        for &(d, w) in &p.dofs {
            b[(d, i)] += C64::new(w, 0.0);
        }
    }
    b
}

/// Dense oracle: (H at points, X = Z^-1 B).
fn dense_h(model: &StructuralModel, w: f64, e: C64) -> (Mat<C64>, Mat<C64>) {
    let z = dense_z(model, w, e);
    let b = obs_matrix(model);
    let x = z.partial_piv_lu().solve(&b);
    let h = b.transpose() * &x;
    (h, x)
}

fn rel(a: C64, b: C64) -> f64 {
    (a - b).norm() / b.norm().max(1e-300)
}

fn lines() -> (Vec<f64>, Vec<C64>) {
    // 30 lines from 10 Hz to 2 kHz (through several resonances), modulus varying with w
    let w: Vec<f64> = (0..30)
        .map(|l| 2.0 * std::f64::consts::PI * (10.0 + 2000.0 * l as f64 / 29.0))
        .collect();
    let e = w
        .iter()
        .map(|&w| E0 + C64::new(1e3 * w, 50.0 * w))
        .collect();
    (w, e)
}

fn check_against_dense(model: &StructuralModel) {
    let inputs = [1usize, 4, 5];
    let fm = FullModel::new(model, &inputs, FullParams::default()).unwrap();
    let (w, e) = lines();
    let sw = fm.sweep(&w, &e, true).unwrap();
    assert_eq!((sw.n_lines, sw.n_out, sw.n_in), (30, 6, 3));
    let s = to_dense_c64(&model.s);
    let b = obs_matrix(model);
    let mut worst_h = 0.0f64;
    let mut worst_d = 0.0f64;
    let mut worst_sh = 0.0f64;
    for l in 0..w.len() {
        let (h, x) = dense_h(model, w[l], e[l]);
        let dh = -(x.transpose() * &s * &x); // -X^T S X
        let sh = b.transpose() * &s * &x;
        for i in 0..6 {
            for (jj, &j) in inputs.iter().enumerate() {
                let k = sw.idx(l, i, jj);
                worst_h = worst_h.max(rel(sw.h[k], h[(i, j)]));
                worst_d = worst_d.max(rel(sw.dh_de[k], dh[(i, j)]));
                worst_sh = worst_sh.max(rel(sw.sh[k], sh[(i, j)]));
            }
        }
    }
    eprintln!("max rel err vs dense: h {worst_h:.2e}, dh/dE' {worst_d:.2e}, sh {worst_sh:.2e}");
    assert!(worst_h < 1e-10, "H vs dense: {worst_h:e}");
    assert!(worst_d < 1e-10, "dH/dE' vs dense: {worst_d:e}");
    assert!(worst_sh < 1e-10, "SH vs dense: {worst_sh:e}");
}

#[test]
fn frf_matches_dense_solve_undamped_adherend() {
    check_against_dense(&small_model(false));
}

#[test]
fn frf_matches_dense_solve_with_rayleigh_and_structural_damping() {
    check_against_dense(&small_model(true));
}

/// H is symmetric (reciprocity): h_ij = h_ji.
#[test]
fn reciprocity() {
    let model = small_model(true);
    let fm = FullModel::new(&model, &[0, 1, 2, 3, 4, 5], FullParams::default()).unwrap();
    let (w, e) = lines();
    let sw = fm.sweep(&w, &e, false).unwrap();
    assert!(sw.dh_de.is_empty() && sw.sh.is_empty());
    for l in 0..w.len() {
        for i in 0..6 {
            for j in 0..6 {
                let (a, b) = (sw.h[sw.idx(l, i, j)], sw.h[sw.idx(l, j, i)]);
                assert!(rel(a, b) < 1e-10, "h{i}{j} != h{j}{i} at line {l}");
            }
        }
    }
}

/// dH/dE' against central differences in E', and dH/dE'' = j dH/dE' against central
/// differences in E'' (Richardson-extrapolated, relative step 1e-4, tolerance 1e-6 relative;
/// see the notes below).
#[test]
fn sensitivities_match_central_differences() {
    for damped in [false, true] {
        let model = small_model(damped);
        let fm = FullModel::new(&model, &[1, 5], FullParams::default()).unwrap();
        let (w, e) = lines();
        let base = fm.sweep(&w, &e, true).unwrap();
        let mut worst_re = 0.0f64;
        let mut worst_im = 0.0f64;
        // Central differences with Richardson extrapolation, D = (4 D(h) - D(2h)) / 3
        // (truncation O(h^4) ~ (h / E'')^4 ~ 1e-13), relative step h = 1e-4. Near resonances H is
        // accurate to ~1e-13 relative (cf. the dense comparison), so
        // the difference quotient carries ~1e-13 / h / (|E' dH/dE'| / |H|) relative noise;
        // entries whose relative sensitivity is below 1e-3 (the adhesive barely affects them)
        // are therefore compared on the scale 1e-3 |H| / E' instead of |dH/dE'|.
        let step = 1e-4 * E0.re;
        for (dir, worst) in [(C64::new(1.0, 0.0), &mut worst_re), (J, &mut worst_im)] {
            let d = |h: f64| -> Vec<C64> {
                sweep_difference(&fm, &w, &e, dir * h)
                    .into_iter()
                    .map(|d| d / (2.0 * h))
                    .collect()
            };
            let (d1, d2) = (d(step), d(2.0 * step));
            for k in 0..base.h.len() {
                let fd = (d1[k] * 4.0 - d2[k]) / 3.0;
                // dH/dE'' = j dH/dE'
                let an = dir * base.dh_de[k];
                let scale = an.norm().max(1e-3 * base.h[k].norm() / E0.re);
                *worst = worst.max((an - fd).norm() / scale);
            }
        }
        eprintln!("damped={damped}: FD rel err dE' {worst_re:.2e}, dE'' {worst_im:.2e}");
        assert!(worst_re < 1e-6, "dH/dE' vs FD: {worst_re:e}");
        assert!(worst_im < 1e-6, "dH/dE'' vs FD: {worst_im:e}");
    }
}

/// The same sweep in 1-thread and 2-thread pools, and sequentially, is bit-identical.
#[test]
fn thread_count_determinism() {
    let model = lattice_model(&LatticeParams::new(20, 4, 3, 5)).model;
    let fm = FullModel::new(&model, &[1, 3], FullParams::default()).unwrap();
    let (w, e) = lines();
    let run = |t: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(t)
            .build()
            .unwrap()
            .install(|| fm.sweep(&w, &e, true).unwrap())
    };
    let a = run(1);
    let b = run(2);
    let seq = FullModel::new(
        &model,
        &[1, 3],
        FullParams {
            parallel: false,
            ..FullParams::default()
        },
    )
    .unwrap()
    .sweep(&w, &e, true)
    .unwrap();
    for (x, y) in [(&a, &b), (&a, &seq)] {
        for (p, q) in
            x.h.iter()
                .chain(&x.dh_de)
                .chain(&x.sh)
                .zip(y.h.iter().chain(&y.dh_de).chain(&y.sh))
        {
            assert_eq!(p.re.to_bits(), q.re.to_bits());
            assert_eq!(p.im.to_bits(), q.im.to_bits());
        }
    }
}

/// Whole receptance column equals the dense one, and reading it at the points gives H.
#[test]
fn receptance_column_matches_dense() {
    let model = small_model(true);
    let (w, e) = (2.0 * std::f64::consts::PI * 300.0, E0);
    let col = receptance_column(&model, w, e, 1).unwrap();
    let (_, x) = dense_h(&model, w, e);
    let scale = x.col(1).iter().map(|v| v.norm()).fold(0.0, f64::max);
    for (r, v) in col.iter().enumerate() {
        assert!((v - x[(r, 1)]).norm() < 1e-10 * scale);
    }
}

/// A free-free structure (no adhesive, no damping) at w = 0 is singular: typed error, no panic.
#[test]
fn singular_dynamic_stiffness_is_an_error() {
    let model = small_model(false);
    let fm = FullModel::new(&model, &[0], FullParams::default()).unwrap();
    let r = fm.sweep(&[0.0, 10.0], &[C64::new(0.0, 0.0), E0], false);
    match r {
        Err(FrfError::Singular { freq_hz, .. }) => assert_eq!(freq_hz, 0.0),
        other => panic!("expected Singular, got {other:?}"),
    }
}

#[test]
fn bad_inputs_are_errors() {
    let model = small_model(false);
    assert!(matches!(
        FullModel::new(&model, &[7], FullParams::default()),
        Err(FrfError::BadInput(7))
    ));
    let fm = FullModel::new(&model, &[0], FullParams::default()).unwrap();
    assert!(matches!(
        fm.sweep(&[1.0, 2.0], &[E0], false),
        Err(FrfError::Length { .. })
    ));
    let mut bad = model.clone();
    bad.points[0].dofs.push((10_000, 1.0));
    assert!(matches!(
        FullModel::new(&bad, &[0], FullParams::default()),
        Err(FrfError::Other(_))
    ));
}
