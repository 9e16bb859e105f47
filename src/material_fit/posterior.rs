//! The material-level posterior: measured E'(w) and E''(w), a [`RelaxationLaw`], relative
//! (log-normal) errors with inferred scales.
//!
//! Likelihood, with `r'_i = ln E'_i - ln E'(w_i; p)` and `r''_i = ln E''_i - ln E''(w_i; p)`:
//!
//! log L = sum_i [ -r'_i^2 / (2 s'^2) - ln s' - ln sqrt(2 pi) ] + the same for r'' with s'',
//!
//! a density in the logarithms of the data, so that laws of any size compare by evidence. The
//! two noise scales `s'` (`sigma_storage`) and `s''` (`sigma_loss`) are parameters with
//! log-uniform priors on [1e-4, 1]: one relative scatter for E' and one for E''. The gradient
//! comes from the law's analytic Jacobian: d r'/dp = -Re(dE*/dp) / E', d r''/dp = -Im(dE*/dp) / E''.
//!
//! Priors (log-uniform, from the data): moduli on [1e-3 min E'', 10 max E'], relaxation times
//! two decades beyond the data's window, [1e-2 / w_max, 1e2 / w_min], the fractional order
//! uniform on (0, 1).

use super::law::{ParamKind, RelaxationLaw};
use super::MaterialFitError;
use crate::common::C64;
use crate::inference::prior::{log_density_all, quantile_all, to_physical_all, Prior};
use crate::inference::{DensityError, Posterior};
use rand::rngs::StdRng;

const LN_SQRT_2PI: f64 = 0.918_938_533_204_672_8;

/// A measured complex-modulus curve (a DMA master curve): SI units, frequencies ascending.
#[derive(Clone, Debug, PartialEq)]
pub struct MasterCurve {
    pub freq_hz: Vec<f64>,
    pub storage_pa: Vec<f64>,
    pub loss_pa: Vec<f64>,
}

impl MasterCurve {
    /// Sort by frequency and check: equal lengths, at least 8 points, finite positive values,
    /// distinct frequencies.
    pub fn new(
        freq_hz: Vec<f64>,
        storage_pa: Vec<f64>,
        loss_pa: Vec<f64>,
    ) -> Result<MasterCurve, MaterialFitError> {
        let n = freq_hz.len();
        if storage_pa.len() != n || loss_pa.len() != n {
            return Err(MaterialFitError::Data(format!(
                "{} frequencies, {} storage and {} loss moduli: every row needs all three",
                n,
                storage_pa.len(),
                loss_pa.len()
            )));
        }
        if n < 8 {
            return Err(MaterialFitError::Data(format!(
                "{n} points: at least 8 are needed to fit and test a law"
            )));
        }
        for (i, ((f, s), l)) in freq_hz.iter().zip(&storage_pa).zip(&loss_pa).enumerate() {
            for (what, v) in [
                ("frequency", f),
                ("storage modulus", s),
                ("loss modulus", l),
            ] {
                if !(v.is_finite() && *v > 0.0) {
                    return Err(MaterialFitError::Data(format!(
                        "row {}: {what} {v} is not a positive finite number (the likelihood is on the logarithm of the moduli)",
                        i + 1
                    )));
                }
            }
        }
        let mut idx: Vec<usize> = (0..n).collect();
        idx.sort_by(|&a, &b| freq_hz[a].total_cmp(&freq_hz[b]));
        let pick = |v: &[f64]| idx.iter().map(|&i| v[i]).collect::<Vec<f64>>();
        let c = MasterCurve {
            freq_hz: pick(&freq_hz),
            storage_pa: pick(&storage_pa),
            loss_pa: pick(&loss_pa),
        };
        if c.freq_hz.windows(2).any(|w| w[1] <= w[0]) {
            return Err(MaterialFitError::Data(
                "two rows have the same frequency; average them first".into(),
            ));
        }
        Ok(c)
    }
    pub fn len(&self) -> usize {
        self.freq_hz.len()
    }
    pub fn is_empty(&self) -> bool {
        self.freq_hz.is_empty()
    }
    /// Angular frequencies (rad/s).
    pub fn omega(&self) -> Vec<f64> {
        self.freq_hz
            .iter()
            .map(|f| std::f64::consts::TAU * f)
            .collect()
    }
}

