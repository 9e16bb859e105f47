//! The measurement chain's settings ([`ChainParams`]) with documented defaults, and their checks.

use super::ExperimentError;
use crate::common::C64;

/// Data window applied to each block before its DFT.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Window {
    /// Periodic (DFT-even) Hann window `w_n = 0.5 - 0.5 cos(2 pi n / N)`, the analyser default
    /// for random excitation.
    Hann,
    /// Rectangular (no) window, `w_n = 1`.
    Rectangular,
}

/// A window name that is neither `"hann"` nor `"rectangular"`.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("\"{0}\": use \"hann\" or \"rectangular\"")]
pub struct UnknownWindow(pub String);

impl std::str::FromStr for Window {
    type Err = UnknownWindow;
    /// `"hann"` or `"rectangular"`; the error says which names exist.
    fn from_str(s: &str) -> Result<Self, UnknownWindow> {
        match s {
            "hann" => Ok(Window::Hann),
            "rectangular" => Ok(Window::Rectangular),
            o => Err(UnknownWindow(o.to_string())),
        }
    }
}

/// How the chain is simulated.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    /// Continuous force and response records, sensor noise added sample by sample,
    /// Welch-averaged: see [`super::timedomain`].
    TimeDomain,
    /// Block spectra drawn directly from their Gaussian distribution (exact second-order
    /// statistics of the time-domain chain): see [`super::freqdomain`].
    FrequencyDomain,
}

/// A sensor-noise level: white Gaussian noise over 0..fs/2 added to the sampled signal.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum NoiseLevel {
    /// RMS of the noise in the channel's unit (N for force, m/s^2 for responses).
    Rms(f64),
    /// RMS of the noise as a fraction of the expected RMS of the (calibrated) signal of
    /// that channel over the excitation band.
    FractionOfSignalRms(f64),
}

impl Default for NoiseLevel {
    fn default() -> Self {
        NoiseLevel::Rms(0.0)
    }
}

/// Shaker armature and stinger at the drive point.
///
/// With `f_s` the electromagnetic force on the armature (mass `m_a`), `k_s` the stinger
/// stiffness and `H_dd` the drive-point receptance, the force transmitted into the structure is
/// `F = f_s k_s / (k_s - w^2 m_a (1 + k_s H_dd))`; with the accelerance `A_dd = -w^2 H_dd`
/// this is `F = f_s k_s / (k_s - w^2 m_a + k_s m_a A_dd)` (armature: `-w^2 m_a x_a = f_s - F`,
/// stinger: `F = k_s (x_a - x_d)`, structure: `x_d = H_dd F`). The measured force is the
/// transmitted one, so H1 still estimates the structure's FRF, but the force spectrum (and
/// with it the SNR) drops at the structure's resonances.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Shaker {
    pub armature_mass_kg: f64,
    pub stinger_stiffness_n_m: f64,
}

/// Knobs of the expected-value quadrature (both modes use it for the truth record; the
/// frequency-domain mode also for the spectral covariances it draws from).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct KernelParams {
    /// Step (Hz) of the fine grid on which the plant is evaluated inside the band.
    /// Default 1/32 Hz (32 points per 1 Hz line spacing).
    pub grid_step_hz: f64,
    /// Half width (Hz) of the window's spectral kernel `|W(f - f_k)|^2` kept around each
    /// line. Default 12 Hz: the Hann kernel falls as `delta^-6`, so the dropped tail is
    /// below 1e-8 of its integral.
    pub half_width_hz: f64,
}

impl Default for KernelParams {
    fn default() -> Self {
        KernelParams {
            grid_step_hz: 1.0 / 32.0,
            half_width_hz: 12.0,
        }
    }
}

