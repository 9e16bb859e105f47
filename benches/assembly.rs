//! Assembly time of the joint model (M, K_b, S and point map) at 5 mm and 2.5 mm elements.
//! Run: `cargo bench --bench assembly`. Before the timed runs, one build per size prints the
//! mesh size and the process's peak resident memory (VmHWM from /proc/self/status).

use criterion::{criterion_group, Criterion};
use rfmlab::fe::joint::{build_joint_model, JointSpec, MeshSize};
use std::hint::black_box;
use std::time::Duration;

fn spec(h: f64) -> JointSpec {
    let mut s = JointSpec::paper();
    s.mesh.size = MeshSize::ElementSize(h);
    s
}

fn peak_rss_mib() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024.0)
}

fn bench_assembly(c: &mut Criterion) {
    let mut g = c.benchmark_group("joint_assembly");
    g.sample_size(10).measurement_time(Duration::from_secs(10));
    for (name, h) in [("5mm", 0.005), ("2.5mm", 0.0025)] {
        let s = spec(h);
        g.bench_function(name, |b| {
            b.iter(|| black_box(build_joint_model(black_box(&s)).unwrap()))
        });
    }
    g.finish();
}

criterion_group!(benches, bench_assembly);

fn main() {
    for h in [0.005, 0.0025] {
        let before = peak_rss_mib().unwrap_or(f64::NAN);
        let (model, info) = build_joint_model(&spec(h)).expect("paper joint builds");
        let nnz = model.m.val().len() + model.k_b.val().len() + model.s.val().len();
        println!(
            "h = {:.1} mm: {} elements, {} nodes, {} free DOFs, nnz(M + K_b + S) = {nnz}, assembly {:.3} s, peak RSS {:.0} MiB (before {:.0} MiB)",
            h * 1e3,
            info.n_elements,
            info.n_nodes,
            info.n_dof,
            info.assembly_seconds,
            peak_rss_mib().unwrap_or(f64::NAN),
            before
        );
    }
    benches();
    Criterion::default().configure_from_args().final_summary();
}
