//! Checks on the real bonded joint (the mesher's model of the paper's structure):
//!
//! * complex modes at the four (mode, excitation level) moduli of the paper's Table 3 (IEM
//!   column) with 5 mm elements: frequency and modal loss factor of the y-bending mode against
//!   the paper's Table 2 and against the values measured with this code;
//! * FRF sensitivities dH/dE', dH/dE'' against central finite differences (10 mm joint);
//! * FRFs against a dense direct complex solve (a coarse joint mesh of 1320 DOFs);
//! * Matrix Market round trip of the joint through SciPy (scripts/mm_roundtrip.py).
//!
//! Python for the last test: env RFMLAB_PYTHON, default `<crate root>/.venv/bin/python`
//! (`python3 -m venv .venv && .venv/bin/pip install numpy scipy`). Missing Python skips the
//! test with a notice, unless env CI is set, in which case it fails.

use crate::numerics::sweep_difference;
use crate::python_checks::{python_for_scipy, scipy_round_trip};
use faer::linalg::solvers::Solve;
use faer::Mat;
use rfmlab::common::{C64, J};
use rfmlab::fe::joint::{build_joint_model, Divisions, JointSpec, MeshSize};
use rfmlab::fe::model::StructuralModel;
use rfmlab::fe::synthetic::to_dense_c64;
use rfmlab::frf::full::{FullModel, FullParams};
use rfmlab::frf::FrfEngine;
use rfmlab::modes::{complex_modes, ModesParams};
use std::f64::consts::PI;

/// Excitation point: id 2 (x = 150 mm), index 1 in `JointSpec::paper().points`.
const INPUT: usize = 1;

fn joint(size: MeshSize) -> StructuralModel {
    let mut s = JointSpec::paper();
    s.mesh.size = size;
    build_joint_model(&s).expect("paper joint builds").0
}

/// Axis of each free DOF (the mesher numbers free DOFs node-major, x, y, z per node).
fn dof_axes(model: &StructuralModel) -> Vec<u8> {
    (0..model.n_dof()).map(|k| (k % 3) as u8).collect()
}

/// One row of the acceptance table: the modulus of the paper's Table 3 (IEM), the paper's
/// Table 2 frequency and loss factor, and this code's values at 5 mm elements (measured with
/// `rfmlab modes studies/paper_geometry.toml --modulus E',E''`).
struct Case {
    label: &'static str,
    /// 0 = first y-bending mode, 1 = second.
    y_mode: usize,
    modulus: C64,
    paper_hz: f64,
    paper_loss: f64,
    ours_hz: f64,
    ours_loss: f64,
    /// Tolerances on the frequency (Hz) and loss factor around `ours_*`.
    tol_hz: f64,
    tol_loss: f64,
}

const CASES: [Case; 4] = [
    Case {
        label: "Level 1, mode 1",
        y_mode: 0,
        modulus: C64::new(6.974e6, 1.4827e6),
        paper_hz: 22.26,
        paper_loss: 0.2044,
        ours_hz: 22.14,
        ours_loss: 0.2044,
        // required: 22.1 +/- 0.3 Hz, 0.204 +/- 0.004
        tol_hz: 0.3,
        tol_loss: 0.004,
    },
    Case {
        label: "Level 1, mode 2",
        y_mode: 1,
        modulus: C64::new(9.6404e6, 1.6085e6),
        paper_hz: 394.45,
        paper_loss: 0.0720,
        ours_hz: 393.79,
        ours_loss: 0.0725,
        tol_hz: 2.0,
        tol_loss: 0.002,
    },
    Case {
        label: "Level 2, mode 1",
        y_mode: 0,
        modulus: C64::new(5.1831e6, 1.1757e6),
        paper_hz: 19.28,
        paper_loss: 0.2202,
        ours_hz: 19.18,
        ours_loss: 0.2203,
        tol_hz: 0.3,
        tol_loss: 0.004,
    },
    Case {
        label: "Level 2, mode 2",
        y_mode: 1,
        modulus: C64::new(8.7146e6, 2.1234e6),
        paper_hz: 387.33,
        paper_loss: 0.1121,
        ours_hz: 386.62,
        ours_loss: 0.1127,
        tol_hz: 2.0,
        tol_loss: 0.002,
    },
];