/// One excitation level's measurement chain.
#[derive(Clone, Debug, PartialEq)]
pub struct ChainParams {
    /// Expected RMS (N) of the force transmitted to the structure (the measured force).
    /// Default 3.3 N (the paper's Level 1; Level 2 is 46.2 N).
    pub force_rms_n: f64,
    /// Excitation band (Hz), flat shaker-force spectrum inside, nothing outside. Default (1, 500).
    /// `lo = 0` is a baseband source, the open band `(0, hi]`: no DC, but the force just above
    /// DC and its negative-frequency mirror leak into the lowest lines (the time-domain mode
    /// leaves the DC bin empty; the expected-value quadrature integrates through 0 Hz).
    pub band_hz: (f64, f64),
    /// Sampling rate (Hz). Default 2048.
    pub fs_hz: f64,
    /// Block length (s); the line spacing is `1 / block_s`. Default 1 s.
    pub block_s: f64,
    /// Fraction of overlap between consecutive blocks, in [0, 1). Default 0.5.
    pub overlap: f64,
    /// Number of averaged blocks. Default 200.
    pub n_averages: usize,
    /// Default [`Window::Hann`].
    pub window: Window,
    /// Noise on the force sensor. Default none.
    pub force_noise: NoiseLevel,
    /// Noise on the response sensors: empty = none, one entry = for all channels, otherwise
    /// one per channel. Default empty.
    pub response_noise: Vec<NoiseLevel>,
    /// Complex calibration factor per response channel (empty = all 1). Default empty.
    pub gains: Vec<C64>,
    /// Delay (s) per response channel (empty = all 0), applied as `exp(-j w tau)`. Default empty.
    pub delays_s: Vec<f64>,
    /// Shaker-structure interaction at the drive point. Default none (ideal force source).
    pub shaker: Option<Shaker>,
    /// Lines (Hz) on which H1 and coherence are reported; each must be a multiple of
    /// `1 / block_s` inside the band. Default 1, 2, ..., 500 Hz.
    pub lines_hz: Vec<f64>,
    /// Seed of the level (substreams are derived from it). Default 0.
    pub seed: u64,
    /// Default [`Mode::TimeDomain`].
    pub mode: Mode,
    /// Default [`KernelParams::default`].
    pub kernel: KernelParams,
}

impl Default for ChainParams {
    fn default() -> Self {
        ChainParams {
            force_rms_n: 3.3,
            band_hz: (1.0, 500.0),
            fs_hz: 2048.0,
            block_s: 1.0,
            overlap: 0.5,
            n_averages: 200,
            window: Window::Hann,
            force_noise: NoiseLevel::default(),
            response_noise: Vec::new(),
            gains: Vec::new(),
            delays_s: Vec::new(),
            shaker: None,
            lines_hz: (1..=500).map(|k| k as f64).collect(),
            seed: 0,
            mode: Mode::TimeDomain,
            kernel: KernelParams::default(),
        }
    }
}

/// Derived sizes of a checked chain.
#[derive(Clone, Debug)]
pub(crate) struct Layout {
    /// Samples per block.
    pub n_block: usize,
    /// Samples between block starts.
    pub hop: usize,
    /// DFT bin of each requested line in a block.
    pub line_bins: Vec<usize>,
}

fn bad(field: &str, message: String) -> ExperimentError {
    ExperimentError::InvalidParams {
        field: field.to_string(),
        message,
    }
}

