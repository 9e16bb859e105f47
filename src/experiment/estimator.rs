//! The H1 / coherence estimator (Welch averaging), its known random error, and the expected
//! block spectral matrix that both simulation modes share.
//!
//! Conventions: a block DFT `X_k = sum_n w_n x_n exp(-j 2 pi k n / N)`; the averaged spectra
//! `G_ff = sum_b |F_b|^2`, `G_fa = sum_b conj(F_b) A_b`, `G_aa = sum_b |A_b|^2`;
//! `H1 = G_fa / G_ff` (the paper's OELF, `H' = S_af / S_ff`) and the ordinary coherence
//! `gamma^2 = |G_fa|^2 / (G_ff G_aa)` (Bendat & Piersol, *Random Data*, ch. 9).

use super::spec::{ChainParams, Window};
use super::{ExperimentError, Plant};
use crate::common::C64;
use std::f64::consts::PI;

/// Running sums of one channel's auto and cross spectra at the requested lines.
#[derive(Clone, Debug)]
pub struct WelchSums {
    pub g_ff: Vec<f64>,
    pub g_fa: Vec<C64>,
    pub g_aa: Vec<f64>,
}

impl WelchSums {
    pub fn new(n_lines: usize) -> Self {
        WelchSums {
            g_ff: vec![0.0; n_lines],
            g_fa: vec![C64::new(0.0, 0.0); n_lines],
            g_aa: vec![0.0; n_lines],
        }
    }

    /// Add one block's force and response DFT values at line `l`.
    #[inline]
    pub fn add(&mut self, l: usize, f: C64, a: C64) {
        self.g_ff[l] += f.norm_sqr();
        self.g_fa[l] += f.conj() * a;
        self.g_aa[l] += a.norm_sqr();
    }

    /// `(H1, gamma^2)` per line. A line with no force power gives H1 = 0, coherence 0.
    pub fn finish(&self) -> (Vec<C64>, Vec<f64>) {
        let h1 = self
            .g_ff
            .iter()
            .zip(&self.g_fa)
            .map(|(ff, fa)| {
                if *ff > 0.0 {
                    fa / ff
                } else {
                    C64::new(0.0, 0.0)
                }
            })
            .collect();
        let coh = (0..self.g_ff.len())
            .map(|l| {
                let d = self.g_ff[l] * self.g_aa[l];
                if d > 0.0 {
                    (self.g_fa[l].norm_sqr() / d).min(1.0)
                } else {
                    0.0
                }
            })
            .collect();
        (h1, coh)
    }
}

/// Bendat & Piersol's normalised random error of `|H1|` (and, in radians, of its phase):
/// `eps = sqrt(1 - gamma^2) / (|gamma| sqrt(2 n_d))` for `n_d` independent averages.
/// With overlapping blocks use [`effective_averages`] for `n_d`.
pub fn random_error_h1(coherence: f64, n_d: f64) -> f64 {
    let g2 = coherence.clamp(1e-300, 1.0);
    (1.0 - g2).sqrt() / (g2.sqrt() * (2.0 * n_d).sqrt())
}

/// Number of independent averages equivalent to `n` overlapping blocks for a white input
/// (Welch 1967): `n / (1 + 2 sum_m (1 - m/n) rho_m^2)`, with `rho_m` the window's overlap
/// correlation ([`Window::overlap_correlation`]). Hann, 50 %: `n / 1.056`.
pub fn effective_averages(window: Window, n_block: usize, hop: usize, n: usize) -> f64 {
    let rho = window.overlap_correlation(n_block, hop);
    let nf = n as f64;
    let s: f64 = rho
        .iter()
        .enumerate()
        .skip(1)
        .filter(|(m, _)| *m < n)
        .map(|(m, r)| (1.0 - m as f64 / nf) * r * r)
        .sum();
    nf / (1.0 + 2.0 * s)
}

/// The structure and force on a set of in-band frequency points with quadrature weights:
/// enough to evaluate every expected block spectrum at any line (see [`BandModel::expected`]).
#[derive(Clone, Debug)]
pub(crate) struct BandModel {
    pub freq_hz: Vec<f64>,
    /// `S_F(f_j) w_j`: two-sided PSD of the transmitted force (N^2/Hz) times the quadrature
    /// weight (Hz): the expected power `E|c_j|^2` of the line's complex amplitude.
    pub force_power: Vec<f64>,
    /// Shaker force per unit transmitted force is not needed; this is the transmitted force
    /// per unit shaker force `T(f_j)` (1 without shaker), kept for the truth record.
    pub transfer: Vec<C64>,
    /// Structure accelerance `H_i(f_j)`, `[channel][point]`.
    pub plain: Vec<Vec<C64>>,
    /// Measured response per unit transmitted force `g_i exp(-j w tau_i) H_i(f_j)`.
    pub resp: Vec<Vec<C64>>,
    /// First point and step of the uniform grid.
    pub f0: f64,
    pub step: f64,
}