/// The prior box derived from the data (see the module doc).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PriorBox {
    pub modulus_pa: (f64, f64),
    pub tau_s: (f64, f64),
    pub sigma: (f64, f64),
}

impl PriorBox {
    pub fn from_data(c: &MasterCurve) -> PriorBox {
        let min_l = c.loss_pa.iter().cloned().fold(f64::INFINITY, f64::min);
        let max_s = c.storage_pa.iter().cloned().fold(0.0, f64::max);
        let w = c.omega();
        PriorBox {
            modulus_pa: (1e-3 * min_l, 10.0 * max_s),
            tau_s: (1e-2 / w[w.len() - 1], 1e2 / w[0]),
            sigma: (1e-4, 1.0),
        }
    }
    fn prior(&self, kind: ParamKind) -> Prior {
        match kind {
            ParamKind::Modulus => Prior::LogUniform {
                lo: self.modulus_pa.0,
                hi: self.modulus_pa.1,
            },
            ParamKind::Time => Prior::LogUniform {
                lo: self.tau_s.0,
                hi: self.tau_s.1,
            },
            ParamKind::Order => Prior::Uniform { lo: 0.0, hi: 1.0 },
        }
    }
    /// `p` moved inside the prior's support (a hair inside its ends).
    pub fn clamp(&self, kind: ParamKind, p: f64) -> f64 {
        let (lo, hi) = match kind {
            ParamKind::Modulus => self.modulus_pa,
            ParamKind::Time => self.tau_s,
            ParamKind::Order => (0.0, 1.0),
        };
        match kind {
            ParamKind::Order => p.clamp(lo + 1e-3, hi - 1e-3),
            _ => p.clamp(lo * 1.001, hi / 1.001),
        }
    }
}

/// The posterior of a law's parameters and the two noise scales given a master curve.
#[derive(Clone, Debug)]
pub struct MaterialPosterior {
    pub law: RelaxationLaw,
    omega: Vec<f64>,
    ln_storage: Vec<f64>,
    ln_loss: Vec<f64>,
    priors: Vec<Prior>,
    names: Vec<String>,
}

impl MaterialPosterior {
    pub fn new(law: RelaxationLaw, curve: &MasterCurve, bounds: &PriorBox) -> MaterialPosterior {
        let mut priors: Vec<Prior> = law.param_kinds().iter().map(|k| bounds.prior(*k)).collect();
        priors.push(Prior::LogUniform {
            lo: bounds.sigma.0,
            hi: bounds.sigma.1,
        });
        priors.push(priors[priors.len() - 1].clone());
        let mut names = law.param_names();
        names.extend(["sigma_storage".to_string(), "sigma_loss".to_string()]);
        MaterialPosterior {
            law,
            omega: curve.omega(),
            ln_storage: curve.storage_pa.iter().map(|v| v.ln()).collect(),
            ln_loss: curve.loss_pa.iter().map(|v| v.ln()).collect(),
            priors,
            names,
        }
    }
    /// Unconstrained coordinates of physical values (law parameters then the two scales),
    /// each first moved inside its prior's support.
    pub fn unconstrained(&self, physical: &[f64]) -> Vec<f64> {
        physical
            .iter()
            .zip(&self.priors)
            .map(|(v, pr)| {
                let v = match *pr {
                    Prior::LogUniform { lo, hi } => v.clamp(lo * 1.0001, hi / 1.0001),
                    Prior::Uniform { lo, hi } => {
                        v.clamp(lo + 1e-4 * (hi - lo), hi - 1e-4 * (hi - lo))
                    }
                    _ => *v,
                };
                pr.to_unconstrained(v)
            })
            .collect()
    }
    /// Log residuals (ln data - ln model) of E' and E'' at the law parameters `p`.
    pub fn log_residuals(&self, p: &[f64]) -> (Vec<f64>, Vec<f64>) {
        let mut rs = Vec::with_capacity(self.omega.len());
        let mut rl = Vec::with_capacity(self.omega.len());
        for (i, &w) in self.omega.iter().enumerate() {
            let e = self.law.modulus(p, w);
            rs.push(self.ln_storage[i] - e.re.ln());
            rl.push(self.ln_loss[i] - e.im.ln());
        }
        (rs, rl)
    }
}

