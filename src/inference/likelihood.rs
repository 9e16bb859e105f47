//! The likelihood of measured complex FRFs under the forward model, and the posterior it
//! makes with the priors.
//!
//! With `r_o = E[H1]_o(p) - X_o` the complex residual of observation `o` (a line and a
//! channel), each observation is an isotropic complex variable with variance `v_o` per real
//! and imaginary part:
//!
//! ```text
//!   Gaussian:   log p(r_o) = -ln(2 pi v_o) - q_o / 2,                              q_o = |r_o|^2 / v_o
//!   Student-t:  log p(r_o) = -ln(2 pi v_o) - (nu/2 + 1) ln(1 + q_o / nu)          (bivariate t, nu > 0)
//! ```
//!
//! and the scales `v_o` come from the chosen noise model:
//!
//! ```text
//!   coherence:  v_o = |X_o|^2 max(1 - g_o^2, floor) / (2 n_d g_o^2)  + (eps |X_o|)^2     (Bendat & Piersol ch. 9)
//!   inferred:   v_o = tau_c(o)^2 |X_o|^2                             + (eps |X_o|)^2     (tau: one per channel [and band])
//! ```
//!
//! `n_d` is the equivalent number of independent averages (Welch with 50 % Hann overlap:
//! n / 1.056), `floor` keeps lines of coherence near one from getting near-zero variance, `eps`
//! is an optional relative model-error floor added in quadrature. The gradient in the law's
//! parameters is the chain rule through the forward model's Jacobian,
//! `dq_o/dp_k = 2 Re(conj(r_o) dE[H1]_o/dp_k) / v_o`; in `tau` and `nu` it is analytic too.
//!
//! **Correlated channels.** A Welch H1 leaks the same off-line force into every channel, so
//! near a resonance (where every channel is dominated by one mode) the channels' errors at a
//! line are correlated (0.3-0.7 on the bundled leaky data). With a [`ChannelCorrelation`] the
//! `n_out` residuals of line `l` form one circular complex Gaussian vector with covariance
//! `C_l = 2 D_l^1/2 R_l D_l^1/2` (`D_l = diag(v_o)`, `R_l` a Hermitian correlation matrix):
//!
//! ```text
//!   log p(r_l) = -sum_k ln(2 pi v_k) - ln det R_l - s_l^H R_l^-1 s_l / 2,      s_k = r_k / sqrt(v_k)
//! ```
//!
//! which is the independent model when `R_l = I`. `R_l` is estimated from standardised
//! residuals (at the MAP) over a window of neighbouring lines, shrunk towards the identity with
//! the Schäfer & Strimmer (2005) intensity `sum Var(c_ij) / sum |c_ij|^2` (`Var(c_ij) = 1/m`
//! for `m` lines): uncorrelated channels give `R = I` back. Gaussian errors only.
//!
//! The posterior ([`FrfPosterior`]) puts a [`Prior`] on every coordinate (law parameters, then
//! the `tau`s, then `nu` when inferred) and maps them to unconstrained coordinates (see
//! [`super::prior`]).

use super::prior::{log_density_all, log_jacobian_all, quantile_all, to_physical_all, Prior};
use super::{Curvature, DensityError, Posterior};
use crate::common::C64;
use crate::forward::{ForwardError, ForwardModel};
use rand::rngs::StdRng;

/// Where the noise scales come from.
#[derive(Clone, Debug, PartialEq)]
pub enum Scale {
    /// From the coherence: `n_averages` equivalent independent averages, `floor` on `1 - g^2`.
    Coherence { n_averages: f64, floor: f64 },
    /// One relative noise level per channel, or per channel and band when `bands_hz` is not
    /// empty (band edges: `[f0, f1, .., fm]` makes m bands), inferred.
    Inferred { bands_hz: Vec<f64> },
    /// Given variances per observation (per real and imaginary part), e.g. from repeated
    /// measurements, or the deterministic RFM's weights `|dH'/dE*|^2` (which makes the maximum
    /// likelihood the RFM fixed point).
    Fixed { variances: Vec<f64> },
}

/// The error law.
#[derive(Clone, Debug, PartialEq)]
pub enum ErrorLaw {
    Gaussian,
    /// Bivariate Student-t; `nu = None` infers it.
    StudentT {
        nu: Option<f64>,
    },
}

/// The noise model of a study.
#[derive(Clone, Debug, PartialEq)]
pub struct NoiseModel {
    pub scale: Scale,
    pub errors: ErrorLaw,
    /// Relative model-error floor added in quadrature (0: none).
    pub model_error: f64,
}

/// Default floor on `1 - g^2` (a line of coherence 0.9999 counts as 0.9999 at most... i.e.
/// its relative error is at least sqrt(1e-4 / (2 n_d))).
pub const DEFAULT_COHERENCE_FLOOR: f64 = 1e-4;

/// Errors in the data or the noise model.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LikelihoodError {
    #[error("{0}")]
    Data(String),
}

/// Measured values of one level: `[line * n_out + k]`.
#[derive(Clone, Debug)]
pub struct FrfData {
    pub freq_hz: Vec<f64>,
    pub n_out: usize,
    pub values: Vec<C64>,
    /// Ordinary coherence per value, when the data have it.
    pub coherence: Option<Vec<f64>>,
}

