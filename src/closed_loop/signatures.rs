//! Residual signatures per resonance: what a residual looks like, in the
//! modal terms an engineer reads it in: a resonance whose frequency moved, a resonance whose
//! damping changed, and a trend below the first resonance (a quasi-static stiffness or
//! calibration offset). Per-channel gain and phase slope are in [`super::ChannelResidual`].
//!
//! Near an isolated resonance r the receptance is H_k = A_k / (w_r^2 - w^2 + j eta_r w_r^2)
//! (plus a slowly varying rest). A relative change s of w_r^2 and a change d of the loss
//! factor give, to first order,
//!
//! ```text
//!   dH_k = -(w_r^2 / A_k) H_k^2 (s + j d) = g_k (s + j d),    g_k = -(w_r^2 / A_k) H_k^2
//! ```
//!
//! to first order; a shift of half a bandwidth is not small, so the data on the resonance's
//! band, over every channel, are fitted by the exact modal form in `q = s + j d`:
//! `X_k ~ H_k - A_k / D0 + A_k / (D0 + w_r^2 q)`, `D0 = w_r^2 - w^2 + j eta_r w_r^2`
//! (Gauss-Newton; the model is analytic in q, so each step is the complex least squares
//! `sum conj(g) r / v / sum |g|^2 / v` with g the derivative above at q). Its variance
//! `1 / sum |g|^2 / v` (complex Gaussian errors of variance v per value; each of Re q and
//! Im q has half of it). Frequency shift `df / f = sqrt(1 + s) - 1`; the data's loss factor
//! `(eta_r + d) / (1 + s)` (the mode `(1 + s) w_r^2 (1 + j eta')`), reported as its change.
//! A_k, w_r and eta_r come from a circle fit of the *prediction* on the band (so the
//! signature is the model's own, and data noise does not enter it); channels whose circle
//! fit fails (a node of the mode) are left out. Data and prediction are accelerances; both
//! are turned into receptances (divided by -w^2) first, with v / w^4.
//!
//! The low-frequency trend is the weighted mean ratio `X / H` on the lines below half the
//! first resonance frequency (`c = sum conj(H) X / v / sum |H|^2 / v`, one per channel) and
//! its z-score `(|c| - 1) / sd`: a quasi-static offset no mode explains (a base compliance
//! or a stiffness error shows there first).

use crate::common::C64;
use crate::data::Quantity;
use crate::modal::{circle_fit, CircleFitParams};

/// The frequency and damping change of one resonance.
#[derive(Clone, Debug, PartialEq)]
pub struct ResonanceSignature {
    /// The prediction's natural frequency (Hz), from its circle fit.
    pub freq_hz: f64,
    /// The prediction's loss factor.
    pub loss_factor: f64,
    /// Relative frequency change data - model, `df / f`, and its sd.
    pub freq_shift: f64,
    pub freq_shift_sd: f64,
    /// Loss factor change data - model (absolute), and its sd.
    pub loss_change: f64,
    pub loss_change_sd: f64,
    /// Channels that entered the regression.
    pub channels: usize,
}

impl ResonanceSignature {
    /// `df / f` in sds.
    pub fn freq_z(&self) -> f64 {
        self.freq_shift / self.freq_shift_sd
    }
    /// Loss-factor change in sds.
    pub fn loss_z(&self) -> f64 {
        self.loss_change / self.loss_change_sd
    }
}

/// The ratio below the first resonance, per channel.
#[derive(Clone, Debug, PartialEq)]
pub struct LowFrequencyTrend {
    /// Upper end (Hz) of the lines used (half the first resonance frequency).
    pub below_hz: f64,
    /// Lines used.
    pub lines: usize,
    /// Per channel: the weighted mean `X / H`, and the sd of its modulus.
    pub ratio: Vec<C64>,
    pub ratio_sd: Vec<f64>,
}

/// Signatures of a residual.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Signatures {
    pub resonances: Vec<ResonanceSignature>,
    pub low_frequency: Option<LowFrequencyTrend>,
}