impl BandModel {
    /// Evaluate the plant on `n + 1` uniform points `lo + j (hi - lo)/n` with trapezoid
    /// weights, and scale the flat shaker-force PSD so that the transmitted force has the
    /// expected RMS `chain.force_rms_n`: `2 sum_j S_F(f_j) w_j = F_rms^2`.
    pub fn build(
        plant: &dyn Plant,
        chain: &ChainParams,
        n: usize,
    ) -> Result<Self, ExperimentError> {
        let (lo, hi) = chain.band_hz;
        let step = (hi - lo) / n as f64;
        let freq_hz: Vec<f64> = (0..=n).map(|j| lo + j as f64 * step).collect();
        let plain = plant_eval(plant, &freq_hz)?;
        let d = plant.drive_channel();
        let transfer: Vec<C64> = match chain.shaker {
            None => vec![C64::new(1.0, 0.0); freq_hz.len()],
            Some(s) => freq_hz
                .iter()
                .zip(&plain[d])
                .map(|(f, a)| s.transfer(*f, *a))
                .collect(),
        };
        if transfer
            .iter()
            .any(|t| !(t.re.is_finite() && t.im.is_finite()))
        {
            return Err(ExperimentError::Plant("the shaker-structure transfer is singular or not finite: check armature mass and stinger stiffness".into()));
        }
        let mut force_power: Vec<f64> = transfer.iter().map(|t| t.norm_sqr() * step).collect();
        force_power[0] *= 0.5;
        force_power[n] *= 0.5;
        let total: f64 = 2.0 * force_power.iter().sum::<f64>();
        if total.is_nan() || total <= 0.0 {
            return Err(ExperimentError::Plant(
                "no force reaches the structure in the band".into(),
            ));
        }
        let scale = chain.force_rms_n.powi(2) / total;
        force_power.iter_mut().for_each(|p| *p *= scale);
        let resp = (0..plain.len())
            .map(|i| {
                let (g, tau) = (chain.gain(i), chain.delay_s(i));
                freq_hz
                    .iter()
                    .zip(&plain[i])
                    .map(|(f, h)| g * C64::from_polar(1.0, -2.0 * PI * f * tau) * h)
                    .collect()
            })
            .collect();
        Ok(BandModel {
            freq_hz,
            force_power,
            transfer,
            plain,
            resp,
            f0: lo,
            step,
        })
    }

    /// Expected mean square of channel `i`'s measured (calibrated) response: `2 sum_j |r_ij|^2 E|c_j|^2`.
    pub fn response_mean_square(&self, i: usize) -> f64 {
        2.0 * self.resp[i]
            .iter()
            .zip(&self.force_power)
            .map(|(r, p)| r.norm_sqr() * p)
            .sum::<f64>()
    }

    /// Mean square of the shaker's own force (N^2) for this transmitted-force level.
    pub fn shaker_force_mean_square(&self) -> f64 {
        2.0 * self
            .force_power
            .iter()
            .zip(&self.transfer)
            .map(|(p, t)| p / t.norm_sqr())
            .sum::<f64>()
    }

    /// Every fine-grid point within `half_width_hz` of line `f_k`, and the mirror images at
    /// `-f_j` of those within it of `-f_k`, with its weight `E|c_j|^2 |W(delta T)|^2` (zero
    /// weights skipped): `visit(j, weight, mirror)`. The sums of [`BandModel::expected`] and
    /// [`BandModel::expected_diagonal`] run over these.
    fn kernel_points(
        &self,
        f_k: f64,
        window: Window,
        n_block: usize,
        block_s: f64,
        half_width_hz: f64,
        mut visit: impl FnMut(usize, f64, bool),
    ) {
        let last = self.freq_hz.len() - 1;
        let idx = |f: f64| (f - self.f0) / self.step;
        let mut add = |j: usize, delta: f64, mirror: bool| {
            let k2 = window.dtft(n_block, delta).norm_sqr() * self.force_power[j];
            if k2 != 0.0 {
                visit(j, k2, mirror);
            }
        };
        let j0 = idx(f_k - half_width_hz).ceil().max(0.0) as usize;
        let j1 = idx(f_k + half_width_hz).floor().min(last as f64);
        if j1 >= 0.0 {
            for j in j0..=(j1 as usize) {
                add(j, (f_k - self.freq_hz[j]) * block_s, false);
            }
        }
        let jm = idx(half_width_hz - f_k).floor().min(last as f64);
        if jm >= 0.0 {
            for j in 0..=(jm as usize) {
                add(j, (f_k + self.freq_hz[j]) * block_s, true);
            }
        }
    }