/// Correlation of the channels' errors per line: the Cholesky factor `L_l` of each line's
/// Hermitian correlation matrix `R_l = L_l L_l^H` (lower triangle, row-major `n x n`) and
/// `ln det R_l`.
#[derive(Clone, Debug, PartialEq)]
pub struct ChannelCorrelation {
    n: usize,
    chol: Vec<Vec<C64>>,
    log_det: Vec<f64>,
    /// Shrinkage intensity used per line (1: identity); for the leakage structure, the
    /// energy share `eps` off the common direction.
    pub shrinkage: Vec<f64>,
    /// Largest |R_ij|, i != j, per line.
    pub max_correlation: Vec<f64>,
}

impl ChannelCorrelation {
    /// From one correlation matrix per line (row-major `n x n`, Hermitian, unit diagonal).
    pub fn from_matrices(n: usize, mats: &[Vec<C64>]) -> Result<Self, LikelihoodError> {
        let mut chol = Vec::with_capacity(mats.len());
        let mut log_det = Vec::with_capacity(mats.len());
        let mut max_correlation = Vec::with_capacity(mats.len());
        for (l, m) in mats.iter().enumerate() {
            if m.len() != n * n {
                return Err(LikelihoodError::Data(format!(
                    "channel correlation of line {l}: {} entries for {n} channels",
                    m.len()
                )));
            }
            let Some(c) = complex_cholesky(m, n) else {
                return Err(LikelihoodError::Data(format!(
                    "channel correlation of line {l} is not positive definite"
                )));
            };
            log_det.push((0..n).map(|i| 2.0 * c[i * n + i].re.ln()).sum());
            chol.push(c);
            let mut mx: f64 = 0.0;
            for i in 0..n {
                for j in 0..n {
                    if i != j {
                        mx = mx.max(m[i * n + j].norm());
                    }
                }
            }
            max_correlation.push(mx);
        }
        Ok(ChannelCorrelation {
            n,
            chol,
            log_det,
            shrinkage: vec![0.0; mats.len()],
            max_correlation,
        })
    }

    /// Estimate from standardised residuals `s` (`[line * n + k]`) over a window of `window`
    /// lines centred on each line (clipped at the ends), shrunk towards the identity.
    pub fn estimate(s: &[C64], n: usize, window: usize) -> Result<Self, LikelihoodError> {
        if n == 0 || !s.len().is_multiple_of(n) || window < 2 {
            return Err(LikelihoodError::Data(format!(
                "channel correlation: {} residuals for {n} channels, window {window} (at least 2 lines)",
                s.len()
            )));
        }
        let n_lines = s.len() / n;
        let half = window / 2;
        let mut mats = Vec::with_capacity(n_lines);
        let mut shrink = Vec::with_capacity(n_lines);
        for l in 0..n_lines {
            let (lo, hi) = if n_lines <= window {
                (0, n_lines)
            } else {
                let lo = l.saturating_sub(half).min(n_lines - window);
                (lo, lo + window)
            };
            let m = (hi - lo) as f64;
            let mut cov = vec![C64::new(0.0, 0.0); n * n];
            for j in lo..hi {
                let sl = &s[j * n..(j + 1) * n];
                for a in 0..n {
                    for b in 0..n {
                        cov[a * n + b] += sl[a] * sl[b].conj();
                    }
                }
            }
            let d: Vec<f64> = (0..n).map(|a| cov[a * n + a].re.max(1e-300)).collect();
            let mut c = cov.clone();
            let mut sum2 = 0.0;
            for a in 0..n {
                for b in 0..n {
                    c[a * n + b] = cov[a * n + b] / (d[a] * d[b]).sqrt();
                    if a != b {
                        sum2 += c[a * n + b].norm_sqr();
                    }
                }
            }
            // Schäfer & Strimmer: lambda = sum Var(c_ij) / sum |c_ij|^2, Var(c_ij) = 1 / m.
            let var_sum = (n * (n - 1)) as f64 / m;
            let lambda = if sum2 > 0.0 {
                (var_sum / sum2).clamp(0.0, 1.0)
            } else {
                1.0
            };
            for a in 0..n {
                for b in 0..n {
                    c[a * n + b] = if a == b {
                        C64::new(1.0, 0.0)
                    } else {
                        c[a * n + b] * (1.0 - lambda)
                    };
                }
            }
            mats.push(c);
            shrink.push(lambda);
        }
        let mut out = Self::from_matrices(n, &mats)?;
        out.shrinkage = shrink;
        Ok(out)
    }

