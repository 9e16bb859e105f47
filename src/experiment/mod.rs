//! Virtual experiment: random excitation at a set RMS force, sensor noise, calibration
//! errors, shaker-structure interaction, and the H1 estimator with coherence (the paper's
//! OELF `H'_i2 = S_(a_i f2) / S_(f2 f2)`, 200 averages, 1-500 Hz at 1 Hz; method.md
//! "Measurement").
//!
//! The structure enters only through the [`Plant`] trait (accelerance on arbitrary lines), so
//! the full FE model or a ROM plug in alike; this module knows nothing of either.
//!
//! Two modes ([`Mode`]): [`timedomain`] simulates continuous records and Welch-averages them;
//! [`freqdomain`] draws the block spectra from their exact Gaussian distribution. Both share
//! the expected value `H1_exp(f_k) = int H S_F |W(f - f_k)|^2 df / int S_F |W(f - f_k)|^2 df`
//! (the exact FRF seen through the window's spectral kernel, [`estimator::BandModel::expected`])
//! and its leakage bias `|H1_exp - H| / |H|`, reported per line in the [`Truth`] record.
//!
//! Entry point: [`simulate_level`].

pub mod estimator;
pub mod freqdomain;
pub mod plant;
pub mod signal;
pub mod spec;
pub mod timedomain;

pub use spec::{ChainParams, KernelParams, Mode, NoiseLevel, Shaker, Window};

use crate::common::{Direction, C64};
use crate::data::{Channel, FrfLevel, Quantity};
use estimator::{effective_averages, plant_eval, random_error_h1, BandModel};

/// An error of the virtual experiment: says what is wrong and how to fix it.
#[derive(Debug, thiserror::Error)]
pub enum ExperimentError {
    #[error("invalid measurement-chain setting `{field}`: {message}")]
    InvalidParams { field: String, message: String },
    #[error("line {line_hz} Hz is not a multiple of the line spacing {df_hz} Hz inside the band {band_hz:?} Hz: choose lines k / block_s within the band")]
    LineNotOnGrid {
        line_hz: f64,
        df_hz: f64,
        band_hz: (f64, f64),
    },
    #[error("plant: {0}")]
    Plant(String),
    #[error("{given} channel labels given for {expected} simulated channels: give one label per plant channel")]
    Labels { given: usize, expected: usize },
}

/// The structure as the rig sees it: accelerance (m/s^2/N) at each channel's response for a
/// unit force at the drive point, on arbitrary lines (Hz). Channel order is fixed; one channel
/// is the drive point (its accelerance drives the shaker-structure interaction).
pub trait Plant: Sync {
    fn n_channels(&self) -> usize;
    fn drive_channel(&self) -> usize;
    /// `[channel][line]` accelerance at `freq_hz`, time convention `exp(+j w t)`.
    fn accelerance(&self, freq_hz: &[f64]) -> Result<Vec<Vec<C64>>, ExperimentError>;
}

/// One simulated channel: H1 (accelerance, m/s^2/N) and ordinary coherence per line.
#[derive(Clone, Debug, PartialEq)]
pub struct SimulatedChannel {
    pub values: Vec<C64>,
    pub coherence: Vec<f64>,
}

/// What the simulation knows and the estimate does not, per channel and line.
#[derive(Clone, Debug, PartialEq)]
pub struct ChannelTruth {
    /// The structure's exact accelerance `H(f_k)` (no calibration error).
    pub exact: Vec<C64>,
    /// Window-kernel average of the exact FRF, `int H S_F |W|^2 / int S_F |W|^2`: the expected
    /// H1 of an ideal (noise-free, calibrated) chain.
    pub kernel: Vec<C64>,
    /// What this chain's H1 converges to: kernel average of `g exp(-j w tau) H`, lowered by
    /// force noise, `E[G_fa] / E[G_ff]`.
    pub expected_h1: Vec<C64>,
    /// Expected ordinary coherence `|E G_fa|^2 / (E G_ff E G_aa)` (leakage and noise).
    pub expected_coherence: Vec<f64>,
    /// Leakage bias `|kernel - exact| / |exact|`.
    pub leakage_bias: Vec<f64>,
    /// Bendat & Piersol's normalised random error of `|H1|` for the expected coherence and the
    /// effective number of averages.
    pub random_error: Vec<f64>,
}

