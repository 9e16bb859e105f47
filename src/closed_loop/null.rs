//! The null level of the residual statistic, calibrated on the same measurement chain.
//!
//! "Consistent with noise" is not a fixed normalised chi-square of 1: the coherence-based
//! noise model floors `1 - g^2`, a Welch H1 leaks the same off-line force into every channel
//! and the measurement model of that leakage is itself approximate, so data of a correct
//! model read well below 1 (about 0.46 on independent Welch data) and a threshold of 1 or
//! 1.2 lets a residual twice the noise pass. The null level is therefore simulated: the
//! fitted model (law and effects at the MAP) is the plant of replicate experiments through
//! the declared estimator, and each replicate's statistic is computed exactly as the data's,
//!
//! ```text
//!   q_r = sum_o |X_r,o - E[H1]_o(p_hat)|^2 / v_r,o / (2 N - k)
//! ```
//!
//! with `X_r` the replicate's H1, `v_r` the noise model's variances from the replicate's own
//! coherence and `E[H1](p_hat)` the fitted model's prediction through its measurement model
//! (no refit per replicate: a refit would lower `q_r` by about `k / (2 N)`, so the level is
//! conservative by that much, 0.1 % for 4 parameters on 2000 values).
//!
//! * With an estimator (`Chain::Welch`): the replicates are the virtual experiment's
//!   frequency-domain mode ([`crate::experiment::simulate_level`], block spectra drawn with the
//!   exact second-order statistics of the overlapped, windowed Welch chain, leakage included;
//!   drawn as [`crate::experiment::Replicates`], the expected spectra computed once),
//!   force band, window, block, rate and number of blocks as declared. The response sensors'
//!   noise is not declared; it is read from the data's coherence: a trial replicate with noise
//!   `s_0` per channel gives `(1 - g^2) / g^2` per line, proportional to the noise power, and
//!   `s_k = s_0 sqrt(median_l [(1 - g_d^2) / g_d^2] / [(1 - g_t^2) / g_t^2])`.
//! * Without one (`Chain::NoiseModel`): each replicate is the fitted prediction plus circular
//!   complex Gaussian noise of the noise model's variances (the analytic null of the noise
//!   model itself).
//!
//! The threshold is `mean + z_(1 - alpha) sd` of the replicates' statistic (a sum over
//! thousands of values: near normal), `alpha` the stated false-alarm rate; the count of
//! replicates above it is reported beside it.

use crate::common::C64;
use crate::experiment::{ChainParams, ExperimentError, Mode, NoiseLevel, Plant, Replicates};
use crate::forward::{ForwardError, ForwardModel, Observation};
use crate::inference::likelihood::{FrfData, FrfLikelihood, FrfPosterior};
use rand::SeedableRng;

/// Settings of the calibration.
#[derive(Clone, Debug, PartialEq)]
pub struct NullParams {
    /// Replicate experiments. Default 20.
    pub replicates: usize,
    /// False-alarm rate of the threshold (a null level read as "not consistent with noise").
    /// Default 0.01.
    pub false_alarm: f64,
    /// Seed of the replicates (each replicate its own stream). Default 0.
    pub seed: u64,
}

impl Default for NullParams {
    fn default() -> Self {
        NullParams {
            replicates: 20,
            false_alarm: 0.01,
            seed: 0,
        }
    }
}

/// The measurement chain of the replicates.
#[derive(Clone, Debug)]
pub enum Chain {
    /// A Welch H1 estimator: window, block, rate, force band, number of blocks and force RMS
    /// as declared (`lines_hz` must be the data's lines); response noise from the coherence.
    Welch(Box<ChainParams>),
    /// The noise model's own Gaussian errors around the fitted prediction.
    NoiseModel,
}

/// The calibrated null level.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct NullCalibration {
    /// How the replicates were made, in words.
    pub method: String,
    /// Normalised chi-square of each replicate.
    pub replicates: Vec<f64>,
    /// Per channel (mean over replicates) of the channel's normalised chi-square.
    pub channel_mean: Vec<f64>,
    pub mean: f64,
    pub sd: f64,
    /// `mean + z_(1 - false_alarm) sd`.
    pub threshold: f64,
    pub false_alarm: f64,
    /// Replicates above the threshold.
    pub exceed: usize,
    /// Response-noise RMS (m/s^2) per channel read from the coherence (Welch chain only).
    pub response_noise_rms: Vec<f64>,
    /// Wall time (s).
    pub seconds: f64,
}