    /// The leakage structure of a Welch H1 with clean sensors: the random error of line `l` is a
    /// common random frequency jitter, `r_l ~ dE[H1]_l/df xi_l` with one complex `xi_l` for
    /// every channel (checked on the independent time-domain virtual data: 97-99.99 % of the
    /// error's energy lies along that direction). `pred` is the expected H1 at the MAP
    /// (`[line * n + k]`, lines `freq_hz`); its central difference across lines gives the
    /// direction, of which only the phases enter the correlation
    /// `R_l = (1 - eps_l) w w^H + eps_l I`, `w_k = exp(j arg dE[H1]_k/df)`. `eps_l`, the
    /// energy share off that direction, is estimated from the standardised residuals `s` over
    /// `window` lines (`E |P_perp s|^2 = 2 (n - 1) eps`), at least `eps_min`.
    pub fn leakage(
        pred: &[C64],
        freq_hz: &[f64],
        s: &[C64],
        n: usize,
        window: usize,
        eps_min: f64,
    ) -> Result<Self, LikelihoodError> {
        let n_lines = freq_hz.len();
        if n < 2 || pred.len() != n_lines * n || s.len() != n_lines * n || n_lines < 3 || window < 2
        {
            return Err(LikelihoodError::Data(format!(
                "leakage correlation: {} predictions and {} residuals for {n_lines} lines x {n} channels (at least 3 lines and 2 channels)",
                pred.len(),
                s.len()
            )));
        }
        let phase: Vec<C64> = (0..n_lines)
            .flat_map(|l| {
                let (a, b) = (l.saturating_sub(1), (l + 1).min(n_lines - 1));
                let df = freq_hz[b] - freq_hz[a];
                (0..n).map(move |k| {
                    let d = (pred[b * n + k] - pred[a * n + k]) / df;
                    if d.norm() > 0.0 {
                        d / d.norm()
                    } else {
                        C64::new(1.0, 0.0)
                    }
                })
            })
            .collect();
        // Energy off the direction per line.
        let off: Vec<f64> = (0..n_lines)
            .map(|l| {
                let w = &phase[l * n..(l + 1) * n];
                let sl = &s[l * n..(l + 1) * n];
                let along: C64 = w.iter().zip(sl).map(|(w, s)| w.conj() * s).sum();
                let tot: f64 = sl.iter().map(|z| z.norm_sqr()).sum();
                (tot - along.norm_sqr() / n as f64).max(0.0)
            })
            .collect();
        let half = window / 2;
        let mut mats = Vec::with_capacity(n_lines);
        let mut eps_all = Vec::with_capacity(n_lines);
        for l in 0..n_lines {
            let (lo, hi) = if n_lines <= window {
                (0, n_lines)
            } else {
                let lo = l.saturating_sub(half).min(n_lines - window);
                (lo, lo + window)
            };
            let eps = (off[lo..hi].iter().sum::<f64>() / (2.0 * (n - 1) as f64 * (hi - lo) as f64))
                .clamp(eps_min, 1.0);
            let w = &phase[l * n..(l + 1) * n];
            let m: Vec<C64> = (0..n * n)
                .map(|ij| {
                    let (i, j) = (ij / n, ij % n);
                    if i == j {
                        C64::new(1.0, 0.0)
                    } else {
                        w[i] * w[j].conj() * (1.0 - eps)
                    }
                })
                .collect();
            mats.push(m);
            eps_all.push(eps);
        }
        let mut out = Self::from_matrices(n, &mats)?;
        out.shrinkage = eps_all;
        Ok(out)
    }

    /// Number of lines.
    pub fn n_lines(&self) -> usize {
        self.chol.len()
    }

    /// `w = L^-1 s` and `y = R^-1 s` at line `l`.
    fn solve(&self, l: usize, s: &[C64]) -> (Vec<C64>, Vec<C64>) {
        let n = self.n;
        let c = &self.chol[l];
        let mut w = vec![C64::new(0.0, 0.0); n];
        for i in 0..n {
            let mut t = s[i];
            for k in 0..i {
                t -= c[i * n + k] * w[k];
            }
            w[i] = t / c[i * n + i].re;
        }
        let mut y = vec![C64::new(0.0, 0.0); n];
        for i in (0..n).rev() {
            let mut t = w[i];
            for k in i + 1..n {
                t -= c[k * n + i].conj() * y[k];
            }
            y[i] = t / c[i * n + i].re;
        }
        (w, y)
    }
}

/// Cholesky factor of a Hermitian positive definite matrix (row-major, lower triangle), or
/// `None` when it is not positive definite.
fn complex_cholesky(a: &[C64], n: usize) -> Option<Vec<C64>> {
    let mut l = vec![C64::new(0.0, 0.0); n * n];
    for i in 0..n {
        for j in 0..=i {
            let mut s = a[i * n + j];
            for k in 0..j {
                s -= l[i * n + k] * l[j * n + k].conj();
            }
            if i == j {
                if !(s.re > 0.0) {
                    return None;
                }
                l[i * n + i] = C64::new(s.re.sqrt(), 0.0);
            } else {
                l[i * n + j] = s / l[j * n + j].re;
            }
        }
    }
    Some(l)
}

/// The likelihood of one level's data under one forward model.
pub struct FrfLikelihood<'a> {
    pub forward: ForwardModel<'a>,
    pub data: FrfData,
    pub noise: NoiseModel,
    /// Per observation: fixed part of the variance (coherence scale plus model error), or the
    /// model-error part only for inferred scales.
    base_var: Vec<f64>,
    /// Per observation `|X_o|^2` (inferred scales multiply it by tau^2).
    abs2: Vec<f64>,
    /// Per observation the index of its tau (inferred scales).
    group: Vec<usize>,
    n_tau: usize,
    /// Names of the noise coordinates.
    noise_names: Vec<String>,
    /// Correlation of the channels' errors per line (`None`: independent channels).
    correlation: Option<ChannelCorrelation>,
}

