//! Read and write a 4-channel, 500-line level (FRF + coherence per channel), ASCII and 58b.

use criterion::{criterion_group, criterion_main, Criterion};
use rfmlab::common::{Direction, C64};
use rfmlab::data::uff58::{parse_uff, serialize_uff};
use rfmlab::data::uff_frf::frf_set_datasets;
use rfmlab::data::{Channel, FrfLevel, FrfSet, Quantity};

fn level() -> FrfSet {
    let freq_hz: Vec<f64> = (1..=500).map(|k| k as f64).collect();
    let channels = (1..=4)
        .map(|p| Channel {
            response_id: p,
            response_dir: Direction::PY,
            reference_id: 2,
            reference_dir: Direction::PY,
            values: freq_hz
                .iter()
                .map(|f| C64::new(1.0 / (1.0 + f * p as f64), 0.01 * f))
                .collect(),
            coherence: Some(vec![0.99; 500]),
            source: None,
        })
        .collect();
    FrfSet {
        levels: vec![FrfLevel {
            name: "L1".into(),
            force_rms_n: Some(3.3),
            n_averages: Some(200),
            quantity: Quantity::Accelerance,
            freq_hz,
            channels,
        }],
    }
}

fn bench(c: &mut Criterion) {
    let ds = frf_set_datasets(&level());
    for binary in [false, true] {
        let tag = if binary { "58b" } else { "ascii" };
        let bytes = serialize_uff(&ds, binary, "bench").unwrap();
        c.bench_function(&format!("uff write 4ch x 500 {tag}"), |b| {
            b.iter(|| serialize_uff(&ds, binary, "bench").unwrap())
        });
        c.bench_function(&format!("uff read 4ch x 500 {tag}"), |b| {
            b.iter(|| parse_uff(&bytes, "bench").unwrap())
        });
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