/// First two y-dominant modes at the four Table 3 moduli, 5 mm elements. Checks: each value
/// within the stated tolerance of this code's reference value, and within 1 % (frequency) and
/// 0.004 (loss factor) of the paper's Table 2 (the paper's own IEM fixed point).
#[test]
fn table3_moduli_give_the_paper_modes_at_5mm() {
    let model = joint(MeshSize::ElementSize(0.005));
    let axes = dof_axes(&model);
    let params = ModesParams::default();
    for c in &CASES {
        let modes = complex_modes(&model, c.modulus, 8, Some(&axes), &params).unwrap();
        let y: Vec<_> = modes
            .iter()
            .filter(|m| m.y_dominant == Some(true))
            .collect();
        assert!(
            y.len() > c.y_mode,
            "{}: only {} y-dominant modes among {:?}",
            c.label,
            y.len(),
            modes.iter().map(|m| m.freq_hz).collect::<Vec<_>>()
        );
        let m = y[c.y_mode];
        eprintln!(
            "{}: E* = {:.4} + {:.4} j MPa -> {:.3} Hz, loss {:.4} (paper {:.2} Hz, {:.4}); residual {:.1e}",
            c.label,
            c.modulus.re / 1e6,
            c.modulus.im / 1e6,
            m.freq_hz,
            m.loss_factor,
            c.paper_hz,
            c.paper_loss,
            m.residual
        );
        assert!(
            (m.freq_hz - c.ours_hz).abs() <= c.tol_hz,
            "{}: {} Hz, expected {} +/- {}",
            c.label,
            m.freq_hz,
            c.ours_hz,
            c.tol_hz
        );
        assert!(
            (m.loss_factor - c.ours_loss).abs() <= c.tol_loss,
            "{}: loss {}, expected {} +/- {}",
            c.label,
            m.loss_factor,
            c.ours_loss,
            c.tol_loss
        );
        assert!(
            (m.freq_hz / c.paper_hz - 1.0).abs() < 0.01,
            "{}: {} Hz vs paper {}",
            c.label,
            m.freq_hz,
            c.paper_hz
        );
        assert!(
            (m.loss_factor - c.paper_loss).abs() < 0.004,
            "{}: loss {} vs paper {}",
            c.label,
            m.loss_factor,
            c.paper_loss
        );
        // the mode is seen by the sensors
        assert!(m.at_points.iter().any(|v| v.norm() > 0.0));
    }
}

fn lines_hz() -> Vec<f64> {
    // below, at and between the y-modes of the 10 mm joint, and at the band end
    vec![5.0, 18.0, 22.0, 26.0, 100.0, 250.0, 390.0, 400.0, 500.0]
}

/// dH/dE' (and dH/dE'' = j dH/dE') against central finite differences on the 10 mm joint.
///
/// Why not a plain central difference with a small step: on this stiff-on-soft structure each
/// solve carries ~1e-8 relative rounding error at and below the first mode (eps cond(Z), see
/// the dense test), uncorrelated between E* +/- h, so a step of 1e-3 |E*| leaves ~5e-6 noise
/// (measured 3.4e-6 with Richardson), while a step of 1e-2 leaves O(h^4) truncation of 7e-6 at
/// the resonance (measured). So the step is large, r = 0.05 |E*|, and the truncation is removed
/// by averaging central differences along N/2 = 8 directions e^{j theta_k} of the complex E*
/// plane, theta_k = 2 pi k / N (k = 0 is the E' direction, k = 4 the E'' direction):
///
/// D = (1/(N/2)) sum_k [H(E* + r e^{j theta_k}) - H(E* - r e^{j theta_k})] / (2 r e^{j theta_k}).
///
/// H is holomorphic in E* (Z is affine in E*), and D is the N-point trapezoidal rule of
/// Cauchy's integral for H'(E*): its truncation error is O((r/R)^N) with R the distance to the
/// nearest pole in the E* plane (>= |E''| ~ 0.2 |E*| on these lines): (0.25)^16 ~ 2e-10.
/// Rounding: ~1e-8 / 0.05 / sqrt(8) ~ 1e-7. Tolerance 1e-6 relative (entries whose relative
/// sensitivity |E* dH/dE'| / |H| is below 1e-3 are compared on the scale 1e-3 |H| / |E*|).
/// The E'' check (dH/dE'' = j dH/dE') uses the directional central difference along E''
/// alone, Richardson-extrapolated at h = 1e-3 |E*|, to the looser 2e-5 its rounding allows.
#[test]
fn sensitivities_match_central_differences_on_10mm_joint() {
    let model = joint(MeshSize::ElementSize(0.01));
    let inputs = [INPUT];
    let fm = FullModel::new(&model, &inputs, FullParams::default()).unwrap();
    let w: Vec<f64> = lines_hz().iter().map(|f| 2.0 * PI * f).collect();
    let e0 = C64::new(6.974e6, 1.4827e6);
    let e: Vec<C64> = w.iter().map(|&w| e0 + C64::new(2e3 * w, 3e2 * w)).collect();
    let base = fm.sweep(&w, &e, true).unwrap();
    // central difference along direction `dir` with step h (per line E*)
    let cd = |dir: C64, h: f64| -> Vec<C64> {
        sweep_difference(&fm, &w, &e, dir * h)
            .into_iter()
            .map(|d| d / (dir * (2.0 * h)))
            .collect()
    };
    let n_dir = 8;
    let r = 0.05 * e0.norm();
    let mut avg = vec![C64::new(0.0, 0.0); base.h.len()];
    for k in 0..n_dir {
        let dir = C64::from_polar(1.0, PI * k as f64 / n_dir as f64);
        for (a, d) in avg.iter_mut().zip(cd(dir, r)) {
            *a += d / n_dir as f64;
        }
    }
    let h1 = 1e-3 * e0.norm();
    let (d1, d2) = (cd(J, h1), cd(J, 2.0 * h1));
    let mut worst = [0.0f64; 2];
    for i in 0..base.h.len() {
        let an = base.dh_de[i];
        let scale = an.norm().max(1e-3 * base.h[i].norm() / e0.norm());
        worst[0] = worst[0].max((an - avg[i]).norm() / scale);
        // cd(J, h) = [dH along E''] / j, which equals dH/dE' iff dH/dE'' = j dH/dE'
        let rich = (d1[i] * 4.0 - d2[i]) / 3.0;
        worst[1] = worst[1].max((an - rich).norm() / scale);
    }
    eprintln!(
        "10 mm joint, {} DOFs: dH/dE' vs averaged central differences {:.2e}; dH/dE'' = j dH/dE' vs E''-direction Richardson {:.2e}",
        model.n_dof(),
        worst[0],
        worst[1]
    );
    assert!(worst[0] < 1e-6, "dH/dE' vs FD: {:e}", worst[0]);
    assert!(worst[1] < 2e-5, "dH/dE'' vs FD: {:e}", worst[1]);
}