/// What one evaluation returns.
#[derive(Clone, Debug, Default)]
pub struct LogLik {
    pub value: f64,
    /// Gradient in (law parameters, taus, nu) when asked.
    pub grad: Vec<f64>,
}

impl<'a> FrfLikelihood<'a> {
    /// `channel_ids[k]` names channel k in the noise coordinates' names.
    pub fn new(
        forward: ForwardModel<'a>,
        data: FrfData,
        noise: NoiseModel,
        channel_ids: &[u32],
    ) -> Result<Self, LikelihoodError> {
        let err = |m: String| Err(LikelihoodError::Data(m));
        let n = data.freq_hz.len() * data.n_out;
        if data.values.len() != n
            || forward.n_out() != data.n_out
            || forward.n_lines() != data.freq_hz.len()
        {
            return err(format!(
                "data hold {} values for {} lines x {} channels; the forward model has {} x {}",
                data.values.len(),
                data.freq_hz.len(),
                data.n_out,
                forward.n_lines(),
                forward.n_out()
            ));
        }
        if let Some((o, _)) = data
            .values
            .iter()
            .enumerate()
            .find(|(_, v)| !(v.re.is_finite() && v.im.is_finite()))
        {
            return err(format!(
                "value at {} Hz, channel {} is NaN or infinite: remove the line (measurements.band_hz) or the channel",
                data.freq_hz[o / data.n_out],
                channel_ids.get(o % data.n_out).copied().unwrap_or(0)
            ));
        }
        if !(noise.model_error >= 0.0 && noise.model_error.is_finite()) {
            return err(format!("model_error {} must be >= 0", noise.model_error));
        }
        let abs2: Vec<f64> = data.values.iter().map(|v| v.norm_sqr()).collect();
        if let Some(o) = abs2.iter().position(|a| !(*a > 0.0)) {
            return err(format!(
                "value at {} Hz, channel {} is zero: a relative noise scale needs |H| > 0; remove the line",
                data.freq_hz[o / data.n_out],
                channel_ids.get(o % data.n_out).copied().unwrap_or(0)
            ));
        }
        let eps2 = noise.model_error.powi(2);
        let mut base_var: Vec<f64> = abs2.iter().map(|a| eps2 * a).collect();
        let mut group = vec![0usize; n];
        let mut n_tau = 0;
        let mut noise_names = Vec::new();
        match &noise.scale {
            Scale::Coherence { n_averages, floor } => {
                if !(*n_averages > 0.0 && n_averages.is_finite()) {
                    return err(format!(
                        "n_averages {n_averages} must be positive (the equivalent number of independent averages)"
                    ));
                }
                if !(*floor > 0.0 && *floor < 1.0) {
                    return err(format!("coherence_floor {floor} must be in (0, 1)"));
                }
                let Some(coh) = &data.coherence else {
                    return err("the noise model \"coherence\" needs coherence in the data files; use noise = \"inferred\"".into());
                };
                for (o, g2) in coh.iter().enumerate() {
                    if !(*g2 > 0.0 && *g2 <= 1.0 + 1e-9) {
                        return err(format!(
                            "coherence {g2} at {} Hz, channel {} is not in (0, 1]: remove the line (measurements.band_hz) or use noise = \"inferred\"",
                            data.freq_hz[o / data.n_out],
                            channel_ids.get(o % data.n_out).copied().unwrap_or(0)
                        ));
                    }
                    let g2 = g2.min(1.0);
                    base_var[o] += coherence_variance(abs2[o], g2, *n_averages, *floor);
                }
            }
            Scale::Fixed { variances } => {
                if variances.len() != n || variances.iter().any(|v| !(*v > 0.0 && v.is_finite())) {
                    return err(format!(
                        "fixed variances: need {n} positive finite values, got {}",
                        variances.len()
                    ));
                }
                base_var
                    .iter_mut()
                    .zip(variances)
                    .for_each(|(b, v)| *b += v);
            }
            Scale::Inferred { bands_hz } => {
                let n_bands = bands_hz.len().saturating_sub(1).max(1);
                if bands_hz.len() >= 2 && bands_hz.windows(2).any(|w| !(w[1] > w[0])) {
                    return err(format!("noise bands {bands_hz:?} must increase"));
                }
                for (o, g) in group.iter_mut().enumerate() {
                    let k = o % data.n_out;
                    let f = data.freq_hz[o / data.n_out];
                    let b = if bands_hz.len() >= 2 {
                        bands_hz
                            .windows(2)
                            .position(|w| f >= w[0] && f <= w[1])
                            .unwrap_or(if f < bands_hz[0] { 0 } else { n_bands - 1 })
                    } else {
                        0
                    };
                    *g = k * n_bands + b;
                }
                n_tau = data.n_out * n_bands;
                for (k, id) in channel_ids.iter().enumerate().take(data.n_out) {
                    for b in 0..n_bands {
                        noise_names.push(if n_bands == 1 {
                            format!("sigma_rel_ch{id}")
                        } else {
                            format!("sigma_rel_ch{id}_band{b}")
                        });
                    }
                    let _ = k;
                }
            }
        }
        if matches!(noise.errors, ErrorLaw::StudentT { nu: None }) {
            noise_names.push("nu".into());
        }
        if let ErrorLaw::StudentT { nu: Some(nu) } = noise.errors {
            if !(nu > 0.0) {
                return err(format!("nu {nu} must be positive"));
            }
        }
        Ok(FrfLikelihood {
            forward,
            data,
            noise,
            base_var,
            abs2,
            group,
            n_tau,
            noise_names,
            correlation: None,
        })
    }

