//! The full-model sweep on the paper's joint with 5 mm elements (`JointSpec::paper()`, 10 248
//! free DOFs): 4 FRFs (4 outputs x 1 input, excitation at point 2) with derivatives dH/dE' and
//! S H, on 20 lines spread over 1-500 Hz (a sparse complex LU per line; the 500-line sweep of
//! the paper's identification is 25 times this, since lines are independent and the pattern's
//! symbolic analysis is done once).
//!
//! Run: `cargo bench --bench frf_full`.

use criterion::{criterion_group, criterion_main, Criterion};
use rfmlab::common::C64;
use rfmlab::fe::joint::{build_joint_model, JointSpec};
use rfmlab::frf::full::{FullModel, FullParams};
use rfmlab::frf::FrfEngine;

fn bench(c: &mut Criterion) {
    let (model, info) = build_joint_model(&JointSpec::paper()).expect("paper joint builds");
    assert_eq!(model.points.len(), 4);
    println!(
        "5 mm joint: {} elements, {} free DOFs",
        info.n_elements, info.n_dof
    );
    let fm = FullModel::new(&model, &[1], FullParams::default()).unwrap();
    let w: Vec<f64> = (0..20)
        .map(|k| 2.0 * std::f64::consts::PI * (1.0 + 25.0 * k as f64))
        .collect();
    let e: Vec<C64> = w.iter().map(|_| C64::new(6.974e6, 1.4827e6)).collect();
    let mut g = c.benchmark_group("frf_full");
    g.sample_size(10);
    g.bench_function("sweep_4frf_20lines_5mm_joint", |b| {
        b.iter(|| fm.sweep(&w, &e, true).unwrap())
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