impl ChainParams {
    /// Check the settings against each other and a plant with `n_channels` channels.
    pub(crate) fn layout(&self, n_channels: usize) -> Result<Layout, ExperimentError> {
        let pos = |x: f64| x.is_finite() && x > 0.0;
        if !(self.force_rms_n.is_finite() && self.force_rms_n >= 0.0) {
            return Err(bad(
                "force_rms_n",
                format!(
                    "{} is not a finite non-negative RMS force (N)",
                    self.force_rms_n
                ),
            ));
        }
        if !pos(self.fs_hz) || !pos(self.block_s) {
            return Err(bad(
                "fs_hz/block_s",
                format!(
                    "fs_hz = {} and block_s = {} must be positive",
                    self.fs_hz, self.block_s
                ),
            ));
        }
        let nb = self.fs_hz * self.block_s;
        let n_block = nb.round() as usize;
        if (nb - n_block as f64).abs() > 1e-9 * nb || n_block < 4 {
            return Err(bad(
                "block_s",
                format!("fs_hz * block_s = {nb} must be an integer number of samples (>= 4)"),
            ));
        }
        if !(0.0..1.0).contains(&self.overlap) {
            return Err(bad(
                "overlap",
                format!("{} must be in [0, 1) (0.5 = 50 %)", self.overlap),
            ));
        }
        let hop = ((1.0 - self.overlap) * n_block as f64).round() as usize;
        if hop == 0 {
            return Err(bad(
                "overlap",
                format!(
                    "{} leaves no step between blocks of {n_block} samples",
                    self.overlap
                ),
            ));
        }
        if self.n_averages == 0 {
            return Err(bad("n_averages", "must be at least 1".into()));
        }
        let (lo, hi) = self.band_hz;
        if !(lo.is_finite() && hi.is_finite() && lo >= 0.0 && hi > lo && hi < 0.5 * self.fs_hz) {
            return Err(bad(
                "band_hz",
                format!(
                    "({lo}, {hi}) must satisfy 0 <= lo < hi < fs/2 = {} Hz",
                    0.5 * self.fs_hz
                ),
            ));
        }
        let df = 1.0 / self.block_s;
        if [lo, hi]
            .iter()
            .any(|e| (e / df - (e / df).round()).abs() > 1e-6)
        {
            return Err(bad(
                "band_hz",
                format!(
                    "edges ({lo}, {hi}) must be multiples of the line spacing 1/block_s = {df} Hz"
                ),
            ));
        }
        let mut line_bins = Vec::with_capacity(self.lines_hz.len());
        for &f in &self.lines_hz {
            let k = (f / df).round();
            if !f.is_finite()
                || (f / df - k).abs() > 1e-6
                || f < lo - 1e-9
                || f > hi + 1e-9
                || k < 1.0
            {
                return Err(ExperimentError::LineNotOnGrid {
                    line_hz: f,
                    df_hz: df,
                    band_hz: self.band_hz,
                });
            }
            line_bins.push(k as usize);
        }
        if line_bins.is_empty() {
            return Err(bad("lines_hz", "no lines requested".into()));
        }
        if line_bins.windows(2).any(|w| w[1] <= w[0]) {
            return Err(bad("lines_hz", "lines must be strictly increasing".into()));
        }
        let per_ch = |len: usize, field: &str| -> Result<(), ExperimentError> {
            if len > 1 && len != n_channels {
                Err(bad(field, format!("has {len} entries; give none, one for all, or one per channel ({n_channels})")))
            } else {
                Ok(())
            }
        };
        per_ch(self.response_noise.len(), "response_noise")?;
        if !self.gains.is_empty() && self.gains.len() != n_channels {
            return Err(bad(
                "gains",
                format!(
                    "has {} entries; give none or one per channel ({n_channels})",
                    self.gains.len()
                ),
            ));
        }
        if !self.delays_s.is_empty() && self.delays_s.len() != n_channels {
            return Err(bad(
                "delays_s",
                format!(
                    "has {} entries; give none or one per channel ({n_channels})",
                    self.delays_s.len()
                ),
            ));
        }
        if self
            .gains
            .iter()
            .any(|g| !(g.re.is_finite() && g.im.is_finite()))
            || self.delays_s.iter().any(|d| !d.is_finite())
        {
            return Err(bad("gains/delays_s", "contain a non-finite value".into()));
        }
        let noise_ok = |n: &NoiseLevel| match *n {
            NoiseLevel::Rms(x) | NoiseLevel::FractionOfSignalRms(x) => x.is_finite() && x >= 0.0,
        };
        if !noise_ok(&self.force_noise) || !self.response_noise.iter().all(noise_ok) {
            return Err(bad(
                "noise",
                "noise levels must be finite and non-negative".into(),
            ));
        }
        if let Some(s) = self.shaker {
            if !(s.armature_mass_kg.is_finite()
                && s.armature_mass_kg >= 0.0
                && pos(s.stinger_stiffness_n_m))
            {
                return Err(bad(
                    "shaker",
                    format!(
                        "armature mass {} kg must be >= 0 and stinger stiffness {} N/m > 0",
                        s.armature_mass_kg, s.stinger_stiffness_n_m
                    ),
                ));
            }
        }
        let k = self.kernel;
        if !pos(k.grid_step_hz) || !pos(k.half_width_hz) || k.grid_step_hz > 0.25 * df {
            return Err(bad("kernel", format!("grid_step_hz = {} must be positive and <= df/4 = {}; half_width_hz = {} positive", k.grid_step_hz, 0.25 * df, k.half_width_hz)));
        }
        Ok(Layout {
            n_block,
            hop,
            line_bins,
        })
    }

    /// Gain of channel `i` (1 if none given).
    pub(crate) fn gain(&self, i: usize) -> C64 {
        self.gains.get(i).copied().unwrap_or(C64::new(1.0, 0.0))
    }
    /// Delay (s) of channel `i` (0 if none given).
    pub(crate) fn delay_s(&self, i: usize) -> f64 {
        self.delays_s.get(i).copied().unwrap_or(0.0)
    }
    /// Noise level of response channel `i`.
    pub(crate) fn response_noise_of(&self, i: usize) -> NoiseLevel {
        match self.response_noise.len() {
            0 => NoiseLevel::Rms(0.0),
            1 => self.response_noise[0],
            _ => self.response_noise[i],
        }
    }
}