    /// Set (or clear) the correlation of the channels' errors per line. Needs Gaussian errors
    /// and one matrix per line of the data's size.
    pub fn set_channel_correlation(
        &mut self,
        c: Option<ChannelCorrelation>,
    ) -> Result<(), LikelihoodError> {
        if let Some(c) = &c {
            if !matches!(self.noise.errors, ErrorLaw::Gaussian) {
                return Err(LikelihoodError::Data(
                    "correlated channels need Gaussian errors: use noise.model = \"coherence\" or \"inferred\"".into(),
                ));
            }
            if c.n != self.data.n_out || c.n_lines() != self.data.freq_hz.len() {
                return Err(LikelihoodError::Data(format!(
                    "channel correlation for {} lines x {} channels; the data have {} x {}",
                    c.n_lines(),
                    c.n,
                    self.data.freq_hz.len(),
                    self.data.n_out
                )));
            }
        }
        self.correlation = c;
        Ok(())
    }

    /// The correlation of the channels' errors, when set.
    pub fn channel_correlation(&self) -> Option<&ChannelCorrelation> {
        self.correlation.as_ref()
    }

    /// Number of noise coordinates (taus, then nu when inferred).
    pub fn n_noise(&self) -> usize {
        self.noise_names.len()
    }
    pub fn noise_names(&self) -> &[String] {
        &self.noise_names
    }
    pub fn n_tau(&self) -> usize {
        self.n_tau
    }
    fn infers_nu(&self) -> bool {
        matches!(self.noise.errors, ErrorLaw::StudentT { nu: None })
    }

    /// Variance per observation for the noise coordinates `noise` (taus, nu).
    pub fn variances(&self, noise: &[f64]) -> Vec<f64> {
        if self.n_tau == 0 {
            return self.base_var.clone();
        }
        self.base_var
            .iter()
            .zip(&self.abs2)
            .zip(&self.group)
            .map(|((b, a), g)| b + noise[*g] * noise[*g] * a)
            .collect()
    }

    /// Per observation log density given residuals `r` and variances `v`.
    fn terms(&self, nu: Option<f64>, r: C64, v: f64) -> (f64, f64, f64) {
        // (log p, d log p / dq, d log p / d nu)
        let q = r.norm_sqr() / v;
        let c = -(std::f64::consts::TAU * v).ln();
        match nu {
            None => (c - 0.5 * q, -0.5, 0.0),
            Some(nu) => {
                let l = (q / nu).ln_1p();
                let lp = c - (nu / 2.0 + 1.0) * l;
                let dq = -(nu + 2.0) / (2.0 * (nu + q));
                let dnu = -0.5 * l + (nu / 2.0 + 1.0) * q / (nu * (nu + q));
                (lp, dq, dnu)
            }
        }
    }

    fn nu_of(&self, noise: &[f64]) -> Option<f64> {
        match self.noise.errors {
            ErrorLaw::Gaussian => None,
            ErrorLaw::StudentT { nu: Some(nu) } => Some(nu),
            ErrorLaw::StudentT { nu: None } => Some(noise[self.n_tau]),
        }
    }

    /// Log likelihood at law parameters `p` and noise coordinates `noise`, with the gradient
    /// in (p, noise) when `grad`.
    pub fn eval(&self, p: &[f64], noise: &[f64], grad: bool) -> Result<LogLik, ForwardError> {
        if !grad {
            let pred = self.forward.predict(p, false)?;
            return Ok(self.eval_values(&pred.values, noise, false).0);
        }
        // The law's part of the gradient by one vector-Jacobian product: the cotangent
        // d log L / d E[H1] pulled back through the measurement kernel and the FRF.
        let lin = self.forward.linearise(p)?;
        let (mut ll, cot) = self.eval_values(&lin.values, noise, true);
        ll.grad.splice(0..0, lin.vjp(&cot));
        Ok(ll)
    }

    /// Log likelihood of the predicted values `values` (`[line * n_out + k]`) and, when
    /// `grad`, its gradient in the noise coordinates with the cotangent `c_o` of the values,
    /// such that `d log L / dp = Re sum_o conj(c_o) d values_o / dp`.
    fn eval_values(&self, values: &[C64], noise: &[f64], grad: bool) -> (LogLik, Vec<C64>) {
        let v = self.variances(noise);
        if let Some(c) = &self.correlation {
            return self.eval_correlated(c, values, noise, &v, grad);
        }
        let nu = self.nu_of(noise);
        let mut value = 0.0;
        let mut g = vec![0.0; if grad { self.n_noise() } else { 0 }];
        let mut cot = Vec::with_capacity(if grad { values.len() } else { 0 });
        for (o, (h, x)) in values.iter().zip(&self.data.values).enumerate() {
            let r = h - x;
            let (lp, dq, dnu) = self.terms(nu, r, v[o]);
            value += lp;
            if grad {
                cot.push(r * (2.0 * dq / v[o]));
                if self.n_tau > 0 {
                    // d/dv [-ln v + f(q)] = -1/v - f'(q) q / v; dv/dtau = 2 tau |X|^2
                    let q = r.norm_sqr() / v[o];
                    let dv = -1.0 / v[o] - dq * q / v[o];
                    let t = self.group[o];
                    g[t] += dv * 2.0 * noise[t] * self.abs2[o];
                }
                if self.infers_nu() {
                    g[self.n_tau] += dnu;
                }
            }
        }
        (LogLik { value, grad: g }, cot)
    }