    /// Expected block spectral matrix at line `f_k` of the vector `(F, A_0, .., A_{m-1})`
    /// (signal part only, noise excluded), `cov[a][b] = E[v_a conj(v_b)]`, and the
    /// window-kernel average of the plain FRF, `K_i = sum H_i S_F |W|^2 / sum S_F |W|^2`:
    /// `E[v_a conj(v_b)] = sum_j E|c_j|^2 r_aj conj(r_bj) |W((f_k - f_j) T)|^2` over the points
    /// within `half_width_hz` of `f_k`, plus their mirror images at `-f_j` (where
    /// `r(-f) = conj(r(f))`): the negative-frequency half of a real signal leaks too.
    pub fn expected(
        &self,
        f_k: f64,
        window: Window,
        n_block: usize,
        block_s: f64,
        half_width_hz: f64,
    ) -> (Vec<Vec<C64>>, Vec<C64>) {
        let m = self.resp.len();
        let mut cov = vec![vec![C64::new(0.0, 0.0); m + 1]; m + 1];
        let mut kern_num = vec![C64::new(0.0, 0.0); m];
        let add = |j: usize, k2: f64, mirror: bool| {
            let r = |i: usize| {
                if mirror {
                    self.resp[i][j].conj()
                } else {
                    self.resp[i][j]
                }
            };
            cov[0][0] += k2;
            for a in 0..m {
                let ra = r(a);
                cov[a + 1][0] += ra * k2;
                let h = if mirror {
                    self.plain[a][j].conj()
                } else {
                    self.plain[a][j]
                };
                kern_num[a] += h * k2;
                for b in 0..=a {
                    cov[a + 1][b + 1] += ra * r(b).conj() * k2;
                }
            }
        };
        self.kernel_points(f_k, window, n_block, block_s, half_width_hz, add);
        // Hermitian fill of the upper triangle (index pairs (a, b) and (b, a)).
        #[allow(clippy::needless_range_loop)]
        for a in 0..=m {
            for b in a + 1..=m {
                cov[a][b] = cov[b][a].conj();
            }
        }
        let p = cov[0][0].re;
        let kernel = kern_num
            .iter()
            .map(|k| if p > 0.0 { k / p } else { C64::new(0.0, 0.0) })
            .collect();
        (cov, kernel)
    }

    /// The diagonal and force column of [`BandModel::expected`] at line `f_k`: `E|F|^2`,
    /// `E[A_i conj(F)]` and `E|A_i|^2` per channel (signal part only), in O(channels) per
    /// frequency point instead of O(channels^2): what the expected coherence needs.
    pub fn expected_diagonal(
        &self,
        f_k: f64,
        window: Window,
        n_block: usize,
        block_s: f64,
        half_width_hz: f64,
    ) -> (f64, Vec<C64>, Vec<f64>) {
        let m = self.resp.len();
        let (mut ff, mut fa, mut aa) = (0.0, vec![C64::new(0.0, 0.0); m], vec![0.0; m]);
        let add = |j: usize, k2: f64, mirror: bool| {
            ff += k2;
            for a in 0..m {
                let r = self.resp[a][j];
                fa[a] += if mirror { r.conj() } else { r } * k2;
                aa[a] += r.norm_sqr() * k2;
            }
        };
        self.kernel_points(f_k, window, n_block, block_s, half_width_hz, add);
        (ff, fa, aa)
    }
}

/// Call the plant and check the shape and finiteness of what it returns.
pub(crate) fn plant_eval(
    plant: &dyn Plant,
    freq_hz: &[f64],
) -> Result<Vec<Vec<C64>>, ExperimentError> {
    let m = plant.n_channels();
    if m == 0 || plant.drive_channel() >= m {
        return Err(ExperimentError::Plant(format!(
            "plant has {m} channels and drive channel {}: need a drive channel among the channels",
            plant.drive_channel()
        )));
    }
    let h = plant.accelerance(freq_hz)?;
    if h.len() != m || h.iter().any(|c| c.len() != freq_hz.len()) {
        return Err(ExperimentError::Plant(format!(
            "plant returned {} channels of lengths {:?} for {m} channels x {} lines",
            h.len(),
            h.iter().map(Vec::len).collect::<Vec<_>>(),
            freq_hz.len()
        )));
    }
    if let Some((i, l)) = h.iter().enumerate().find_map(|(i, c)| {
        c.iter()
            .position(|v| !(v.re.is_finite() && v.im.is_finite()))
            .map(|l| (i, l))
    }) {
        return Err(ExperimentError::Plant(format!(
            "plant accelerance is not finite at channel {i}, {} Hz",
            freq_hz[l]
        )));
    }
    Ok(h)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn random_error_formula_values() {
        // gamma^2 = 0.8, n_d = 100: sqrt(0.2)/(sqrt(0.8) sqrt(200)) = 0.035355
        assert!((random_error_h1(0.8, 100.0) - 0.035355339).abs() < 1e-8);
        assert_eq!(random_error_h1(1.0, 10.0), 0.0);
    }

    #[test]
    fn hann_half_overlap_effective_averages() {
        let n = effective_averages(Window::Hann, 2048, 1024, 200);
        assert!((200.0 / n - 1.0555).abs() < 2e-3, "{n}");
        assert!((effective_averages(Window::Rectangular, 64, 64, 50) - 50.0).abs() < 1e-12);
    }
}
