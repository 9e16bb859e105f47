//! Criterion bench of the Bayesian layer's unit of work on the paper's joint (5 mm elements,
//! excitation at point 2, 4 measured points, 500 lines 1-500 Hz, Model 4 at Level 1's truth):
//! one log-likelihood value + gradient (coherence noise model), without and with the H1
//! measurement model (Hann, 1 s blocks, force from 0 Hz; 8 points per line and the grid the
//! runner chooses by convergence; and its bias linearised at the point, what the samplers
//! evaluate), side by side
//! with the ROM sweep of the same 4 FRFs x 500 lines with derivatives that it is measured
//! against (the target: at most twice the sweep).
//! Run: `cargo bench --bench likelihood`.

use criterion::{criterion_group, criterion_main, Criterion};
use rfmlab::common::C64;
use rfmlab::experiment::Window;
use rfmlab::fe::joint::{build_joint_model, JointSpec};
use rfmlab::forward::{EstimatorSpec, ForwardModel, MeasurementModel, MeasurementParams};
use rfmlab::frf::{FrfEngine, Sweep};
use rfmlab::inference::likelihood::{ErrorLaw, FrfData, FrfLikelihood, NoiseModel, Scale};
use rfmlab::material::{paper_table4, ConstitutiveModel, Model4};
use rfmlab::rom::{build_rom, RomParams};
use std::hint::black_box;

/// The ROM prepared on several grids: each sweep goes to the pencil of its grid.
struct Engines(Vec<rfmlab::rom::PencilSweep>);
impl FrfEngine for Engines {
    fn n_out(&self) -> usize {
        self.0[0].n_out()
    }
    fn inputs(&self) -> &[usize] {
        self.0[0].inputs()
    }
    fn sweep_into(
        &self,
        omega: &[f64],
        modulus: &[C64],
        d: bool,
        out: &mut Sweep,
    ) -> Result<(), rfmlab::frf::FrfError> {
        let p = self
            .0
            .iter()
            .find(|p| p.omega_rad_s() == omega)
            .expect("a prepared grid");
        p.sweep_into(omega, modulus, d, out)
    }
}

fn bench(c: &mut Criterion) {
    let (model, _) = build_joint_model(&JointSpec::paper()).expect("paper joint builds");
    let params = RomParams {
        n_cert_moduli_per_axis: 2,
        n_cert_lines: 10,
        ..RomParams::default()
    };
    let (rom, _) = build_rom(&model, &[1], &params).expect("certified ROM");
    let lines: Vec<f64> = (1..=500).map(|f| f as f64).collect();
    let omega: Vec<f64> = lines.iter().map(|f| std::f64::consts::TAU * f).collect();
    let (p, _) = paper_table4(4);
    let spec = EstimatorSpec {
        window: Window::Hann,
        block_s: 1.0,
        fs_hz: 2048.0,
        force_band_hz: (0.0, 500.0),
        shaker: None,
    };
    let grid = |ppl: usize| {
        MeasurementModel::new(
            spec,
            &lines,
            &MeasurementParams {
                points_per_line: ppl,
                ..MeasurementParams::default()
            },
        )
        .unwrap()
    };
    let mut pencils = vec![rom.prepare(&omega).unwrap()];
    for ppl in rfmlab::forward::GRID_CANDIDATES {
        pencils.push(rom.prepare(&grid(ppl).fine_omega()).unwrap());
    }
    let engines = Engines(pencils);
    // The grid the runner would choose for this rig (converged at the truth).
    let obs = rfmlab::forward::Observation::new(&engines, &omega, 1, &[0, 1, 2, 3], None).unwrap();
    let (auto, choice) = obs
        .converged_measurement(
            spec,
            &|w| Model4.modulus(&paper_table4(4).0, w),
            rfmlab::forward::GRID_TOLERANCE,
        )
        .unwrap();
    eprintln!("converged grid: {choice:?}");
    let mm = grid(8);
    let outputs = [0usize, 1, 2, 3];
    let lik = |m: Option<MeasurementModel>| {
        let fm = ForwardModel::new(&engines, &Model4, &omega, 1, &outputs, m).unwrap();
        let values = fm.predict(&p, false).unwrap().values;
        let data = FrfData {
            freq_hz: lines.clone(),
            n_out: 4,
            values: values.iter().map(|v| v * 1.01).collect(),
            coherence: Some(vec![0.99; values.len()]),
        };
        let noise = NoiseModel {
            scale: Scale::Coherence {
                n_averages: 189.5,
                floor: 1e-4,
            },
            errors: ErrorLaw::Gaussian,
            model_error: 0.0,
        };
        FrfLikelihood::new(fm, data, noise, &[1, 2, 3, 4]).unwrap()
    };
    let plain = lik(None);
    let measured = lik(Some(mm.clone()));
    let measured_auto = lik(Some(auto.clone()));
    // What the samplers evaluate by default: the measurement bias linearised at the MAP.
    let mut measured_lin = lik(Some(auto.clone()));
    measured_lin.forward.linearise_measurement(&p).unwrap();
    eprintln!(
        "fine grids: {} points (8 per line), {} points (converged, {} per line) for 500 lines",
        mm.fine_hz.len(),
        auto.fine_hz.len(),
        choice.points_per_line
    );
    let modulus: Vec<C64> = omega.iter().map(|&w| Model4.modulus(&p, w)).collect();
    let mut out = Sweep::default();
    c.bench_function("rom_sweep_4x500_with_derivatives_5mm", |b| {
        b.iter(|| {
            engines.0[0]
                .sweep_moduli_into(black_box(&modulus), true, &mut out)
                .unwrap()
        })
    });
    c.bench_function("loglik_and_gradient_4x500_5mm", |b| {
        b.iter(|| plain.eval(black_box(&p), &[], true).unwrap())
    });
    c.bench_function(
        "loglik_and_gradient_4x500_with_measurement_model_8_per_line_5mm",
        |b| b.iter(|| measured.eval(black_box(&p), &[], true).unwrap()),
    );
    c.bench_function(
        "loglik_and_gradient_4x500_with_measurement_model_converged_grid_5mm",
        |b| b.iter(|| measured_auto.eval(black_box(&p), &[], true).unwrap()),
    );
    c.bench_function(
        "loglik_and_gradient_4x500_with_measurement_model_linearised_5mm",
        |b| b.iter(|| measured_lin.eval(black_box(&p), &[], true).unwrap()),
    );
    // The sweep the likelihood with the measurement model must make: the converged fine grid.
    let fine_modulus: Vec<C64> = auto
        .fine_omega()
        .iter()
        .map(|&w| Model4.modulus(&p, w))
        .collect();
    let fine_pencil = engines
        .0
        .iter()
        .find(|q| q.omega_rad_s() == auto.fine_omega().as_slice())
        .expect("prepared");
    c.bench_function(
        "rom_sweep_4x_converged_fine_grid_with_derivatives_5mm",
        |b| {
            b.iter(|| {
                fine_pencil
                    .sweep_moduli_into(black_box(&fine_modulus), true, &mut out)
                    .unwrap()
            })
        },
    );
}

criterion_group!(benches, bench);
criterion_main!(benches);