    /// Log density of line `l`'s predicted values `h` with correlated channels (Gaussian
    /// errors; see the module doc), with `s = D^-1/2 r` and `y = R^-1 s` for the gradient.
    fn correlated_line(
        &self,
        c: &ChannelCorrelation,
        l: usize,
        h: &[C64],
        vl: &[f64],
    ) -> (f64, Vec<C64>, Vec<C64>) {
        let n = self.data.n_out;
        let x = &self.data.values[l * n..(l + 1) * n];
        let mut lp = -c.log_det[l];
        let s: Vec<C64> = (0..n)
            .map(|k| {
                lp -= (std::f64::consts::TAU * vl[k]).ln();
                (h[k] - x[k]) / vl[k].sqrt()
            })
            .collect();
        let (w, y) = c.solve(l, &s);
        lp -= 0.5 * w.iter().map(|z| z.norm_sqr()).sum::<f64>();
        (lp, s, y)
    }

    /// [`Self::eval_values`] with correlated channels: the cotangent is `-D^-1/2 y` and
    /// `d log p / d v_k = -1/v_k + Re(conj(y_k) s_k) / (2 v_k)`.
    fn eval_correlated(
        &self,
        c: &ChannelCorrelation,
        values: &[C64],
        noise: &[f64],
        v: &[f64],
        grad: bool,
    ) -> (LogLik, Vec<C64>) {
        let n = self.data.n_out;
        let mut g = vec![0.0; if grad { self.n_noise() } else { 0 }];
        let mut cot = Vec::with_capacity(if grad { values.len() } else { 0 });
        let mut value = 0.0;
        for (l, h) in values.chunks_exact(n).enumerate() {
            let vl = &v[l * n..(l + 1) * n];
            let (lp, s, y) = self.correlated_line(c, l, h, vl);
            value += lp;
            if grad {
                for k in 0..n {
                    cot.push(-y[k] / vl[k].sqrt());
                    if self.n_tau > 0 {
                        let dv = -1.0 / vl[k] + 0.5 * (y[k].conj() * s[k]).re / vl[k];
                        let t = self.group[l * n + k];
                        g[t] += dv * 2.0 * noise[t] * self.abs2[l * n + k];
                    }
                }
            }
        }
        (LogLik { value, grad: g }, cot)
    }

    /// The log likelihood at `(p, noise)`, its gradient in `(p, noise)` and a Gauss-Newton
    /// curvature: an approximation of the Hessian of `-log L`, row-major over `(p, noise)`
    /// (a [`Curvature`] in the physical coordinates).
    ///
    /// The law's block is the expected information of the residuals through the forward
    /// model's Jacobian `J = dE[H1]/dp`: `sum_o w_o Re(conj(J_io) J_jo)` with the weight
    /// `w_o = -2 (d log p / d q_o) / v_o` (`1 / v_o` for Gaussian errors, the IRLS weight for
    /// Student-t); with correlated channels the columns are whitened line by line,
    /// `Re((L_l^-1 D_l^-1/2 J_i)^H (L_l^-1 D_l^-1/2 J_j))`. The noise block is a central
    /// difference of the whole gradient in the noise coordinates with the prediction held (no
    /// forward solve), so the noise rows are exact. The law's block is the Hessian where the
    /// residuals are noise (it drops the residuals' second-order term), and positive
    /// semi-definite everywhere, which is what a Gauss-Newton search needs.
    pub fn information(&self, p: &[f64], noise: &[f64]) -> Result<Curvature, ForwardError> {
        let pred = self.forward.predict(p, true)?;
        let (ll, cot) = self.eval_values(&pred.values, noise, true);
        let np = p.len();
        let nn = self.n_noise();
        let d = np + nn;
        // The law's part of the gradient for a cotangent of the values.
        let law_grad = |cot: &[C64]| -> Vec<f64> {
            pred.jac
                .iter()
                .map(|col| col.iter().zip(cot).map(|(j, c)| (c.conj() * j).re).sum())
                .collect()
        };
        let mut grad = law_grad(&cot);
        grad.extend_from_slice(&ll.grad);
        let mut hess = vec![0.0; d * d];
        let v = self.variances(noise);
        let n = self.data.n_out;
        let mut add = |cols: &[C64]| {
            // cols: the np whitened columns of one observation (or one line's channel).
            for i in 0..np {
                for j in 0..=i {
                    hess[i * d + j] += (cols[i].conj() * cols[j]).re;
                }
            }
        };
        match &self.correlation {
            Some(c) => {
                let mut cols = vec![vec![C64::new(0.0, 0.0); np]; n];
                for l in 0..self.data.freq_hz.len() {
                    for (i, col) in pred.jac.iter().enumerate() {
                        let s: Vec<C64> = (0..n)
                            .map(|k| col[l * n + k] / v[l * n + k].sqrt())
                            .collect();
                        let (w, _) = c.solve(l, &s);
                        for k in 0..n {
                            cols[k][i] = w[k];
                        }
                    }
                    cols.iter().for_each(|c| add(c));
                }
            }
            None => {
                let nu = self.nu_of(noise);
                let mut cols = vec![C64::new(0.0, 0.0); np];
                for (o, (h, x)) in pred.values.iter().zip(&self.data.values).enumerate() {
                    let (_, dq, _) = self.terms(nu, h - x, v[o]);
                    let w = (-2.0 * dq / v[o]).max(0.0).sqrt();
                    for (i, col) in pred.jac.iter().enumerate() {
                        cols[i] = col[o] * w;
                    }
                    add(&cols);
                }
            }
        }
        // The noise coordinates' rows: central differences of the whole gradient in noise
        // coordinate t with the prediction held (the law's part through the cotangent).
        for t in 0..nn {
            let e = 1e-6 * (1.0 + noise[t].abs());
            let mut z = noise.to_vec();
            z[t] = noise[t] + e;
            let (lp, cp) = self.eval_values(&pred.values, &z, true);
            z[t] = noise[t] - e;
            let (lm, cm) = self.eval_values(&pred.values, &z, true);
            let (gp, gm) = (law_grad(&cp), law_grad(&cm));
            for i in 0..np {
                let h = -(gp[i] - gm[i]) / (2.0 * e);
                hess[i * d + np + t] = h;
                hess[(np + t) * d + i] = h;
            }
            for u in 0..nn {
                hess[(np + u) * d + np + t] = -(lp.grad[u] - lm.grad[u]) / (2.0 * e);
            }
        }
        for i in 0..d {
            for j in 0..i {
                let s = if i < np {
                    hess[i * d + j]
                } else {
                    0.5 * (hess[i * d + j] + hess[j * d + i])
                };
                hess[i * d + j] = s;
                hess[j * d + i] = s;
            }
        }
        Ok(Curvature {
            value: ll.value,
            grad,
            hess,
        })
    }