/// A coarse joint mesh, with Rayleigh and structural adherend damping so every term of
/// Z(w) = -w^2 M + K_b + j w C_b + j D_b + E* S is exercised.
fn coarse_damped_joint() -> StructuralModel {
    let mut s = JointSpec::paper();
    s.mesh.size = MeshSize::Divisions(Divisions {
        x_adhesive: 2,
        x_outside: 20,
        y_beam: 1,
        y_adhesive: 1,
        z: 2,
    });
    s.damping.rayleigh_alpha_per_s = 2.0;
    s.damping.rayleigh_beta_s = 1e-6;
    s.damping.structural_loss_factor = 0.002;
    build_joint_model(&s).unwrap().0
}

/// Receptances and dH/dE' of the sparse engine against a dense partial-pivoting LU of the same
/// complex Z(w): 1e-10 relative at and above the resonances; below the first mode, see the
/// rounding-floor note at the end. (S H is exactly zero here: the points sit on the upper
/// face, away from the adhesive, so it is covered by tests/frf_full.rs instead.)
#[test]
fn frfs_match_dense_direct_solve_on_coarse_joint() {
    let model = coarse_damped_joint();
    let n = model.n_dof();
    assert!((500..=2500).contains(&n), "coarse joint has {n} DOFs");
    assert!(model.c_b.is_some() && model.d_b.is_some());
    let inputs = [INPUT, 3];
    let fm = FullModel::new(&model, &inputs, FullParams::default()).unwrap();
    let w: Vec<f64> = [10.0, 30.0, 150.0, 420.0, 900.0, 2000.0]
        .iter()
        .map(|f| 2.0 * PI * f)
        .collect();
    let e: Vec<C64> = w
        .iter()
        .map(|&w| C64::new(6e6 + 2e3 * w, 1.2e6 + 4e2 * w))
        .collect();
    let sw = fm.sweep(&w, &e, true).unwrap();
    let (m, k, s) = (
        to_dense_c64(&model.m),
        to_dense_c64(&model.k_b),
        to_dense_c64(&model.s),
    );
    let c = to_dense_c64(model.c_b.as_ref().unwrap());
    let d = to_dense_c64(model.d_b.as_ref().unwrap());
    let np = model.points.len();
    let mut b = Mat::<C64>::zeros(n, np);
    for (i, p) in model.points.iter().enumerate() {
        for &(dof, wt) in &p.dofs {
            b[(dof, i)] += C64::new(wt, 0.0);
        }
    }
    // worst relative error of H and dH/dE' on the lines above (index 0) and below (index 1)
    // the first resonance
    let mut worst = [[0.0f64; 2]; 2];
    for l in 0..w.len() {
        let z = Mat::from_fn(n, n, |r, q| {
            k[(r, q)] - m[(r, q)] * (w[l] * w[l])
                + e[l] * s[(r, q)]
                + J * w[l] * c[(r, q)]
                + J * d[(r, q)]
        });
        let x = z.partial_piv_lu().solve(&b);
        let h = b.transpose() * &x;
        let dh = -(x.transpose() * &s * &x);
        let band = usize::from(w[l] < 2.0 * PI * 100.0);
        // normwise over the line's n_out x n_in block (single entries near an antiresonance
        // have no relative accuracy to speak of)
        let mut acc = [[0.0f64; 2]; 2];
        for i in 0..np {
            for (jj, &j) in inputs.iter().enumerate() {
                let idx = sw.idx(l, i, jj);
                acc[0][0] += (sw.h[idx] - h[(i, j)]).norm_sqr();
                acc[0][1] += h[(i, j)].norm_sqr();
                acc[1][0] += (sw.dh_de[idx] - dh[(i, j)]).norm_sqr();
                acc[1][1] += dh[(i, j)].norm_sqr();
            }
        }
        for q in 0..2 {
            worst[band][q] = worst[band][q].max((acc[q][0] / acc[q][1]).sqrt());
        }
    }
    eprintln!(
        "coarse joint, {n} DOFs: max rel err vs dense: >= 100 Hz: H {:.2e}, dH/dE' {:.2e}; below the first mode: H {:.2e}, dH/dE' {:.2e}",
        worst[0][0], worst[0][1], worst[1][0], worst[1][1]
    );
    assert!(worst[0][0] < 1e-10, "H vs dense: {:e}", worst[0][0]);
    // dH/dE' = -X^T S X is a product of two solutions (errors add) with cancellation in the
    // sum over adhesive DOFs: 1e-9 (measured 3.2e-10).
    assert!(worst[0][1] < 1e-9, "dH/dE' vs dense: {:e}", worst[0][1]);
    // Below the first (rocking/bending-on-adhesive) mode the response is governed by the soft
    // adhesive (E*/E_steel ~ 3.5e-5) while Z's entries are set by the steel: both LU
    // factorisations are backward stable, but their forward errors are ~eps cond(Z) ~ 1e-8 and
    // uncorrelated, uniform over all entries (measured 6e-9 at 10 Hz, 1.2e-8 at 30 Hz). That is
    // the rounding floor of any double-precision direct solve, not an engine defect.
    assert!(
        worst[1][0] < 5e-8,
        "H vs dense below the first mode: {:e}",
        worst[1][0]
    );
    assert!(
        worst[1][1] < 1e-7,
        "dH/dE' vs dense below the first mode: {:e}",
        worst[1][1]
    );
}

