//! The certified ROM on the paper's bonded joint (rfmlab::fe::joint): build, certificate and sweep.
//!
//! Fast tests use the 10 mm mesh; the 5 mm and 2.5 mm acceptance runs are `#[ignore]`d
//! (commands in their doc comments) because they take longer than a test should.

use rfmlab::fe::joint::{build_joint_model, JointSpec, MeshSize};
use rfmlab::fe::model::StructuralModel;
use rfmlab::rom::{build_rom, RomParams};
use std::time::Instant;

fn joint(element_size_m: f64) -> StructuralModel {
    let mut spec = JointSpec::paper();
    spec.mesh.size = MeshSize::ElementSize(element_size_m);
    build_joint_model(&spec).expect("joint model").0
}

/// Peak resident memory of this process (VmHWM, bytes).
fn vm_hwm_bytes() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

fn all_inputs(m: &StructuralModel) -> Vec<usize> {
    (0..m.points.len()).collect()
}

fn certify_report(element_size_m: f64) {
    let t = Instant::now();
    let model = joint(element_size_m);
    let t_asm = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let envf = |k: &str, d: f64| {
        std::env::var(k)
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(d)
    };
    let d = RomParams::default();
    let params = RomParams {
        allow_uncertified: true,
        deflation_tol: envf("ROM_DEFL", d.deflation_tol),
        n_e_ref_initial: envf("ROM_NE", d.n_e_ref_initial as f64) as usize,
        krylov_depth_initial: envf("ROM_D0", d.krylov_depth_initial as f64) as usize,
        krylov_depth_step: envf("ROM_DS", d.krylov_depth_step as f64) as usize,
        max_levels: envf("ROM_LV", d.max_levels as f64) as usize,
        n_cert_lines: envf("ROM_LINES", d.n_cert_lines as f64) as usize,
        n_cert_moduli_per_axis: envf("ROM_MODULI", d.n_cert_moduli_per_axis as f64) as usize,
        reference: if std::env::var("ROM_REF").as_deref() == Ok("lu") {
            rfmlab::rom::Reference::SparseLu
        } else {
            rfmlab::rom::Reference::Iterative {
                residual_tol: envf("ROM_RTOL", 1e-9),
                max_iter: envf("ROM_MAXIT", 80.0) as usize,
            }
        },
        ..d
    };
    let (rom, cert) = build_rom(&model, &all_inputs(&model), &params).expect("ROM");
    let t_rom = t.elapsed().as_secs_f64();
    eprintln!(
        "mesh {:.1} mm: {} DOFs, assembly {t_asm:.2} s, ROM {t_rom:.2} s (basis {:.2} s, certificate {:.2} s), n_r {}, error {:.3e}, history {:?}, VmHWM {:.2} GB",
        element_size_m * 1e3,
        model.n_dof(),
        cert.seconds_basis,
        cert.seconds_certify,
        rom.basis_size(),
        cert.max_rel_error,
        cert.error_history,
        vm_hwm_bytes().unwrap_or(0) as f64 / 1e9
    );
    eprintln!("certificate: {cert:?}");
    assert!(cert.passed && cert.max_rel_error <= 1e-6);
}

/// 5 mm mesh (10248 DOFs), E' in [0.5, 50] MPa, E'' in [0.01, 20] MPa, 1-500 Hz, 1e-6.
/// `cargo test --test suite rom_joint:: -- --ignored --nocapture certify_5mm`
#[test]
#[ignore]
fn certify_5mm() {
    certify_report(0.005);
}

/// 2.5 mm mesh (67224 DOFs). Release: `cargo test --release --test suite rom_joint:: -- --ignored --nocapture certify_2p5mm`
#[test]
#[ignore]
fn certify_2p5mm() {
    certify_report(0.0025);
}

#[test]
fn certify_10mm() {
    certify_report(0.010);
}