/// The truth record of one simulated level (the lead writes it to a sidecar).
#[derive(Clone, Debug, PartialEq)]
pub struct Truth {
    pub freq_hz: Vec<f64>,
    pub mode: Mode,
    pub seed: u64,
    /// Expected RMS of the transmitted (measured) force, N.
    pub force_rms_n: f64,
    /// Expected RMS of the shaker's own force (equal to `force_rms_n` without shaker), N.
    pub shaker_force_rms_n: f64,
    /// Transmitted force per unit shaker force at each line (all 1 without shaker).
    pub force_transfer: Vec<C64>,
    /// Absolute noise RMS on the force (N) and on each response (m/s^2).
    pub force_noise_rms_n: f64,
    pub response_noise_rms: Vec<f64>,
    /// Expected RMS of each measured response signal, m/s^2.
    pub response_rms: Vec<f64>,
    pub n_averages: usize,
    /// Independent-average equivalent of the overlapping blocks (Welch).
    pub effective_averages: f64,
    pub channels: Vec<ChannelTruth>,
}

/// One simulated excitation level.
#[derive(Clone, Debug, PartialEq)]
pub struct SimulatedLevel {
    pub freq_hz: Vec<f64>,
    pub channels: Vec<SimulatedChannel>,
    pub force_rms_n: f64,
    pub n_averages: usize,
    pub truth: Truth,
}

/// Point ids and directions of one channel (attached by the caller).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ChannelLabel {
    pub response_id: u32,
    pub response_dir: Direction,
    pub reference_id: u32,
    pub reference_dir: Direction,
}

impl ChannelLabel {
    /// One label per response point `(id, direction)`, all driven at `reference`.
    pub fn for_responses(
        responses: impl IntoIterator<Item = (u32, Direction)>,
        reference: (u32, Direction),
    ) -> Vec<ChannelLabel> {
        responses
            .into_iter()
            .map(|(id, dir)| ChannelLabel {
                response_id: id,
                response_dir: dir,
                reference_id: reference.0,
                reference_dir: reference.1,
            })
            .collect()
    }
}

impl SimulatedLevel {
    /// The level as measured data (accelerance with coherence, labelled channels).
    pub fn to_frf_level(
        &self,
        name: &str,
        labels: &[ChannelLabel],
    ) -> Result<FrfLevel, ExperimentError> {
        if labels.len() != self.channels.len() {
            return Err(ExperimentError::Labels {
                given: labels.len(),
                expected: self.channels.len(),
            });
        }
        Ok(FrfLevel {
            name: name.to_string(),
            force_rms_n: Some(self.force_rms_n),
            n_averages: u32::try_from(self.n_averages).ok(),
            quantity: Quantity::Accelerance,
            freq_hz: self.freq_hz.clone(),
            channels: self
                .channels
                .iter()
                .zip(labels)
                .map(|(c, l)| Channel {
                    response_id: l.response_id,
                    response_dir: l.response_dir,
                    reference_id: l.reference_id,
                    reference_dir: l.reference_dir,
                    values: c.values.clone(),
                    coherence: Some(c.coherence.clone()),
                    source: None,
                })
                .collect(),
        })
    }
}

fn cjson(v: &[C64]) -> serde_json::Value {
    serde_json::json!({ "re": v.iter().map(|z| z.re).collect::<Vec<_>>(), "im": v.iter().map(|z| z.im).collect::<Vec<_>>() })
}

impl Truth {
    /// JSON form for a sidecar file (complex vectors as `{re: [..], im: [..]}`), labelled simulated.
    pub fn to_json(&self) -> serde_json::Value {
        serde_json::json!({
            "simulated": true,
            "mode": format!("{:?}", self.mode),
            "seed": self.seed,
            "freq_hz": self.freq_hz,
            "force_rms_n": self.force_rms_n,
            "shaker_force_rms_n": self.shaker_force_rms_n,
            "force_transfer": cjson(&self.force_transfer),
            "force_noise_rms_n": self.force_noise_rms_n,
            "response_noise_rms_m_s2": self.response_noise_rms,
            "response_rms_m_s2": self.response_rms,
            "n_averages": self.n_averages,
            "effective_averages": self.effective_averages,
            "channels": self.channels.iter().map(|c| serde_json::json!({
                "exact": cjson(&c.exact),
                "kernel": cjson(&c.kernel),
                "expected_h1": cjson(&c.expected_h1),
                "expected_coherence": c.expected_coherence,
                "leakage_bias": c.leakage_bias,
                "random_error": c.random_error,
            })).collect::<Vec<_>>(),
        })
    }
}

