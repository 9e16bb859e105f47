//! Criterion benches of issue 3: one pencil sweep of 4 FRFs x 500 lines for a given E*(w)
//! curve (with derivatives), the per-line dense LU sweep of the same ROM, and the ROM build.
//! The model is the beam-on-adhesive test model (tests/rom_model) until the mesher lands.

use criterion::{criterion_group, criterion_main, Criterion};
use rfmlab::common::C64;
use rfmlab::frf::{FrfEngine, Sweep};
use rfmlab::rom::{build_rom, RomParams};
use std::hint::black_box;

#[path = "../tests/rom_model/mod.rs"]
mod rom_model;

/// Model 4 at Level 1 (method.md): E0 + j h + j w eta1 E1 / (E1 + j w eta1).
fn model4(omega: f64) -> C64 {
    let (e0, e1, eta1, h) = (6.67e6, 3.1487e6, 4.181e3, 0.944e6);
    let jw = C64::new(0.0, omega * eta1);
    C64::new(e0, h) + jw * e1 / (e1 + jw)
}

fn bench(c: &mut Criterion) {
    let model = rom_model::beam_model(60);
    let params = RomParams::default();
    let (rom, cert) = build_rom(&model, &[1], &params).expect("certified ROM");
    let omega: Vec<f64> = (1..=500)
        .map(|f| 2.0 * std::f64::consts::PI * f as f64)
        .collect();
    let modulus: Vec<C64> = omega.iter().map(|&w| model4(w)).collect();
    let pencil = rom.prepare(&omega).unwrap();
    let (near, mom) = pencil.mean_terms();
    eprintln!(
        "n_dof {}, n_r {}, cert {:.2e}, near terms/line {near:.1}, moments/line {mom:.1}, fallback lines {}, flops/sweep (with derivatives) {:.3e}",
        model.n_dof(),
        rom.basis_size(),
        cert.max_rel_error,
        pencil.n_fallback_lines(),
        pencil.flops_per_sweep(true)
    );
    let mut out = Sweep::default();
    c.bench_function("pencil_sweep_4x500_with_derivatives", |b| {
        b.iter(|| {
            pencil
                .sweep_into(black_box(&omega), black_box(&modulus), true, &mut out)
                .unwrap()
        })
    });
    c.bench_function("pencil_sweep_4x500_h_only", |b| {
        b.iter(|| {
            pencil
                .sweep_into(black_box(&omega), black_box(&modulus), false, &mut out)
                .unwrap()
        })
    });
    let mut g = c.benchmark_group("slow");
    g.sample_size(10);
    g.bench_function("reduced_lu_sweep_4x500_with_derivatives", |b| {
        b.iter(|| rom.lu_sweep(&omega, &modulus, true).unwrap())
    });
    g.bench_function("pencil_prepare_500_lines", |b| {
        b.iter(|| rom.prepare(&omega).unwrap())
    });
    g.bench_function("rom_build_beam60", |b| {
        b.iter(|| build_rom(&model, &[1], &params).unwrap())
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