    /// The law's block of the expected (Fisher) information per channel at `p`, summed over
    /// the lines: `[k]` row-major `np x np`, `sum_l Re(conj(J_ilk) J_jlk) / v_lk` with the
    /// variances at the noise coordinates `noise`. It is [`Self::information`]'s law block split
    /// by channel for Gaussian errors and independent channels, where the information of a set
    /// of channels is the sum of theirs (what a sensor-placement search adds up), and it does
    /// not depend on the data beyond their variances.
    pub fn channel_information(
        &self,
        p: &[f64],
        noise: &[f64],
    ) -> Result<Vec<Vec<f64>>, ForwardError> {
        Ok(self.channel_information_of(&self.forward.predict(p, true)?, noise))
    }

    /// [`Self::channel_information`] of a prediction with its Jacobian already at hand.
    pub fn channel_information_of(
        &self,
        pred: &crate::forward::Prediction,
        noise: &[f64],
    ) -> Vec<Vec<f64>> {
        let v = self.variances(noise);
        let np = pred.jac.len();
        let n = self.data.n_out;
        let mut out = vec![vec![0.0; np * np]; n];
        for (o, vo) in v.iter().enumerate() {
            let f = &mut out[o % n];
            for i in 0..np {
                let ji = pred.jac[i][o];
                for j in 0..=i {
                    f[i * np + j] += (ji.conj() * pred.jac[j][o]).re / vo;
                }
            }
        }
        for f in &mut out {
            for i in 0..np {
                for j in 0..i {
                    f[j * np + i] = f[i * np + j];
                }
            }
        }
        out
    }

    /// Pointwise log likelihood per line (summed over channels), for LOO and WAIC.
    pub fn pointwise(&self, p: &[f64], noise: &[f64]) -> Result<Vec<f64>, ForwardError> {
        let pred = self.forward.predict(p, false)?;
        let v = self.variances(noise);
        let nu = self.nu_of(noise);
        let n = self.data.n_out;
        if let Some(c) = &self.correlation {
            return Ok(pred
                .values
                .chunks_exact(n)
                .enumerate()
                .map(|(l, h)| self.correlated_line(c, l, h, &v[l * n..(l + 1) * n]).0)
                .collect());
        }
        let mut out = vec![0.0; self.data.freq_hz.len()];
        for (o, (h, x)) in pred.values.iter().zip(&self.data.values).enumerate() {
            out[o / n] += self.terms(nu, h - x, v[o]).0;
        }
        Ok(out)
    }

    /// Standardised residuals `(E[H1] - X) / sqrt(v)` (complex, per observation).
    pub fn standardised(&self, p: &[f64], noise: &[f64]) -> Result<Vec<C64>, ForwardError> {
        let pred = self.forward.predict(p, false)?;
        let v = self.variances(noise);
        Ok(pred
            .values
            .iter()
            .zip(&self.data.values)
            .zip(&v)
            .map(|((h, x), v)| (h - x) / v.sqrt())
            .collect())
    }
}

/// Priors and likelihood: a [`Posterior`] over unconstrained coordinates.
pub struct FrfPosterior<'a> {
    pub likelihood: FrfLikelihood<'a>,
    /// One prior per coordinate: law parameters, then noise coordinates.
    pub priors: Vec<Prior>,
    pub names: Vec<String>,
}