impl Posterior for MaterialPosterior {
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
        let np = self.law.n_params();
        let phys = self.constrained(x);
        let (p, sig) = phys.split_at(np);
        let (ss, sl) = (sig[0], sig[1]);
        let want_grad = grad.is_some();
        let mut gp = vec![0.0; np];
        let mut jac = vec![C64::new(0.0, 0.0); np];
        let (mut q_s, mut q_l) = (0.0, 0.0);
        for (i, &w) in self.omega.iter().enumerate() {
            let e = self.law.modulus(p, w);
            if !(e.re > 0.0 && e.im > 0.0 && e.re.is_finite() && e.im.is_finite()) {
                return Err(DensityError::Recoverable(format!(
                    "law {} gives E* = {e} at w = {w} rad/s (the likelihood needs E', E'' > 0)",
                    self.law.label()
                )));
            }
            let rs = self.ln_storage[i] - e.re.ln();
            let rl = self.ln_loss[i] - e.im.ln();
            q_s += rs * rs;
            q_l += rl * rl;
            if want_grad {
                self.law.jacobian(p, w, &mut jac);
                // d(-r^2/2s^2)/dp = r/s^2 * d(ln E)/dp.
                let a = rs / (ss * ss * e.re);
                let b = rl / (sl * sl * e.im);
                for k in 0..np {
                    gp[k] += a * jac[k].re + b * jac[k].im;
                }
            }
        }
        let n = self.omega.len() as f64;
        let ll = -0.5 * q_s / (ss * ss)
            - n * ss.ln()
            - 0.5 * q_l / (sl * sl)
            - n * sl.ln()
            - 2.0 * n * LN_SQRT_2PI;
        if let Some(g) = grad {
            for k in 0..np {
                g[k] = gp[k] * self.priors[k].dp_dx(x[k]);
            }
            g[np] = (q_s / ss.powi(3) - n / ss) * self.priors[np].dp_dx(x[np]);
            g[np + 1] = (q_l / sl.powi(3) - n / sl) * self.priors[np + 1].dp_dx(x[np + 1]);
        }
        Ok(ll)
    }
    fn sample_prior(&self, rng: &mut StdRng) -> Vec<f64> {
        self.priors.iter().map(|p| p.sample_x(rng)).collect()
    }
    fn constrained(&self, x: &[f64]) -> Vec<f64> {
        to_physical_all(&self.priors, x)
    }
    fn log_jacobian(&self, x: &[f64], grad: Option<&mut [f64]>) -> f64 {
        let mut s = 0.0;
        let mut g = grad;
        for (i, (xi, p)) in x.iter().zip(&self.priors).enumerate() {
            s += p.dp_dx(*xi).abs().ln();
            if let Some(g) = g.as_deref_mut() {
                // d/dx ln|dp/dx|: log-uniform ln p + ln s + ln(1 - s) + c, uniform ln s + ln(1 - s) + c.
                let sg = 1.0 / (1.0 + (-xi).exp());
                g[i] = match *p {
                    Prior::LogUniform { lo, hi } => {
                        (hi / lo).ln() * sg * (1.0 - sg) + 1.0 - 2.0 * sg
                    }
                    _ => 1.0 - 2.0 * sg,
                };
            }
        }
        s
    }
    fn prior_quantile(&self, u: &[f64]) -> Vec<f64> {
        quantile_all(&self.priors, u)
    }
}
