//! The small dense spring-mass chain of the RFM, IEM and Gauss-Newton tests (rfm.rs, iem.rs,
//! rfm_gauss_newton.rs).
#![allow(dead_code)]

use faer::Mat;

/// Number of DOFs (masses) of the chain.
pub const N: usize = 8;

/// Chain of 8 masses (0.08..0.15 kg), as (M, K_b, S) with K = K_b + E* S. Springs: ground-1,
/// 1-2 and ground-5 are adhesive (stiffness E* x area/thickness, in S), the rest steel-like (in
/// K_b). Modes span about 20-1500 Hz.
pub fn chain() -> (Mat<f64>, Mat<f64>, Mat<f64>) {
    let mut m = Mat::<f64>::zeros(N, N);
    for i in 0..N {
        m[(i, i)] = 0.08 + 0.01 * i as f64;
    }
    let mut k = Mat::<f64>::zeros(N, N);
    let mut s = Mat::<f64>::zeros(N, N);
    let add = |a: &mut Mat<f64>, i: Option<usize>, j: usize, v: f64| {
        a[(j, j)] += v;
        if let Some(i) = i {
            a[(i, i)] += v;
            a[(i, j)] -= v;
            a[(j, i)] -= v;
        }
    };
    add(&mut s, None, 0, 0.02);
    add(&mut s, Some(0), 1, 0.01);
    add(&mut s, None, 4, 0.004);
    for i in 1..N - 1 {
        add(&mut k, Some(i), i + 1, 1.5e6 + 2e5 * i as f64);
    }
    (m, k, s)
}

/// DOFs of the chain measured in the inference tests (points 0-3), excited at point 1.
pub const MEASURED: [usize; 4] = [1, 3, 5, 7];

/// The chain as a dense FRF engine observed at [`MEASURED`], every point an input.
pub fn measured_engine() -> rfmlab::rfm::DenseEngine {
    let (m, k, s) = chain();
    rfmlab::rfm::DenseEngine::new(
        m,
        k,
        s,
        MEASURED.iter().map(|&d| vec![(d, 1.0)]).collect(),
        (0..MEASURED.len()).collect(),
    )
    .unwrap()
}

/// A seeded standard normal stream without extra dependencies (xorshift64* + Box-Muller).
pub struct Normal(pub u64);
impl Normal {
    pub fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        ((self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }
    pub fn next(&mut self) -> f64 {
        let (u, v) = (self.uniform(), self.uniform());
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    }
}

/// The H1 measurement model of the chain's tests: Hann windows of 1/6 s (6 Hz lines) at
/// 4096 Hz, a white force over 2-1000 Hz, on the lines `lines_hz`.
pub fn hann_measurement(lines_hz: &[f64]) -> rfmlab::forward::MeasurementModel {
    rfmlab::forward::MeasurementModel::new(
        rfmlab::forward::EstimatorSpec {
            window: rfmlab::experiment::Window::Hann,
            block_s: 1.0 / 6.0,
            fs_hz: 4096.0,
            force_band_hz: (2.0, 1000.0),
            shaker: None,
        },
        lines_hz,
        &rfmlab::forward::MeasurementParams::default(),
    )
    .unwrap()
}