/// The ROM's complex modes (its reduced pencil, what the IEM uses with the ROM engine) match
/// the full model's complex modes (shift-invert Lanczos + Rayleigh-quotient refinement) for
/// every ROM mode inside the certified band: eigenvalue and phi^T S phi.
#[test]
fn rom_complex_modes_match_the_full_model_in_band() {
    let model = joint(0.010);
    let params = RomParams {
        n_cert_moduli_per_axis: 2,
        n_cert_lines: 10,
        ..RomParams::default()
    };
    let (rom, _) = build_rom(&model, &all_inputs(&model), &params).expect("ROM");
    let e = rfmlab::common::C64::new(6.974e6, 1.4827e6);
    let full =
        rfmlab::modes::complex_modes(&model, e, 12, None, &rfmlab::modes::ModesParams::default())
            .expect("full modes");
    let reduced = rom.complex_modes(e, 12).expect("ROM modes");
    let obs =
        |m: &rfmlab::frf::EngineMode| m.at_points.iter().map(|z| z.norm()).fold(0.0, f64::max);
    let top = reduced.iter().map(obs).fold(0.0, f64::max);
    // Modes the points see (y bending); the basis also carries traces of modes they do not
    // (lateral bending, torsion), amplified from rounding by the Krylov sequence.
    let in_band: Vec<_> = reduced
        .iter()
        .filter(|m| m.freq_hz() < 500.0 && obs(m) > 1e-3 * top)
        .collect();
    for m in &reduced {
        eprintln!(
            "ROM mode {:.4} Hz, observability {:.2e}",
            m.freq_hz(),
            obs(m) / top
        );
    }
    assert!(in_band.len() >= 2, "ROM modes below 500 Hz: {in_band:?}");
    for m in in_band {
        let f = full
            .iter()
            .min_by(|a, b| {
                (a.lambda - m.lambda)
                    .norm()
                    .total_cmp(&(b.lambda - m.lambda).norm())
            })
            .unwrap();
        let d_lambda = (f.lambda - m.lambda).norm() / f.lambda.norm();
        let d_sens = (f.phi_s_phi - m.phi_s_phi).norm() / f.phi_s_phi.norm();
        eprintln!(
            "ROM mode {:.4} Hz eta {:.5}: full {:.4} Hz eta {:.5}; |d lambda|/|lambda| {d_lambda:.2e}, phi^T S phi {d_sens:.2e}",
            m.freq_hz(),
            m.loss_factor(),
            f.freq_hz,
            f.loss_factor,
        );
        assert!(d_lambda < 1e-6, "eigenvalue {d_lambda:e}");
        assert!(d_sens < 1e-4, "phi^T S phi {d_sens:e}");
    }
}

/// `rfmlab convergence --method rom`'s modes: a Krylov basis at the one modulus
/// (`build_basis_only`, no certificate) gives the same first two y-dominant modes as the full
/// model's refined complex modes, classified by the same kinetic-energy rule.
#[test]
fn basis_only_modes_match_full_y_modes_at_10mm() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let study = rfmlab::study::load(&root.join("studies/paper_geometry.toml")).unwrap();
    let mut s = study.structure.clone();
    if let rfmlab::study::StructureSource::Mesher(j) = &mut s.source {
        j.mesh = rfmlab::study::MeshSize::ElementSize(0.010);
    }
    let b = rfmlab::study::build::build_model(&s, "paper_geometry.toml").unwrap();
    let e = rfmlab::common::C64::new(6.974e6, 1.4827e6);
    let threshold = rfmlab::modes::ModesParams::default().y_dominant_threshold;
    let full: Vec<_> = rfmlab::modes::complex_modes(
        &b.model,
        e,
        8,
        b.dof_axes.as_deref(),
        &rfmlab::modes::ModesParams::default(),
    )
    .unwrap()
    .into_iter()
    .filter(|m| m.y_dominant == Some(true))
    .take(2)
    .collect();
    let params = RomParams {
        range: rfmlab::rom::ModulusRange {
            e_storage_pa: (e.re, e.re),
            e_loss_pa: (e.im, e.im),
        },
        krylov_depth_initial: 6,
        ..RomParams::default()
    };
    let inputs = all_inputs(&b.model);
    let rom =
        rfmlab::rom::build_basis_only(&b.model, &inputs, &params, b.dof_axes.as_deref()).unwrap();
    let reduced: Vec<_> = rom
        .complex_modes(e, 8)
        .unwrap()
        .into_iter()
        .filter(|m| m.energy_fraction_xyz.is_some_and(|f| f[1] > threshold))
        .take(2)
        .collect();
    assert_eq!((full.len(), reduced.len()), (2, 2));
    for (f, r) in full.iter().zip(&reduced) {
        let d = (f.lambda - r.lambda).norm() / f.lambda.norm();
        eprintln!(
            "full {:.4} Hz eta {:.5} | basis-only {:.4} Hz eta {:.5}: {d:.1e}",
            f.freq_hz,
            f.loss_factor,
            r.freq_hz(),
            r.loss_factor()
        );
        assert!(d < 1e-8, "eigenvalue differs by {d:e}");
    }
}