impl Signatures {
    /// Sentences for the report: each signature beyond `z_min` sds.
    pub fn findings(&self, z_min: f64) -> Vec<String> {
        let mut out = Vec::new();
        for r in &self.resonances {
            if r.freq_z().abs() >= z_min {
                out.push(format!(
                    "the resonance at {:.1} Hz sits {:+.3} % off in frequency in the data ({:.1} sd)",
                    r.freq_hz,
                    100.0 * r.freq_shift,
                    r.freq_z()
                ));
            }
            if r.loss_z().abs() >= z_min {
                out.push(format!(
                    "the resonance at {:.1} Hz has a loss factor {:+.2e} off (model {:.3e}, {:.1} sd)",
                    r.freq_hz,
                    r.loss_change,
                    r.loss_factor,
                    r.loss_z()
                ));
            }
        }
        if let Some(t) = &self.low_frequency {
            for (k, (c, sd)) in t.ratio.iter().zip(&t.ratio_sd).enumerate() {
                let z = (c.norm() - 1.0) / sd;
                if z.abs() >= z_min {
                    out.push(format!(
                        "channel {} below {:.1} Hz: data / model = {:.4} ({:.1} sd from 1): a quasi-static offset",
                        k + 1,
                        t.below_hz,
                        c.norm(),
                        z
                    ));
                }
            }
        }
        out
    }
}

/// Resonances of the prediction: local maxima of `hsum` at least `prominence` times the
/// deepest trough on the way to a higher peak on either side.
fn peaks(hsum: &[f64], prominence: f64) -> Vec<usize> {
    let n = hsum.len();
    let mut out = Vec::new();
    for l in 1..n.saturating_sub(1) {
        if hsum[l] > hsum[l - 1] && hsum[l] >= hsum[l + 1] {
            // The lowest value between this peak and the nearest higher one on each side.
            let mut left = hsum[l];
            let mut i = l;
            while i > 0 && hsum[i - 1] <= hsum[l] {
                i -= 1;
                left = left.min(hsum[i]);
            }
            let mut right = hsum[l];
            let mut j = l;
            while j + 1 < n && hsum[j + 1] <= hsum[l] {
                j += 1;
                right = right.min(hsum[j]);
            }
            if hsum[l] >= prominence * left.max(right) {
                out.push(l);
            }
        }
    }
    out
}