/// Ordinary coherence `|G_fa|^2 / (G_ff G_aa)` of expected block spectra (noise included),
/// at most 1; 0 where a spectrum vanishes.
fn coherence(g_fa: C64, g_ff: f64, g_aa: f64) -> f64 {
    if g_ff * g_aa > 0.0 {
        (g_fa.norm_sqr() / (g_ff * g_aa)).min(1.0)
    } else {
        0.0
    }
}

fn noise_rms(level: NoiseLevel, signal_rms: f64) -> f64 {
    match level {
        NoiseLevel::Rms(x) => x,
        NoiseLevel::FractionOfSignalRms(f) => f * signal_rms,
    }
}

/// The expected-value model on the fine grid of `chain.kernel` (both modes use it for the
/// truth; the frequency-domain mode also draws from it).
pub(crate) fn band_model_fine(
    plant: &dyn Plant,
    chain: &ChainParams,
) -> Result<BandModel, ExperimentError> {
    let (lo, hi) = chain.band_hz;
    let n = ((hi - lo) / chain.kernel.grid_step_hz).ceil().max(1.0) as usize;
    BandModel::build(plant, chain, n)
}

/// [`BandModel::expected`] at DFT bin `k` (frequency `k / block_s`) of the chain's layout.
fn expected_at_bin(
    band: &BandModel,
    chain: &ChainParams,
    layout: &spec::Layout,
    k: usize,
) -> (Vec<Vec<C64>>, Vec<C64>) {
    band.expected(
        k as f64 * (1.0 / chain.block_s),
        chain.window,
        layout.n_block,
        chain.block_s,
        chain.kernel.half_width_hz,
    )
}

/// The H1 estimator's systematic (leakage) error for `plant`, as the identification's model of
/// its own measurement chain: `[channel][line]` of `K_i(f_k) - H_i(f_k)` on `chain.lines_hz`,
/// the window-kernel average `int H S_F |W|^2 / int S_F |W|^2` of the exact accelerance minus
/// the accelerance itself ([`estimator::BandModel::expected`]). The force spectrum is flat over
/// `chain.band_hz`, coloured by `chain.shaker` when given. Noise, gains and delays are not part
/// of it (they are random or calibration errors, not leakage).
pub fn leakage_bias(
    plant: &dyn Plant,
    chain: &ChainParams,
) -> Result<Vec<Vec<C64>>, ExperimentError> {
    let layout = chain.layout(plant.n_channels())?;
    let band = band_model_fine(plant, chain)?;
    let exact = plant_eval(plant, &chain.lines_hz)?;
    let mut out: Vec<Vec<C64>> = vec![Vec::with_capacity(chain.lines_hz.len()); exact.len()];
    for (li, &k) in layout.line_bins.iter().enumerate() {
        let (_, kernel) = expected_at_bin(&band, chain, &layout, k);
        for (i, o) in out.iter_mut().enumerate() {
            o.push(kernel[i] - exact[i][li]);
        }
    }
    Ok(out)
}

/// The frequency points (Hz) of the expected-value model's fine grid for `chain` (where the
/// plant is evaluated): `lo + j (hi - lo) / n`, `n` from `chain.kernel.grid_step_hz`. An engine
/// prepared on these points (as `2 pi f`, the zero excluded) serves the plant exactly.
pub fn band_grid_hz(chain: &ChainParams) -> Vec<f64> {
    let (lo, hi) = chain.band_hz;
    let n = ((hi - lo) / chain.kernel.grid_step_hz).ceil().max(1.0) as usize;
    let step = (hi - lo) / n as f64;
    (0..=n).map(|j| lo + j as f64 * step).collect()
}

/// The expected ordinary coherence `[channel][line]` of the chain on `plant` at
/// `chain.lines_hz`: the truth record's `expected_coherence` of [`simulate_level`] (the same
/// force spectrum, window kernel and sensor noise), without simulating the records. What a test
/// plan predicts for the likelihood's noise scales (`rfmlab design`).
pub fn expected_coherence(
    plant: &dyn Plant,
    chain: &ChainParams,
) -> Result<Vec<Vec<f64>>, ExperimentError> {
    Ok(expected_coherence_at(plant, chain, &[chain.force_rms_n])?.remove(0))
}