/// The basis build runs its Krylov sequences, sparse products and Gram-Schmidt sweeps in
/// parallel over fixed-size chunks: on the 5 mm mesh (10248 DOFs, several chunks of every
/// kernel) the reduced matrices are bit-identical with one and two threads.
#[test]
fn basis_is_bit_identical_with_one_or_two_threads_on_5mm() {
    let model = joint(0.005);
    let params = RomParams::default();
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| rfmlab::rom::build_basis_only(&model, &[1], &params, None).unwrap())
    };
    let (a, b) = (run(1), run(2));
    assert!(a.basis_size() > 20);
    let e = rfmlab::common::C64::new(6.974e6, 1.4827e6);
    let omega: Vec<f64> = (1..=200)
        .map(|k| 2.0 * std::f64::consts::PI * 2.5 * k as f64)
        .collect();
    let sa = a.lu_sweep(&omega, &vec![e; omega.len()], true).unwrap();
    let sb = b.lu_sweep(&omega, &vec![e; omega.len()], true).unwrap();
    let bits = |v: &[rfmlab::common::C64]| {
        v.iter()
            .flat_map(|z| [z.re.to_bits(), z.im.to_bits()])
            .collect::<Vec<_>>()
    };
    assert_eq!(a.basis_size(), b.basis_size());
    assert_eq!(bits(&sa.h), bits(&sb.h));
    assert_eq!(bits(&sa.dh_de), bits(&sb.dh_de));
}

/// The certificate (its GMRES reference: systems queued per factor, blocked kernels over
/// fixed chunks) gives the same bits with one or two threads, 4 x 4 FRFs on the 10 mm joint.
#[test]
fn certificate_is_bit_identical_with_one_or_two_threads_on_10mm() {
    let model = joint(0.010);
    let inputs = all_inputs(&model);
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| build_rom(&model, &inputs, &RomParams::default()).unwrap())
    };
    let ((ra, ca), (rb, cb)) = (run(1), run(2));
    assert!(ca.passed && ca.reference == "GMRES");
    assert_eq!(ca.max_rel_error.to_bits(), cb.max_rel_error.to_bits());
    assert_eq!(
        ca.reference_residual.map(f64::to_bits),
        cb.reference_residual.map(f64::to_bits)
    );
    assert_eq!(ca.reference_iterations, cb.reference_iterations);
    assert_eq!(ra.basis_size(), rb.basis_size());
}

/// The certificate's GMRES reference (ROM as coarse space, real Cholesky preconditioner,
/// Arnoldi in the preconditioner's energy product) against the sparse-LU reference on the
/// 10 mm joint. The worst validation point is near-resonant and lightly damped
/// (E'' = 0.01 MPa, 21.8 Hz), where Z is so ill-conditioned that the LU's own residual is
/// ~1e-8 ||b|| and the ROM's error there is known only to a few 1e-8 of the peak: the
/// certificates from the LU and from GMRES at residuals 1e-9 and 1e-10 all pass and agree to
/// 1e-7 (a tenth of the 1e-6 tolerance), and tightening GMRES moves it by less than 1e-8.
#[test]
fn gmres_reference_agrees_with_sparse_lu_at_10mm() {
    let model = joint(0.010);
    let inputs = [1usize];
    let with = |reference| RomParams {
        reference,
        ..RomParams::default()
    };
    let (_, c_lu) =
        build_rom(&model, &inputs, &with(rfmlab::rom::Reference::SparseLu)).expect("LU");
    let (_, c_9) = build_rom(&model, &inputs, &RomParams::default()).expect("GMRES 1e-9");
    let tight = rfmlab::rom::Reference::Iterative {
        residual_tol: 1e-10,
        max_iter: 300,
    };
    let (_, c_10) = build_rom(&model, &inputs, &with(tight)).expect("GMRES 1e-10");
    eprintln!("LU: {c_lu:?}\nGMRES 1e-9: {c_9:?}\nGMRES 1e-10: {c_10:?}");
    assert_eq!(c_9.reference, "GMRES");
    assert_eq!(c_lu.reference, "sparse LU");
    assert!(c_9.reference_residual.unwrap() <= 1e-9);
    assert!(c_10.reference_residual.unwrap() <= 1e-10);
    assert!(c_lu.passed && c_9.passed && c_10.passed);
    assert_eq!(c_lu.basis_size, c_9.basis_size);
    let (e_lu, e9, e10) = (c_lu.max_rel_error, c_9.max_rel_error, c_10.max_rel_error);
    assert!(
        (e9 - e10).abs() <= 1e-8,
        "GMRES 1e-9 {e9:.3e} vs 1e-10 {e10:.3e}"
    );
    for (name, e) in [("1e-9", e9), ("1e-10", e10)] {
        assert!(
            (e_lu - e).abs() <= 1e-7,
            "LU {e_lu:.3e} vs GMRES {name} {e:.3e}"
        );
    }
    // the energy product keeps the iteration count low (16 measured at 1e-9)
    assert!(
        c_9.reference_iterations.unwrap() <= 25,
        "{:?}",
        c_9.reference_iterations
    );
}
