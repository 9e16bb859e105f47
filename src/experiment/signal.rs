//! Signals: the window and its spectral kernel, the shaker's force transfer, seeded substreams.

use super::spec::{Shaker, Window};
use crate::common::C64;
use rand::rngs::StdRng;
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use std::f64::consts::PI;

impl Window {
    /// The `n` window samples `w_0..w_{n-1}` (periodic form, as analysers use with the DFT).
    pub fn samples(self, n: usize) -> Vec<f64> {
        match self {
            Window::Hann => (0..n)
                .map(|i| 0.5 - 0.5 * (2.0 * PI * i as f64 / n as f64).cos())
                .collect(),
            Window::Rectangular => vec![1.0; n],
        }
    }

    /// The window's DTFT `W(delta) = sum_n w_n exp(-j 2 pi delta n / N)` at an offset `delta`
    /// measured in DFT bins (`delta = (f - f_k) T_block`), in closed form: the Dirichlet kernel
    /// `D(delta) = exp(-j pi delta (N-1)/N) sin(pi delta) / sin(pi delta / N)` for the rectangular
    /// window, and `0.5 D(delta) - 0.25 D(delta - 1) - 0.25 D(delta + 1)` for Hann.
    /// A block's DFT of a line at `f` is `W((f_k - f) T)` times its complex amplitude, so
    /// `|W|^2` is the spectral kernel through which the estimator sees the structure.
    pub fn dtft(self, n: usize, delta: f64) -> C64 {
        match self {
            Window::Rectangular => dirichlet(n, delta),
            Window::Hann => {
                0.5 * dirichlet(n, delta)
                    - 0.25 * dirichlet(n, delta - 1.0)
                    - 0.25 * dirichlet(n, delta + 1.0)
            }
        }
    }

    /// `sum_n w_n^2` for `n` samples: the block power of unit-variance white noise.
    pub fn power_sum(self, n: usize) -> f64 {
        self.samples(n).iter().map(|w| w * w).sum()
    }

    /// Correlation coefficient `rho_m = sum_n w_n w_{n + m hop} / sum_n w_n^2` between the DFTs
    /// of blocks `m` hops apart for a white input (Welch 1967); empty tail once blocks stop
    /// overlapping. Element 0 is 1.
    pub fn overlap_correlation(self, n: usize, hop: usize) -> Vec<f64> {
        let w = self.samples(n);
        let p: f64 = w.iter().map(|x| x * x).sum();
        let mut rho = vec![1.0];
        let mut m = 1;
        while m * hop < n {
            let s: f64 = (0..n - m * hop).map(|i| w[i] * w[i + m * hop]).sum();
            rho.push(s / p);
            m += 1;
        }
        rho
    }
}

/// Dirichlet kernel `sum_{n<N} exp(-j 2 pi delta n / N)`.
fn dirichlet(n: usize, delta: f64) -> C64 {
    let nf = n as f64;
    let phase = C64::from_polar(1.0, -PI * delta * (nf - 1.0) / nf);
    let den = (PI * delta / nf).sin();
    if den.abs() < 1e-12 {
        // delta a multiple of N: N equal terms exp(-j 2 pi m n) = 1.
        return C64::new(nf, 0.0);
    }
    phase * ((PI * delta).sin() / den)
}

impl Shaker {
    /// Transmitted force per unit shaker force, `T = k_s / (k_s - w^2 m_a + k_s m_a A_dd)`
    /// with `A_dd` the drive-point accelerance (see [`Shaker`] for the derivation).
    pub fn transfer(&self, freq_hz: f64, a_dd: C64) -> C64 {
        let w2 = (2.0 * PI * freq_hz).powi(2);
        let (m, k) = (self.armature_mass_kg, self.stinger_stiffness_n_m);
        C64::new(k, 0.0) / (C64::new(k - w2 * m, 0.0) + k * m * a_dd)
    }
}

/// Stream ids of the seeded substreams (so results do not depend on the thread count).
pub(crate) mod stream {
    pub const FORCE: u64 = 1;
    pub const FORCE_NOISE: u64 = 2;
    pub const RESPONSE_NOISE: u64 = 3;
    pub const FD_LINE: u64 = 4;
}

/// SplitMix64 finaliser: decorrelates nearby seeds.
fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// The generator of substream (`kind`, `index`) of a level seeded with `seed`.
pub(crate) fn substream(seed: u64, kind: u64, index: u64) -> StdRng {
    StdRng::seed_from_u64(mix(mix(mix(seed) ^ kind) ^ index))
}

/// A standard circular complex Gaussian draw: `E|z|^2 = 1`, real and imaginary parts
/// independent with variance 1/2.
pub(crate) fn complex_normal(rng: &mut StdRng) -> C64 {
    let a: f64 = StandardNormal.sample(rng);
    let b: f64 = StandardNormal.sample(rng);
    C64::new(a, b) * std::f64::consts::FRAC_1_SQRT_2
}

/// A standard real Gaussian draw.
pub(crate) fn normal(rng: &mut StdRng) -> f64 {
    StandardNormal.sample(rng)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dtft_matches_direct_sum() {
        for window in [Window::Hann, Window::Rectangular] {
            let n = 64;
            let w = window.samples(n);
            for &d in &[0.0, 0.3, 1.0, -1.0, 2.5, -7.25, 64.0, 13.0] {
                let direct: C64 = w
                    .iter()
                    .enumerate()
                    .map(|(i, wi)| *wi * C64::from_polar(1.0, -2.0 * PI * d * i as f64 / n as f64))
                    .sum();
                let closed = window.dtft(n, d);
                assert!(
                    (direct - closed).norm() < 1e-9 * (1.0 + direct.norm()),
                    "{window:?} d={d}: {direct} vs {closed}"
                );
            }
        }
    }

    #[test]
    fn hann_overlap_correlation_is_one_sixth() {
        let rho = Window::Hann.overlap_correlation(2048, 1024);
        assert_eq!(rho.len(), 2);
        assert!((rho[1] - 1.0 / 6.0).abs() < 1e-3, "{rho:?}");
    }

    #[test]
    fn stiff_stinger_massless_armature_is_ideal_source() {
        let s = Shaker {
            armature_mass_kg: 0.0,
            stinger_stiffness_n_m: 1e6,
        };
        assert!((s.transfer(100.0, C64::new(3.0, -2.0)) - 1.0).norm() < 1e-12);
        // Rigid stinger limit: F = f_s / (1 + m_a A_dd).
        let s = Shaker {
            armature_mass_kg: 0.02,
            stinger_stiffness_n_m: 1e14,
        };
        let a = C64::new(5.0, 4.0);
        assert!((s.transfer(50.0, a) - 1.0 / (1.0 + 0.02 * a)).norm() < 1e-8);
    }
}