/// [`expected_coherence`] at several force levels (N RMS, `[level][channel][line]`), the plant
/// evaluated once: everything else of the chain is `chain`'s.
pub fn expected_coherence_at(
    plant: &dyn Plant,
    chain: &ChainParams,
    force_rms_n: &[f64],
) -> Result<Vec<Vec<Vec<f64>>>, ExperimentError> {
    let layout = chain.layout(plant.n_channels())?;
    let base = band_model_fine(plant, chain)?;
    let p_w = chain.window.power_sum(layout.n_block);
    let mut all = Vec::new();
    for &f_rms in force_rms_n {
        let mut band = base.clone();
        let r = (f_rms / chain.force_rms_n).powi(2);
        band.force_power.iter_mut().for_each(|p| *p *= r);
        let m = band.resp.len();
        let force_noise = noise_rms(chain.force_noise, f_rms);
        let resp_noise: Vec<f64> = (0..m)
            .map(|i| {
                noise_rms(
                    chain.response_noise_of(i),
                    band.response_mean_square(i).sqrt(),
                )
            })
            .collect();
        let mut out = vec![Vec::with_capacity(layout.line_bins.len()); m];
        for &k in &layout.line_bins {
            let (ff, fa, aa) = band.expected_diagonal(
                k as f64 / chain.block_s,
                chain.window,
                layout.n_block,
                chain.block_s,
                chain.kernel.half_width_hz,
            );
            let g_ff = ff + force_noise.powi(2) * p_w;
            for (i, o) in out.iter_mut().enumerate() {
                let g_aa = aa[i] + resp_noise[i].powi(2) * p_w;
                o.push(coherence(fa[i], g_ff, g_aa));
            }
        }
        all.push(out);
    }
    Ok(all)
}

/// Replicates of one level in the frequency-domain mode that differ only in their seed and
/// their sensors' noise: each draw's channels are [`simulate_level`]'s for that chain, bit for
/// bit, but the plant is evaluated and every line's expected block spectra are computed once,
/// and a draw only draws its blocks (the closed loop's null level draws twenty replicates of a
/// fitted model, and the spectra were most of each).
pub struct Replicates {
    /// The chain the replicates share (its seed and noise are each draw's).
    chain: ChainParams,
    layout: spec::Layout,
    band: BandModel,
    expected: Vec<(Vec<Vec<C64>>, Vec<C64>)>,
}

impl Replicates {
    /// The replicates of `chain` (frequency-domain mode) on `plant`.
    pub fn new(plant: &dyn Plant, chain: &ChainParams) -> Result<Replicates, ExperimentError> {
        if chain.mode != Mode::FrequencyDomain {
            return Err(ExperimentError::InvalidParams {
                field: "mode".into(),
                message:
                    "replicates share their expected spectra in the frequency-domain mode only"
                        .into(),
            });
        }
        let layout = chain.layout(plant.n_channels())?;
        let band = band_model_fine(plant, chain)?;
        let expected = freqdomain::line_expectations(&band, chain, &layout);
        Ok(Replicates {
            chain: chain.clone(),
            layout,
            band,
            expected,
        })
    }

    /// The channels of one replicate: [`simulate_level`]`(plant, chain).channels` for `chain`,
    /// which must be the replicates' chain but for its seed and noise.
    pub fn draw(&self, chain: &ChainParams) -> Result<Vec<SimulatedChannel>, ExperimentError> {
        let same = ChainParams {
            seed: self.chain.seed,
            force_noise: self.chain.force_noise,
            response_noise: self.chain.response_noise.clone(),
            ..chain.clone()
        };
        if same != self.chain {
            return Err(ExperimentError::InvalidParams {
                field: "seed".into(),
                message:
                    "a replicate's chain differs from the replicates' in more than its seed and noise"
                        .into(),
            });
        }
        let m = self.band.resp.len();
        let p_w = chain.window.power_sum(self.layout.n_block);
        let force_noise = noise_rms(chain.force_noise, chain.force_rms_n);
        let np: Vec<f64> = (0..m)
            .map(|i| {
                let s = noise_rms(
                    chain.response_noise_of(i),
                    self.band.response_mean_square(i).sqrt(),
                );
                s * s * p_w
            })
            .collect();
        let sums = freqdomain::simulate(
            &self.band,
            &self.expected,
            chain,
            &self.layout,
            (force_noise.powi(2) * p_w, &np),
        );
        Ok(sums
            .iter()
            .map(|s| {
                let (values, coherence) = s.finish();
                SimulatedChannel { values, coherence }
            })
            .collect())
    }
}

