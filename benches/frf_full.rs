//! One full-model sweep: 4 FRFs (4 outputs x 1 input) x 500 lines, with derivatives.
//! Until the mesher is merged this runs on a synthetic lattice of 9,600 DOFs
//! (`rfmlab::linalg::synthetic`), replace by the 5 mm joint mesh afterwards.
//!
//! Run: `cargo bench --bench frf_full`.

use criterion::{criterion_group, criterion_main, Criterion};
use rfmlab::common::C64;
use rfmlab::frf::full::{FullModel, FullParams};
use rfmlab::frf::FrfEngine;
use rfmlab::linalg::synthetic::{lattice_model, LatticeParams};

fn bench(c: &mut Criterion) {
    let mut model = lattice_model(&LatticeParams::new(40, 10, 8, 1)).model;
    model.points.truncate(4);
    let fm = FullModel::new(&model, &[1], FullParams::default()).unwrap();
    let w: Vec<f64> = (0..500)
        .map(|l| 2.0 * std::f64::consts::PI * (10.0 + l as f64))
        .collect();
    let e: Vec<C64> = w.iter().map(|_| C64::new(7e6, 1.5e6)).collect();
    let mut g = c.benchmark_group("frf_full");
    g.sample_size(10);
    g.bench_function("sweep_4frf_500lines_9600dof", |b| {
        b.iter(|| fm.sweep(&w, &e, true).unwrap())
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