/// The 10 mm joint (with adherend damping, so C_b and D_b travel too) exported with
/// `export_model`, rewritten by scipy.io.mmread/mmwrite, imported: same FRFs to 1e-12.
#[test]
fn scipy_matrix_market_round_trip_of_the_joint() {
    let Some(py) = python_for_scipy("scipy_matrix_market_round_trip_of_the_joint") else {
        return;
    };
    let mut s = JointSpec::paper();
    s.mesh.size = MeshSize::ElementSize(0.01);
    s.damping.rayleigh_alpha_per_s = 2.0;
    s.damping.rayleigh_beta_s = 1e-6;
    s.damping.structural_loss_factor = 0.002;
    let model = build_joint_model(&s).unwrap().0;
    let back = scipy_round_trip(&py, &model);
    assert_eq!(back.n_dof(), model.n_dof());
    assert!(back.c_b.is_some() && back.d_b.is_some());
    assert_eq!(back.points.len(), model.points.len());
    let w: Vec<f64> = lines_hz().iter().map(|f| 2.0 * PI * f).collect();
    let e = vec![C64::new(6.974e6, 1.4827e6); w.len()];
    let sweep = |m: &StructuralModel| {
        FullModel::new(m, &[INPUT], FullParams::default())
            .unwrap()
            .sweep(&w, &e, false)
            .unwrap()
            .h
    };
    let (a, b) = (sweep(&model), sweep(&back));
    let worst = a
        .iter()
        .zip(&b)
        .map(|(x, y)| (x - y).norm() / x.norm())
        .fold(0.0, f64::max);
    eprintln!(
        "joint scipy round trip ({} DOFs): max relative FRF difference {worst:.1e}",
        model.n_dof()
    );
    assert!(
        worst < 1e-12,
        "FRFs after the SciPy round trip differ by {worst:e}"
    );
}