impl<'a> FrfPosterior<'a> {
    pub fn new(likelihood: FrfLikelihood<'a>, priors: Vec<Prior>) -> Result<Self, LikelihoodError> {
        let mut names = likelihood.forward.param_names();
        names.extend(likelihood.noise_names().iter().cloned());
        if priors.len() != names.len() {
            return Err(LikelihoodError::Data(format!(
                "{} priors for {} coordinates ({names:?})",
                priors.len(),
                names.len()
            )));
        }
        Ok(FrfPosterior {
            likelihood,
            priors,
            names,
        })
    }

    pub fn n_law(&self) -> usize {
        self.likelihood.forward.n_params()
    }

    /// Physical values of all coordinates.
    pub fn physical(&self, x: &[f64]) -> Vec<f64> {
        to_physical_all(&self.priors, x)
    }

    /// Unconstrained coordinates of physical values.
    pub fn unconstrained(&self, p: &[f64]) -> Vec<f64> {
        p.iter()
            .zip(&self.priors)
            .map(|(p, pr)| pr.to_unconstrained(*p))
            .collect()
    }
}

impl Posterior for FrfPosterior<'_> {
    fn dim(&self) -> usize {
        self.priors.len()
    }
    fn names(&self) -> Vec<String> {
        self.names.clone()
    }
    fn log_prior(&self, x: &[f64], grad: Option<&mut [f64]>) -> f64 {
        log_density_all(&self.priors, x, grad)
    }
    fn log_likelihood(&self, x: &[f64], grad: Option<&mut [f64]>) -> Result<f64, DensityError> {
        let phys = self.physical(x);
        let nl = self.n_law();
        let ll = self
            .likelihood
            .eval(&phys[..nl], &phys[nl..], grad.is_some())
            .map_err(|e| match e {
                ForwardError::Setup(m) => DensityError::Fatal(m),
                e => DensityError::Recoverable(e.to_string()),
            })?;
        if let Some(g) = grad {
            for (i, gi) in g.iter_mut().enumerate() {
                *gi = ll.grad[i] * self.priors[i].dp_dx(x[i]);
            }
        }
        if ll.value.is_finite() {
            Ok(ll.value)
        } else {
            Err(DensityError::Recoverable(format!(
                "log likelihood {} at {phys:?}",
                ll.value
            )))
        }
    }
    fn sample_prior(&self, rng: &mut StdRng) -> Vec<f64> {
        self.priors.iter().map(|p| p.sample_x(rng)).collect()
    }
    fn constrained(&self, x: &[f64]) -> Vec<f64> {
        self.physical(x)
    }
    fn log_jacobian(&self, x: &[f64], grad: Option<&mut [f64]>) -> f64 {
        log_jacobian_all(&self.priors, x, grad)
    }
    fn prior_quantile(&self, u: &[f64]) -> Vec<f64> {
        quantile_all(&self.priors, u)
    }
    /// The likelihood's Gauss-Newton curvature ([`FrfLikelihood::information`]) through the
    /// transform, `D I D - diag(dL/dp d2p/dx2)` (`D = diag dp/dx`; the second term is exact),
    /// plus the prior's Hessian in `x` (diagonal: the priors are independent), by central
    /// differences of its closed-form derivative.
    fn curvature(&self, x: &[f64]) -> Option<Result<Curvature, DensityError>> {
        let phys = self.physical(x);
        let nl = self.n_law();
        let info = match self.likelihood.information(&phys[..nl], &phys[nl..]) {
            Ok(i) => i,
            Err(ForwardError::Setup(m)) => return Some(Err(DensityError::Fatal(m))),
            Err(e) => return Some(Err(DensityError::Recoverable(e.to_string()))),
        };
        if !info.value.is_finite() {
            return Some(Err(DensityError::Recoverable(format!(
                "log likelihood {} at {phys:?}",
                info.value
            ))));
        }
        let d = x.len();
        let mut grad = vec![0.0; d];
        let lp = log_density_all(&self.priors, x, Some(&mut grad));
        let mut hess = vec![0.0; d * d];
        for i in 0..d {
            let pr = &self.priors[i];
            let dp = pr.dp_dx(x[i]);
            grad[i] += info.grad[i] * dp;
            for j in 0..d {
                hess[i * d + j] = dp * info.hess[i * d + j] * self.priors[j].dp_dx(x[j]);
            }
            let e = 1e-5 * (1.0 + x[i].abs());
            let d2p = (pr.dp_dx(x[i] + e) - pr.dp_dx(x[i] - e)) / (2.0 * e);
            let d2prior = (pr.log_density_x(x[i] + e).1 - pr.log_density_x(x[i] - e).1) / (2.0 * e);
            hess[i * d + i] -= info.grad[i] * d2p + d2prior;
        }
        Some(Ok(Curvature {
            value: lp + info.value,
            grad,
            hess,
        }))
    }
}

/// The variance of each of Re and Im of an H1 estimate from its coherence: `|H|^2 (1 - g2) /
/// (2 n g2)` (Bendat and Piersol, n independent averages), with `1 - g2` floored at `floor`.
pub fn coherence_variance(abs2: f64, g2: f64, n_averages: f64, floor: f64) -> f64 {
    abs2 * (1.0 - g2).max(floor) / (2.0 * n_averages * g2)
}