/// Signatures of data `x` against prediction `h` (accelerances `[line * n_out + k]`) with
/// variances `v` on lines `freq_hz`.
pub fn signatures(freq_hz: &[f64], x: &[C64], h: &[C64], v: &[f64], n_out: usize) -> Signatures {
    let nl = freq_hz.len();
    if nl < 8 || x.len() != nl * n_out || h.len() != x.len() || v.len() != x.len() {
        return Signatures::default();
    }
    // Receptances.
    let w2: Vec<f64> = freq_hz
        .iter()
        .map(|f| (std::f64::consts::TAU * f).powi(2))
        .collect();
    let rec = |a: &[C64]| -> Vec<C64> {
        a.iter()
            .enumerate()
            .map(|(o, z)| -z / w2[o / n_out].max(f64::MIN_POSITIVE))
            .collect()
    };
    let (xr, hr) = (rec(x), rec(h));
    let vr: Vec<f64> = v
        .iter()
        .enumerate()
        .map(|(o, v)| v / w2[o / n_out].max(f64::MIN_POSITIVE).powi(2))
        .collect();
    // Peaks of the prediction: each channel's |H|^2 over its largest, summed.
    let top: Vec<f64> = (0..n_out)
        .map(|k| {
            (0..nl)
                .map(|l| h[l * n_out + k].norm_sqr())
                .fold(f64::MIN_POSITIVE, f64::max)
        })
        .collect();
    let hsum: Vec<f64> = (0..nl)
        .map(|l| {
            (0..n_out)
                .map(|k| h[l * n_out + k].norm_sqr() / top[k])
                .sum()
        })
        .collect();
    let pk = peaks(&hsum, 4.0);
    let mut resonances = Vec::new();
    for &l in &pk {
        // The band: down to where the weighted sum has fallen by 4 (about the half-power
        // points of the strongest channel), at least 3 lines either side.
        let mut a = l;
        while a > 0 && hsum[a - 1] > hsum[l] / 4.0 && hsum[a - 1] < hsum[a] {
            a -= 1;
        }
        let mut b = l;
        while b + 1 < nl && hsum[b + 1] > hsum[l] / 4.0 && hsum[b + 1] < hsum[b] {
            b += 1;
        }
        let a = a.saturating_sub(3.max(l - a));
        let b = (b + 3.max(b - l)).min(nl - 1);
        let band = (freq_hz[a], freq_hz[b]);
        // Per channel: the prediction's modal term A / D0 on the band (circle fit) and the rest.
        struct Term {
            k: usize,
            a: C64,
            wr2: f64,
        }
        let mut terms = Vec::new();
        let (mut f_r, mut eta_r) = (0.0, 0.0);
        for k in 0..n_out {
            let hk: Vec<C64> = (0..nl).map(|i| hr[i * n_out + k]).collect();
            let fit = match circle_fit(
                freq_hz,
                &hk,
                Quantity::Receptance,
                band,
                &CircleFitParams::default(),
            ) {
                Ok(f) if f.modal_constant.norm() > 0.0 && f.loss_factor > 0.0 => f,
                _ => continue,
            };
            f_r += fit.freq_hz;
            eta_r += fit.loss_factor;
            terms.push(Term {
                k,
                a: fit.modal_constant,
                wr2: (std::f64::consts::TAU * fit.freq_hz).powi(2),
            });
        }
        if terms.is_empty() {
            continue;
        }
        let used = terms.len() as f64;
        let (f_r, eta_r) = (f_r / used, eta_r / used);
        // Gauss-Newton on q = s + j d (analytic in q, so a complex least squares step):
        // H(q) = H - A / D0 + A / (D0 + w_r^2 q),  D0 = w_r^2 - w^2 + j eta w_r^2.
        let mut q = C64::new(0.0, 0.0);
        let mut den = 0.0;
        for _ in 0..30 {
            let mut num = C64::new(0.0, 0.0);
            den = 0.0;
            for t in &terms {
                for i in a..=b {
                    let o = i * n_out + t.k;
                    let d0 = C64::new(t.wr2 - w2[i], eta_r * t.wr2);
                    let dq = d0 + t.wr2 * q;
                    let model = hr[o] - t.a / d0 + t.a / dq;
                    let jac = -t.a * t.wr2 / (dq * dq);
                    num += jac.conj() * (xr[o] - model) / vr[o];
                    den += jac.norm_sqr() / vr[o];
                }
            }
            if den <= 0.0 {
                break;
            }
            let step = num / den;
            q += step;
            if step.norm() < 1e-12 * (1.0 + q.norm()) {
                break;
            }
        }
        if den <= 0.0 || !q.re.is_finite() || !q.im.is_finite() {
            continue;
        }
        let sd = (0.5 / den).sqrt();
        // (1 + s) w_r^2 = (w_r (1 + df/f))^2.
        resonances.push(ResonanceSignature {
            freq_hz: f_r,
            loss_factor: eta_r,
            freq_shift: (1.0 + q.re).max(0.0).sqrt() - 1.0,
            freq_shift_sd: 0.5 * sd,
            // The data's mode: (1 + s) w_r^2 (1 + j eta'), eta' = (eta + Im q) / (1 + s).
            loss_change: (eta_r + q.im) / (1.0 + q.re) - eta_r,
            loss_change_sd: sd / (1.0 + q.re).abs(),
            channels: terms.len(),
        });
    }
    let low_frequency = resonances.first().and_then(|r| {
        let below = 0.5 * r.freq_hz;
        let lines: Vec<usize> = (0..nl).filter(|&l| freq_hz[l] <= below).collect();
        if lines.len() < 2 {
            return None;
        }
        let mut ratio = Vec::with_capacity(n_out);
        let mut ratio_sd = Vec::with_capacity(n_out);
        for k in 0..n_out {
            let (mut sxh, mut shh) = (C64::new(0.0, 0.0), 0.0);
            for &l in &lines {
                let o = l * n_out + k;
                sxh += x[o] * h[o].conj() / v[o];
                shh += h[o].norm_sqr() / v[o];
            }
            ratio.push(sxh / shh);
            ratio_sd.push((0.5 / shh).sqrt());
        }
        Some(LowFrequencyTrend {
            below_hz: below,
            lines: lines.len(),
            ratio,
            ratio_sd,
        })
    });
    Signatures {
        resonances,
        low_frequency,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Accelerance of a sum of modes `(f_r, eta_r, A_r per channel)`.
    fn modal(freq: &[f64], modes: &[(f64, f64, [f64; 2])]) -> Vec<C64> {
        let mut out = Vec::new();
        for &f in freq {
            let w2 = (std::f64::consts::TAU * f).powi(2);
            for k in 0..2 {
                let mut hk = C64::new(0.0, 0.0);
                for &(fr, eta, a) in modes {
                    let wr2 = (std::f64::consts::TAU * fr).powi(2);
                    hk += a[k] / C64::new(wr2 - w2, eta * wr2);
                }
                out.push(-w2 * hk);
            }
        }
        out
    }

    #[test]
    fn a_shifted_resonance_and_a_damping_change_are_found_where_they_are() {
        let freq: Vec<f64> = (1..=500).map(|f| f as f64).collect();
        let model = [
            (40.0, 0.05, [1.0, 0.6]),
            (150.0, 0.04, [0.8, -0.5]),
            (330.0, 0.03, [0.5, 0.7]),
        ];
        // Data: the second mode 1 % higher, the third with 20 % more damping.
        let mut data = model;
        data[1].0 *= 1.01;
        data[2].1 *= 1.2;
        let h = modal(&freq, &model);
        let x = modal(&freq, &data);
        // Noise variance: 1e-3 of each value's modulus squared, floored.
        let v: Vec<f64> = h
            .iter()
            .map(|z| (1e-3 * z.norm()).powi(2) + 1e-12)
            .collect();
        let s = signatures(&freq, &x, &h, &v, 2);
        assert_eq!(s.resonances.len(), 3, "{s:?}");
        let r = &s.resonances;
        assert!((r[0].freq_hz - 40.0).abs() < 0.1 && (r[2].freq_hz - 330.0).abs() < 1.0);
        // Mode 2: df/f = +1 % (first order in a 1 % shift: within 0.1 %), no damping change
        // beyond a small fraction of the loss factor; modes 1 and 3: no frequency shift.
        assert!((r[1].freq_shift - 0.01).abs() < 1e-3, "{:?}", r[1]);
        assert!(
            r[0].freq_shift.abs() < 1e-4 && r[2].freq_shift.abs() < 1e-3,
            "{r:?}"
        );
        // Mode 3: loss factor +0.006 (0.03 * 20 %).
        assert!((r[2].loss_change - 0.006).abs() < 1e-3, "{:?}", r[2]);
        assert!(r[0].loss_change.abs() < 1e-4, "{:?}", r[0]);
        let f = s.findings(5.0);
        assert!(
            f.iter()
                .any(|t| t.contains("150.0 Hz") && t.contains("frequency")),
            "{f:?}"
        );
        assert!(
            f.iter()
                .any(|t| t.contains("330.0 Hz") && t.contains("loss factor")),
            "{f:?}"
        );
        assert!(!f.iter().any(|t| t.contains("40.0 Hz")), "{f:?}");
        // The same data as the model: no finding; a 2 % static offset on channel 2: found.
        assert!(signatures(&freq, &h, &h, &v, 2).findings(3.0).is_empty());
        let mut y = h.clone();
        for l in 0..freq.len() {
            y[l * 2 + 1] *= 1.02;
        }
        let f = signatures(&freq, &y, &h, &v, 2).findings(5.0);
        assert!(
            f.iter()
                .any(|t| t.contains("channel 2") && t.contains("quasi-static")),
            "{f:?}"
        );
    }
}
