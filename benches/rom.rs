//! Criterion benches of the certified ROM on the paper's joint with 5 mm elements (10 248 free DOFs,
//! excitation at point 2, the 4 measured points): one pencil sweep of 4 FRFs x 500 lines
//! (1-500 Hz) for the Model 4 E*(w) curve, with and without derivatives; the per-line
//! dense LU sweep of the same ROM; the pencil preparation. The full-model sweep of the same
//! problem is `benches/frf_full.rs`; scipy's is `scripts/scipy_sweep.py`.
//!
//! The ROM here uses the default basis settings (the certified one of `rfmlab rom`) but a
//! small validation set (2 x 2 moduli x 10 lines), because the bench times the sweep,
//! not the certificate. Run: `cargo bench --bench rom`.

use criterion::{criterion_group, criterion_main, Criterion};
use rfmlab::common::C64;
use rfmlab::fe::joint::{build_joint_model, JointSpec};
use rfmlab::frf::Sweep;
use rfmlab::material::{paper_table4, ConstitutiveModel, Model4};
use rfmlab::rom::{build_rom, RomParams};
use std::hint::black_box;

fn bench(c: &mut Criterion) {
    let (model, info) = build_joint_model(&JointSpec::paper()).expect("paper joint builds");
    let params = RomParams {
        n_cert_moduli_per_axis: 2,
        n_cert_lines: 10,
        ..RomParams::default()
    };
    let (rom, cert) = build_rom(&model, &[1], &params).expect("certified ROM");
    let omega: Vec<f64> = (1..=500)
        .map(|f| 2.0 * std::f64::consts::PI * f as f64)
        .collect();
    let (p, _) = paper_table4(4); // Model 4, Level 1: the default data's truth
    let modulus: Vec<C64> = omega.iter().map(|&w| Model4.modulus(&p, w)).collect();
    let pencil = rom.prepare(&omega).unwrap();
    let (near, mom) = pencil.mean_terms();
    let flops_d = pencil.flops_per_sweep(true);
    let flops_h = pencil.flops_per_sweep(false);
    eprintln!(
        "5 mm joint: {} elements, {} DOFs; n_r {}, cert {:.2e} (basis {:.1} s), near terms/line {near:.1}, moments/line {mom:.1}, fallback lines {}, flops/sweep {:.3e} with derivatives, {:.3e} without",
        info.n_elements,
        model.n_dof(),
        rom.basis_size(),
        cert.max_rel_error,
        cert.seconds_basis,
        pencil.n_fallback_lines(),
        flops_d,
        flops_h
    );
    let mut out = Sweep::default();
    c.bench_function("pencil_sweep_4x500_with_derivatives_5mm", |b| {
        b.iter(|| {
            pencil
                .sweep_moduli_into(black_box(&modulus), true, &mut out)
                .unwrap()
        })
    });
    c.bench_function("pencil_sweep_4x500_h_only_5mm", |b| {
        b.iter(|| {
            pencil
                .sweep_moduli_into(black_box(&modulus), false, &mut out)
                .unwrap()
        })
    });
    let mut g = c.benchmark_group("slow");
    g.sample_size(10);
    g.bench_function("reduced_lu_sweep_4x500_with_derivatives_5mm", |b| {
        b.iter(|| rom.lu_sweep(&omega, &modulus, true).unwrap())
    });
    g.bench_function("pencil_prepare_500_lines_5mm", |b| {
        b.iter(|| rom.prepare(&omega).unwrap())
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