/// Errors of the calibration.
#[derive(Debug, Clone, thiserror::Error)]
pub enum NullError {
    #[error("forward model: {0}")]
    Forward(#[from] ForwardError),
    #[error("replicate experiment: {0}")]
    Experiment(String),
    #[error("replicate data: {0}")]
    Data(String),
}

impl From<ExperimentError> for NullError {
    fn from(e: ExperimentError) -> Self {
        NullError::Experiment(e.to_string())
    }
}

/// The fitted model (law and effects at `p`, no measurement model) as a rig's plant. Every
/// replicate asks for the same grids (the force band's and the lines'), so each grid's answer
/// is kept: a single kept grid was evicted by the other one, and every replicate paid two
/// sweeps of the fine grids (most of the calibration's time with a term ROM).
struct ModelPlant<'m, 'a> {
    fm: &'m ForwardModel<'a>,
    p: Vec<f64>,
    drive: usize,
    /// Accelerances `[channel][line]` by grid (Hz); the simulation asks for two.
    cache: crate::common::Recent<Vec<f64>, Vec<Vec<C64>>, 4>,
}

impl Plant for ModelPlant<'_, '_> {
    fn n_channels(&self) -> usize {
        self.fm.n_out()
    }
    fn drive_channel(&self) -> usize {
        self.drive
    }
    fn accelerance(&self, freq_hz: &[f64]) -> Result<Vec<Vec<C64>>, ExperimentError> {
        self.cache
            .get_or_try(freq_hz.to_vec(), || self.evaluate(freq_hz))
    }
}

impl ModelPlant<'_, '_> {
    fn evaluate(&self, freq_hz: &[f64]) -> Result<Vec<Vec<C64>>, ExperimentError> {
        let fail = |e: ForwardError| ExperimentError::Plant(e.to_string());
        let omega: Vec<f64> = freq_hz.iter().map(|f| f * std::f64::consts::TAU).collect();
        let n = self.fm.n_out();
        let mut out = vec![Vec::with_capacity(freq_hz.len()); n];
        // In chunks: the engine's sweep holds every line's receptances at once.
        for chunk in omega.chunks(2048) {
            let obs = Observation::new(
                self.fm.obs.engine,
                chunk,
                self.fm.obs.input,
                &self.fm.obs.outputs,
                None,
            )
            .map_err(fail)?;
            let mut m = ForwardModel {
                obs,
                law: self.fm.law,
                linear_bias: None,
                effects: Default::default(),
            };
            m.set_effects(self.fm.effects.clone()).map_err(fail)?;
            let pred = m.predict(&self.p, false).map_err(fail)?;
            for (i, v) in pred.values.iter().enumerate() {
                out[i % n].push(*v);
            }
        }
        Ok(out)
    }
}

/// `(1 - g^2) / g^2` per value (coherence clamped to (1e-12, 1)).
fn noise_ratio(g2: f64) -> f64 {
    let g = g2.clamp(1e-12, 1.0);
    (1.0 - g) / g
}

/// The median of `v` (NaN when empty).
fn median(mut v: Vec<f64>) -> f64 {
    v.retain(|x| x.is_finite());
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let m = v.len() / 2;
    if v.len() % 2 == 1 {
        v[m]
    } else {
        0.5 * (v[m - 1] + v[m])
    }
}

/// Normalised chi-square (total, per channel) of `x` against `pred` under the noise model of
/// `post` with the coherence `coherence` (the replicate's own), noise coordinates `noise`.
fn statistic(
    post: &FrfPosterior<'_>,
    x: Vec<C64>,
    coherence: Option<Vec<f64>>,
    pred: &[C64],
    noise: &[f64],
    ids: &[u32],
) -> Result<(f64, Vec<f64>), NullError> {
    let lik = &post.likelihood;
    let fm = &lik.forward;
    let obs = Observation::new(
        fm.obs.engine,
        &fm.obs.omega_rad_s,
        fm.obs.input,
        &fm.obs.outputs,
        fm.obs.measurement.clone(),
    )?;
    let copy = ForwardModel {
        obs,
        law: fm.law,
        linear_bias: None,
        effects: Default::default(),
    };
    let data = FrfData {
        freq_hz: lik.data.freq_hz.clone(),
        n_out: lik.data.n_out,
        values: x,
        coherence,
    };
    let rep = FrfLikelihood::new(copy, data, lik.noise.clone(), ids)
        .map_err(|e| NullError::Data(e.to_string()))?;
    let v = rep.variances(noise);
    let n = lik.data.n_out;
    let nl = lik.data.freq_hz.len();
    let mut per = vec![0.0; n];
    let mut total = 0.0;
    for (o, ((x, h), v)) in rep.data.values.iter().zip(pred).zip(&v).enumerate() {
        let q = (x - h).norm_sqr() / v;
        total += q;
        per[o % n] += q;
    }
    let dof = (2 * n * nl) as f64 - post.names.len() as f64;
    Ok((
        total / dof,
        per.iter().map(|q| q / (2 * nl) as f64).collect(),
    ))
}

/// Calibrate the null level of the normalised chi-square at the fit `phys` (law and free
/// effects, then noise coordinates) of `post`, replicates made through `chain`; `ids` name the
/// channels.
pub fn calibrate(
    post: &FrfPosterior<'_>,
    phys: &[f64],
    chain: &Chain,
    ids: &[u32],
    params: &NullParams,
) -> Result<NullCalibration, NullError> {
    let t0 = std::time::Instant::now();
    let lik = &post.likelihood;
    let fm = &lik.forward;
    let np = fm.n_params();
    let n = lik.data.n_out;
    let pred = fm.predict(&phys[..np], false)?.values;
    let noise = &phys[np..];
    let mut reps = Vec::with_capacity(params.replicates);
    let mut per_channel = vec![0.0; n];
    let (method, noise_rms) = match chain {
        Chain::Welch(chain) => {
            let drive = fm
                .obs
                .outputs
                .iter()
                .position(|&o| o == fm.obs.input)
                .unwrap_or(0);
            let plant = ModelPlant {
                fm,
                p: phys[..np].to_vec(),
                drive,
                cache: Default::default(),
            };
            let Some(coh_data) = &lik.data.coherence else {
                return Err(NullError::Data(
                    "a Welch chain's null level reads the sensor noise from the coherence, and the data have none".into(),
                ));
            };
            // Trial replicate: the noise power per channel from the coherence ratio.
            let s0 = 1e-3;
            let mut c = chain.clone();
            c.mode = Mode::FrequencyDomain;
            c.force_noise = NoiseLevel::Rms(0.0);
            c.response_noise = vec![NoiseLevel::Rms(s0); n];
            c.seed = params.seed.wrapping_add(1_000_003);
            // The replicates share the plant and the expected spectra; each draws its blocks.
            let replicates = Replicates::new(&plant, &c)?;
            let trial = replicates.draw(&c)?;
            let sig: Vec<f64> = (0..n)
                .map(|k| {
                    let nl = lik.data.freq_hz.len();
                    let r: Vec<f64> = (0..nl)
                        .map(|l| {
                            noise_ratio(coh_data[l * n + k]) / noise_ratio(trial[k].coherence[l])
                        })
                        .collect();
                    let m = median(r);
                    if m.is_finite() {
                        s0 * m.sqrt()
                    } else {
                        0.0
                    }
                })
                .collect();
            c.response_noise = sig.iter().map(|s| NoiseLevel::Rms(*s)).collect();
            for r in 0..params.replicates {
                c.seed = params.seed.wrapping_add(r as u64);
                let sim = replicates.draw(&c)?;
                let nl = c.lines_hz.len();
                let mut x = Vec::with_capacity(nl * n);
                let mut g = Vec::with_capacity(nl * n);
                for l in 0..nl {
                    for ch in &sim {
                        x.push(ch.values[l]);
                        g.push(ch.coherence[l]);
                    }
                }
                let (q, per) = statistic(post, x, Some(g), &pred, noise, ids)?;
                reps.push(q);
                per_channel.iter_mut().zip(per).for_each(|(a, b)| *a += b);
            }
            (
                format!(
                    "{} replicate Welch experiments of the fitted model ({} blocks of {} s at {} Hz, {:?} window, force {:.3} N RMS over {:?} Hz, response noise from the data's coherence), each scored like the data",
                    params.replicates,
                    chain.n_averages,
                    chain.block_s,
                    chain.fs_hz,
                    chain.window,
                    chain.force_rms_n,
                    chain.band_hz
                ),
                sig,
            )
        }
        Chain::NoiseModel => {
            let v = lik.variances(noise);
            for r in 0..params.replicates {
                let mut rng = rand::rngs::StdRng::seed_from_u64(
                    params.seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ (r as u64 + 1),
                );
                let x: Vec<C64> = pred
                    .iter()
                    .zip(&v)
                    .map(|(h, v)| {
                        let s = v.sqrt();
                        h + C64::new(
                            s * crate::experiment::signal::normal(&mut rng),
                            s * crate::experiment::signal::normal(&mut rng),
                        )
                    })
                    .collect();
                let (q, per) = statistic(post, x, lik.data.coherence.clone(), &pred, noise, ids)?;
                reps.push(q);
                per_channel.iter_mut().zip(per).for_each(|(a, b)| *a += b);
            }
            (
                format!(
                    "{} replicates of the fitted prediction plus the noise model's Gaussian errors (no estimator declared)",
                    params.replicates
                ),
                Vec::new(),
            )
        }
    };
    let m = reps.len().max(1) as f64;
    let mean = reps.iter().sum::<f64>() / m;
    let sd = (reps.iter().map(|q| (q - mean).powi(2)).sum::<f64>() / (m - 1.0).max(1.0)).sqrt();
    let z = crate::inference::prior::normal_quantile(1.0 - params.false_alarm);
    let threshold = mean + z * sd;
    Ok(NullCalibration {
        method,
        exceed: reps.iter().filter(|q| **q > threshold).count(),
        replicates: reps,
        channel_mean: per_channel.iter().map(|a| a / m).collect(),
        mean,
        sd,
        threshold,
        false_alarm: params.false_alarm,
        response_noise_rms: noise_rms,
        seconds: t0.elapsed().as_secs_f64(),
    })
}