/// Simulate one excitation level of the measurement chain on `plant`.
///
/// Returns H1 and coherence per channel on `chain.lines_hz` plus the truth record.
/// Deterministic for a given `chain.seed`, independent of the number of threads.
pub fn simulate_level(
    plant: &dyn Plant,
    chain: &ChainParams,
) -> Result<SimulatedLevel, ExperimentError> {
    let m = plant.n_channels();
    let layout = chain.layout(m)?;
    let band = band_model_fine(plant, chain)?;
    let m = band.resp.len();
    let p_w = chain.window.power_sum(layout.n_block);
    let response_rms: Vec<f64> = (0..m)
        .map(|i| band.response_mean_square(i).sqrt())
        .collect();
    let force_noise = noise_rms(chain.force_noise, chain.force_rms_n);
    let resp_noise: Vec<f64> = (0..m)
        .map(|i| noise_rms(chain.response_noise_of(i), response_rms[i]))
        .collect();
    let n_eff = effective_averages(chain.window, layout.n_block, layout.hop, chain.n_averages);

    // Truth on the lines.
    let exact = plant_eval(plant, &chain.lines_hz)?;
    let force_transfer: Vec<C64> = match chain.shaker {
        Some(s) => chain
            .lines_hz
            .iter()
            .zip(&exact[plant.drive_channel()])
            .map(|(f, a)| s.transfer(*f, *a))
            .collect(),
        None => vec![C64::new(1.0, 0.0); chain.lines_hz.len()],
    };
    let mut channels: Vec<ChannelTruth> = (0..m)
        .map(|i| ChannelTruth {
            exact: exact[i].clone(),
            kernel: Vec::new(),
            expected_h1: Vec::new(),
            expected_coherence: Vec::new(),
            leakage_bias: Vec::new(),
            random_error: Vec::new(),
        })
        .collect();
    // Every line's expected block spectra: the truth's, and the frequency-domain mode's
    // covariances.
    let expected = freqdomain::line_expectations(&band, chain, &layout);
    for (li, (cov, kernel)) in expected.iter().enumerate() {
        let g_ff = cov[0][0].re + force_noise.powi(2) * p_w;
        for (i, c) in channels.iter_mut().enumerate() {
            let g_aa = cov[i + 1][i + 1].re + resp_noise[i].powi(2) * p_w;
            let g_fa = cov[i + 1][0];
            let h = c.exact[li];
            let coh = coherence(g_fa, g_ff, g_aa);
            c.expected_h1.push(if g_ff > 0.0 {
                g_fa / g_ff
            } else {
                C64::new(0.0, 0.0)
            });
            c.leakage_bias.push(if h.norm() > 0.0 {
                (kernel[i] - h).norm() / h.norm()
            } else {
                f64::INFINITY
            });
            c.kernel.push(kernel[i]);
            c.expected_coherence.push(coh);
            c.random_error.push(random_error_h1(coh, n_eff));
        }
    }
    let truth = Truth {
        freq_hz: chain.lines_hz.clone(),
        mode: chain.mode,
        seed: chain.seed,
        force_rms_n: chain.force_rms_n,
        shaker_force_rms_n: band.shaker_force_mean_square().sqrt(),
        force_transfer,
        force_noise_rms_n: force_noise,
        response_noise_rms: resp_noise.clone(),
        response_rms,
        n_averages: chain.n_averages,
        effective_averages: n_eff,
        channels,
    };

    let sums = match chain.mode {
        Mode::TimeDomain => {
            timedomain::simulate(plant, chain, &layout, (force_noise, &resp_noise))?
        }
        Mode::FrequencyDomain => {
            let np: Vec<f64> = resp_noise.iter().map(|s| s * s * p_w).collect();
            freqdomain::simulate(
                &band,
                &expected,
                chain,
                &layout,
                (force_noise.powi(2) * p_w, &np),
            )
        }
    };
    let channels = sums
        .iter()
        .map(|s| {
            let (values, coherence) = s.finish();
            SimulatedChannel { values, coherence }
        })
        .collect();
    Ok(SimulatedLevel {
        freq_hz: chain.lines_hz.clone(),
        channels,
        force_rms_n: chain.force_rms_n,
        n_averages: chain.n_averages,
        truth,
    })
}
