//! Criterion bench of the ROM build: assembly, basis and certificate of the ROM
//! of the paper's joint on the 2.5 mm mesh (67 224 free DOFs), excitation at point 2 and the
//! 4 measured points (4 FRFs), default settings: E' 0.5-50 MPa, E'' 0.01-20 MPa, 1-500 Hz,
//! tolerance 1e-6, 9 moduli x 25 lines, GMRES reference. Ten samples of about 30 s each:
//! `cargo bench --bench rom_build` (about 6 minutes). The peak resident memory of the whole
//! bench process (VmHWM) is printed at the end.

use criterion::{criterion_group, criterion_main, Criterion};
use rfmlab::fe::joint::{build_joint_model, JointSpec, MeshSize};
use rfmlab::rom::{build_rom, RomParams};
use std::time::Duration;

fn vm_hwm_gb() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .and_then(|l| l.split_whitespace().nth(1).map(str::to_owned))
        })
        .and_then(|kb| kb.parse::<f64>().ok())
        .map_or(0.0, |kb| kb * 1024.0 / 1e9)
}

fn bench(c: &mut Criterion) {
    let mut spec = JointSpec::paper();
    spec.mesh.size = MeshSize::ElementSize(0.0025);
    let mut g = c.benchmark_group("rom_build");
    g.sample_size(10)
        .measurement_time(Duration::from_secs(300))
        .warm_up_time(Duration::from_secs(1));
    g.bench_function("assembly_basis_certificate_2p5mm_4frf", |b| {
        b.iter(|| {
            let (model, _) = build_joint_model(&spec).expect("joint builds");
            let (rom, cert) = build_rom(&model, &[1], &RomParams::default()).expect("certified");
            assert!(cert.passed);
            rom
        })
    });
    g.finish();
    eprintln!(
        "peak resident memory of the bench process: {:.2} GB",
        vm_hwm_gb()
    );
}

criterion_group!(benches, bench);
criterion_main!(benches);
