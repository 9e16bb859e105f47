//! Time-domain mode: continuous force and response records, Welch-averaged.
//!
//! **Force.** One period of a periodic band-limited Gaussian random signal of `L` samples
//! (`L` = the smallest multiple of the block length not shorter than `n_averages` hops):
//! `x_n = sum_j c_j exp(j 2 pi f_j n / fs)` over the record's DFT bins `f_j = j fs / L`, with
//! `c_j` independent circular complex Gaussian of power `E|c_j|^2 = S_F(f_j) fs / L` inside
//! the band (half at the two edge bins, the trapezoid rule), nothing outside, and
//! `c_{-j} = conj(c_j)`. It is a stationary Gaussian process whose expected RMS is
//! `force_rms_n` (a realised record scatters by about `1 / sqrt(B L / fs)`, 0.2 % here).
//! With a shaker, `c_j = T(f_j) s_j` with `s_j` the flat shaker-force spectrum.
//!
//! **Response: exact linear filtering.** The response of the structure to a periodic force in
//! steady state is periodic, with amplitudes `H(f_j) c_j` at the same bins: multiplying the
//! record spectrum by the plant evaluated at every in-band bin and inverting the FFT is the
//! exact (circular) convolution, with no impulse-response truncation and no causality issue
//! for structural (hysteretic) damping, whose impulse response is not causal. Gain and delay
//! multiply the bin amplitudes by `g exp(-j 2 pi f_j tau)` (an exact fractional delay of a
//! periodic signal). The only error is FFT round-off (about 1e-15 relative).
//! The plant is evaluated at `(hi - lo) L / fs + 1` bins (49 901 for the defaults).
//!
//! **Noise.** White Gaussian noise of the resolved RMS is added to every sample of the force
//! and response records (from its own seeded substream per channel).
//!
//! **Estimator.** `n_averages` Hann-windowed blocks start every `hop` samples, read
//! circularly from the periodic record (the last block wraps around: every block is an equally
//! valid stationary segment); the DFT bins of the requested lines are accumulated into
//! [`WelchSums`].

use super::estimator::{BandModel, WelchSums};
use super::signal::{complex_normal, normal, stream, substream};
use super::spec::{ChainParams, Layout};
use super::{ExperimentError, Plant};
use crate::common::C64;
use rayon::prelude::*;
use rustfft::FftPlanner;

/// Record length (samples) of the time-domain mode for a checked layout.
pub(crate) fn record_len(layout: &Layout, n_averages: usize) -> usize {
    let need = n_averages * layout.hop;
    need.div_ceil(layout.n_block).max(1) * layout.n_block
}

/// Simulate the chain in the time domain; returns the Welch sums per channel.
/// `noise_rms` = (force, per response channel) absolute noise RMS.
pub(crate) fn simulate(
    plant: &dyn Plant,
    chain: &ChainParams,
    layout: &Layout,
    noise_rms: (f64, &[f64]),
) -> Result<Vec<WelchSums>, ExperimentError> {
    let l = record_len(layout, chain.n_averages);
    let bins_per_df = l / layout.n_block; // record bins per block line spacing
    let (lo, hi) = chain.band_hz;
    let df = 1.0 / chain.block_s;
    let j_lo = (lo / df).round() as usize * bins_per_df;
    let j_hi = (hi / df).round() as usize * bins_per_df;
    // The plant and force spectrum on the record's in-band bins, trapezoid weights.
    let band = BandModel::build(plant, chain, j_hi - j_lo)?;
    let m = band.resp.len();

    // Force amplitudes (one sequential substream).
    let mut rng = substream(chain.seed, stream::FORCE, 0);
    let c: Vec<C64> = band
        .force_power
        .iter()
        .map(|p| complex_normal(&mut rng) * p.sqrt())
        .collect();

    let mut planner = FftPlanner::<f64>::new();
    let ifft = planner.plan_fft_inverse(l);
    let fft_block = planner.plan_fft_forward(layout.n_block);
    let window = chain.window.samples(layout.n_block);

    // Builds a real record from in-band bin amplitudes (positive frequencies), plus white noise.
    let record =
        |amp: &dyn Fn(usize) -> C64, noise: f64, stream_kind: u64, index: u64| -> Vec<f64> {
            let mut spec = vec![C64::new(0.0, 0.0); l];
            // A baseband band (lo = 0) leaves the DC bin empty: a zero-mean force.
            for j in usize::from(j_lo == 0)..=(j_hi - j_lo) {
                let a = amp(j);
                spec[j_lo + j] = a;
                spec[l - j_lo - j] = a.conj();
            }
            ifft.process(&mut spec);
            let mut x: Vec<f64> = spec.iter().map(|z| z.re).collect();
            if noise > 0.0 {
                let mut rng = substream(chain.seed, stream_kind, index);
                x.iter_mut().for_each(|v| *v += noise * normal(&mut rng));
            }
            x
        };
    let welch = |x: &[f64]| -> Vec<Vec<C64>> {
        // DFT values at the requested lines for every block.
        let mut buf = vec![C64::new(0.0, 0.0); layout.n_block];
        (0..chain.n_averages)
            .map(|b| {
                let s = b * layout.hop;
                for (n, z) in buf.iter_mut().enumerate() {
                    *z = C64::new(x[(s + n) % l] * window[n], 0.0);
                }
                fft_block.process(&mut buf);
                layout.line_bins.iter().map(|&k| buf[k]).collect()
            })
            .collect()
    };

    let force = record(&|j| c[j], noise_rms.0, stream::FORCE_NOISE, 0);
    let force_blocks = welch(&force);
    drop(force);
    let sums = (0..m)
        .into_par_iter()
        .map(|i| {
            let a = record(
                &|j| band.resp[i][j] * c[j],
                noise_rms.1[i],
                stream::RESPONSE_NOISE,
                i as u64,
            );
            let blocks = welch(&a);
            let mut s = WelchSums::new(layout.line_bins.len());
            for (fb, ab) in force_blocks.iter().zip(&blocks) {
                for (li, (f, a)) in fb.iter().zip(ab).enumerate() {
                    s.add(li, *f, *a);
                }
            }
            s
        })
        .collect();
    Ok(sums)
}
