//! Simulating one level (4 channels, 200 averages, 500 lines) in time- and frequency-domain mode.

use criterion::{criterion_group, criterion_main, Criterion};
use rfmlab::common::C64;
use rfmlab::experiment::{simulate_level, ChainParams, ExperimentError, Mode, NoiseLevel, Plant};
use std::f64::consts::PI;

/// Modal sum with structural damping: 22 Hz (eta 0.2), 394 Hz (eta 0.07), 900 Hz (eta 0.05).
struct ModalPlant;

const F: [f64; 3] = [22.0, 394.0, 900.0];
const ETA: [f64; 3] = [0.2, 0.07, 0.05];
const PHI: [[f64; 3]; 4] = [
    [1.0, 0.8, 0.5],
    [1.3, -0.6, 0.7],
    [0.7, 1.1, -0.4],
    [0.4, 0.9, 0.9],
];

impl Plant for ModalPlant {
    fn n_channels(&self) -> usize {
        4
    }
    fn drive_channel(&self) -> usize {
        1
    }
    fn accelerance(&self, freq_hz: &[f64]) -> Result<Vec<Vec<C64>>, ExperimentError> {
        Ok((0..4)
            .map(|c| {
                freq_hz
                    .iter()
                    .map(|&f| {
                        let w2 = (2.0 * PI * f).powi(2);
                        (0..3)
                            .map(|r| {
                                let wr2 = (2.0 * PI * F[r]).powi(2);
                                -w2 * PHI[c][r] * PHI[1][r] / C64::new(wr2 - w2, wr2 * ETA[r])
                            })
                            .sum()
                    })
                    .collect()
            })
            .collect())
    }
}

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("simulate_level_4ch_200avg_500lines");
    g.sample_size(10);
    for (name, mode) in [
        ("time_domain", Mode::TimeDomain),
        ("frequency_domain", Mode::FrequencyDomain),
    ] {
        let chain = ChainParams {
            mode,
            response_noise: vec![NoiseLevel::FractionOfSignalRms(0.02)],
            ..ChainParams::default()
        };
        g.bench_function(name, |b| {
            b.iter(|| simulate_level(&ModalPlant, &chain).unwrap())
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
