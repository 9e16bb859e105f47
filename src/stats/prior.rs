//! Priors on positive physical parameters and the map to unconstrained coordinates.
//!
//! Every parameter `p` gets an unconstrained coordinate `x in R`:
//!
//! | family | support | x |
//! |---|---|---|
//! | log-uniform on [a, b] | [a, b] | `logit((ln p - ln a) / (ln b - ln a))` |
//! | uniform on [a, b] | [a, b] | `logit((p - a) / (b - a))` |
//! | truncated normal N(m, s) on [a, b] | [a, b] | `logit((p - a) / (b - a))` |
//! | log-normal (median m, sigma of ln p) | (0, inf) | `ln p` |
//!
//! and the density of `x` is `pi(p(x)) |dp/dx|` (the transform's log-Jacobian included), so a
//! sampler in `x` sees a smooth density on all of `R` and integrates to one. With
//! `s = sigmoid(x)`: `dp/dx = (b - a) s (1 - s)` for the linear maps and `p ln(b/a) s (1 - s)`
//! for the log map; a log-uniform prior has `log pi_x(x) = ln s + ln(1 - s)`.
//!
//! Default (documented in the README): log-uniform over a decade either side of the initial
//! value, clipped to the law's admissible range.

use rand::rngs::StdRng;
use rand::RngExt;

/// One parameter's prior.
#[derive(Clone, Debug, PartialEq)]
pub enum Prior {
    LogUniform {
        lo: f64,
        hi: f64,
    },
    Uniform {
        lo: f64,
        hi: f64,
    },
    LogNormal {
        median: f64,
        sigma_ln: f64,
    },
    TruncatedNormal {
        mean: f64,
        sd: f64,
        lo: f64,
        hi: f64,
    },
}

/// Errors in a prior's settings; the message says what to change.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{0}")]
pub struct PriorError(pub String);

fn sigmoid(x: f64) -> f64 {
    if x >= 0.0 {
        1.0 / (1.0 + (-x).exp())
    } else {
        let e = x.exp();
        e / (1.0 + e)
    }
}

/// `ln sigmoid(x)`, stable for large |x|.
fn ln_sigmoid(x: f64) -> f64 {
    if x >= 0.0 {
        -(-x).exp().ln_1p()
    } else {
        x - x.exp().ln_1p()
    }
}

fn logit(s: f64) -> f64 {
    (s / (1.0 - s)).ln()
}

/// Standard normal CDF via the complementary error function.
pub fn normal_cdf(z: f64) -> f64 {
    0.5 * libm::erfc(-z / std::f64::consts::SQRT_2)
}

/// Inverse standard normal CDF: the diagnostics' quantile function
/// ([`super::special::norm_ppf`], accurate to about 1e-15 in both tails), with the support's
/// ends mapped to -inf and +inf.
pub fn normal_quantile(u: f64) -> f64 {
    if u <= 0.0 {
        return f64::NEG_INFINITY;
    }
    if u >= 1.0 {
        return f64::INFINITY;
    }
    super::special::norm_ppf(u)
}

const LN_SQRT_2PI: f64 = 0.918_938_533_204_672_8;

impl Prior {
    /// Check the settings (and that `inside`, e.g. the initial value, lies in the support).
    pub fn validate(&self) -> Result<(), PriorError> {
        let err = |m: String| Err(PriorError(m));
        match *self {
            Prior::LogUniform { lo, hi } => {
                if !(lo > 0.0 && hi > lo && hi.is_finite()) {
                    return err(format!(
                        "log-uniform bounds [{lo}, {hi}]: need 0 < lo < hi < inf"
                    ));
                }
            }
            Prior::Uniform { lo, hi } => {
                if !(lo >= 0.0 && hi > lo && hi.is_finite()) {
                    return err(format!(
                        "uniform bounds [{lo}, {hi}]: need 0 <= lo < hi < inf (parameters are positive)"
                    ));
                }
            }
            Prior::LogNormal { median, sigma_ln } => {
                if !(median > 0.0 && median.is_finite() && sigma_ln > 0.0 && sigma_ln.is_finite()) {
                    return err(format!(
                        "log-normal median {median}, sigma_ln {sigma_ln}: both must be positive and finite"
                    ));
                }
            }
            Prior::TruncatedNormal { mean, sd, lo, hi } => {
                if !(sd > 0.0 && mean.is_finite() && lo >= 0.0 && hi > lo && hi.is_finite()) {
                    return err(format!(
                        "truncated normal mean {mean}, sd {sd} on [{lo}, {hi}]: need sd > 0 and 0 <= lo < hi < inf"
                    ));
                }
                let z = self.tn_mass();
                if !(z > 1e-300) {
                    return err(format!(
                        "truncated normal mean {mean}, sd {sd} has no mass on [{lo}, {hi}]"
                    ));
                }
            }
        }
        Ok(())
    }

    /// Whether `p` lies inside the support (open for the bounded families).
    pub fn contains(&self, p: f64) -> bool {
        match *self {
            Prior::LogUniform { lo, hi }
            | Prior::Uniform { lo, hi }
            | Prior::TruncatedNormal { lo, hi, .. } => p > lo && p < hi,
            Prior::LogNormal { .. } => p > 0.0 && p.is_finite(),
        }
    }

    fn tn_mass(&self) -> f64 {
        match *self {
            Prior::TruncatedNormal { mean, sd, lo, hi } => {
                normal_cdf((hi - mean) / sd) - normal_cdf((lo - mean) / sd)
            }
            _ => 1.0,
        }
    }

    /// Physical value of the unconstrained coordinate `x`.
    pub fn to_physical(&self, x: f64) -> f64 {
        match *self {
            Prior::LogUniform { lo, hi } => {
                let s = sigmoid(x);
                (lo.ln() + s * (hi / lo).ln()).exp().clamp(lo, hi)
            }
            Prior::Uniform { lo, hi } | Prior::TruncatedNormal { lo, hi, .. } => {
                (lo + (hi - lo) * sigmoid(x)).clamp(lo, hi)
            }
            Prior::LogNormal { .. } => x.exp(),
        }
    }

    /// Unconstrained coordinate of the physical value `p` (inside the support).
    pub fn to_unconstrained(&self, p: f64) -> f64 {
        match *self {
            Prior::LogUniform { lo, hi } => logit((p / lo).ln() / (hi / lo).ln()),
            Prior::Uniform { lo, hi } | Prior::TruncatedNormal { lo, hi, .. } => {
                logit((p - lo) / (hi - lo))
            }
            Prior::LogNormal { .. } => p.ln(),
        }
    }

    /// `dp/dx` at `x`.
    pub fn dp_dx(&self, x: f64) -> f64 {
        match *self {
            Prior::LogUniform { lo, hi } => {
                let s = sigmoid(x);
                self.to_physical(x) * (hi / lo).ln() * s * (1.0 - s)
            }
            Prior::Uniform { lo, hi } | Prior::TruncatedNormal { lo, hi, .. } => {
                let s = sigmoid(x);
                (hi - lo) * s * (1.0 - s)
            }
            Prior::LogNormal { .. } => x.exp(),
        }
    }

    /// `log pi_x(x)` (normalised over R) and its derivative in `x`.
    pub fn log_density_x(&self, x: f64) -> (f64, f64) {
        // ln s + ln(1 - s) and its derivative 1 - 2 s.
        let ls = ln_sigmoid(x) + ln_sigmoid(-x);
        let dls = 1.0 - 2.0 * sigmoid(x);
        match *self {
            Prior::LogUniform { .. } | Prior::Uniform { .. } => (ls, dls),
            Prior::TruncatedNormal { mean, sd, lo, hi } => {
                let p = self.to_physical(x);
                let z = (p - mean) / sd;
                let lp = -0.5 * z * z - LN_SQRT_2PI - sd.ln() - self.tn_mass().ln();
                // d/dx [-(p-m)^2/(2 sd^2)] = -z/sd dp/dx
                let dp = (hi - lo) * sigmoid(x) * (1.0 - sigmoid(x));
                (lp + (hi - lo).ln() + ls, -z / sd * dp + dls)
            }
            Prior::LogNormal { median, sigma_ln } => {
                // x = ln p ~ N(ln median, sigma_ln): the density of x directly.
                let z = (x - median.ln()) / sigma_ln;
                (-0.5 * z * z - LN_SQRT_2PI - sigma_ln.ln(), -z / sigma_ln)
            }
        }
    }

    /// Log density of the physical value `p` (for reports and prior-sd comparisons).
    pub fn log_density_physical(&self, p: f64) -> f64 {
        if !self.contains(p) {
            return f64::NEG_INFINITY;
        }
        let x = self.to_unconstrained(p);
        self.log_density_x(x).0 - self.dp_dx(x).abs().ln()
    }

    /// Quantile `u in (0, 1)` in unconstrained coordinates (for space-filling starts and
    /// prior draws).
    pub fn quantile_x(&self, u: f64) -> f64 {
        let u = u.clamp(1e-12, 1.0 - 1e-12);
        match *self {
            Prior::LogUniform { .. } | Prior::Uniform { .. } => logit(u),
            Prior::TruncatedNormal { mean, sd, lo, hi } => {
                let a = normal_cdf((lo - mean) / sd);
                let b = normal_cdf((hi - mean) / sd);
                let p = (mean + sd * normal_quantile(a + u * (b - a))).clamp(lo, hi);
                let p = p.clamp(lo + 1e-12 * (hi - lo), hi - 1e-12 * (hi - lo));
                self.to_unconstrained(p)
            }
            Prior::LogNormal { median, sigma_ln } => median.ln() + sigma_ln * normal_quantile(u),
        }
    }

    /// One draw in unconstrained coordinates.
    pub fn sample_x(&self, rng: &mut StdRng) -> f64 {
        let u: f64 = rng.random::<f64>();
        self.quantile_x(u)
    }

    /// Prior standard deviation of the physical value (numerically, on quantiles).
    pub fn sd_physical(&self) -> f64 {
        let n = 2000;
        let v: Vec<f64> = (0..n)
            .map(|i| self.to_physical(self.quantile_x((i as f64 + 0.5) / n as f64)))
            .collect();
        let m = v.iter().sum::<f64>() / n as f64;
        (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / n as f64).sqrt()
    }

    /// The documented default: log-uniform over a decade either side of `initial`, clipped to
    /// the admissible open range `(lo, hi)`.
    pub fn default_for(initial: f64, admissible: (f64, f64)) -> Prior {
        let lo = (initial / 10.0).max(admissible.0.max(0.0) + f64::MIN_POSITIVE);
        let hi = (initial * 10.0).min(admissible.1);
        Prior::LogUniform { lo, hi }
    }

    /// Family name as written in a study file.
    pub fn family(&self) -> &'static str {
        match self {
            Prior::LogUniform { .. } => "log_uniform",
            Prior::Uniform { .. } => "uniform",
            Prior::LogNormal { .. } => "log_normal",
            Prior::TruncatedNormal { .. } => "truncated_normal",
        }
    }
}

/// The log prior density of a vector of unconstrained coordinates, one prior each (the
/// priors are independent), with its gradient written to `grad` when given.
pub fn log_density_all(priors: &[Prior], x: &[f64], grad: Option<&mut [f64]>) -> f64 {
    let mut s = 0.0;
    let mut g = grad;
    for (i, (xi, p)) in x.iter().zip(priors).enumerate() {
        let (l, d) = p.log_density_x(*xi);
        s += l;
        if let Some(g) = g.as_deref_mut() {
            g[i] = d;
        }
    }
    s
}

/// `sum ln |dp_i/dx_i|` of a vector of unconstrained coordinates, with its gradient (a central
/// difference of the closed form `dp_dx`) written to `grad` when given.
pub fn log_jacobian_all(priors: &[Prior], x: &[f64], grad: Option<&mut [f64]>) -> f64 {
    let mut s = 0.0;
    let mut g = grad;
    for (i, (xi, p)) in x.iter().zip(priors).enumerate() {
        s += p.dp_dx(*xi).abs().ln();
        if let Some(g) = g.as_deref_mut() {
            let e = 1e-6 * (1.0 + xi.abs());
            g[i] = (p.dp_dx(xi + e).abs().ln() - p.dp_dx(xi - e).abs().ln()) / (2.0 * e);
        }
    }
    s
}

/// Physical values of a vector of unconstrained coordinates.
pub fn to_physical_all(priors: &[Prior], x: &[f64]) -> Vec<f64> {
    x.iter()
        .zip(priors)
        .map(|(x, p)| p.to_physical(*x))
        .collect()
}

/// Unconstrained coordinates at the prior quantiles `u` (one per coordinate).
pub fn quantile_all(priors: &[Prior], u: &[f64]) -> Vec<f64> {
    u.iter()
        .zip(priors)
        .map(|(u, p)| p.quantile_x(*u))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn families() -> Vec<Prior> {
        vec![
            Prior::LogUniform { lo: 1e5, hi: 1e7 },
            Prior::Uniform { lo: 0.0, hi: 5.0 },
            Prior::LogNormal {
                median: 3e6,
                sigma_ln: 0.7,
            },
            Prior::TruncatedNormal {
                mean: 2.0,
                sd: 1.5,
                lo: 0.5,
                hi: 6.0,
            },
        ]
    }

    #[test]
    fn densities_in_x_integrate_to_one_and_gradients_match() {
        for p in families() {
            p.validate().unwrap();
            // Trapezoid over a wide x range.
            let (a, b, n) = (-40.0, 40.0, 200_000);
            let h = (b - a) / n as f64;
            let mut s = 0.0;
            for i in 0..=n {
                let x = a + i as f64 * h;
                let w = if i == 0 || i == n { 0.5 } else { 1.0 };
                s += w * p.log_density_x(x).0.exp();
            }
            let s = s * h;
            assert!((s - 1.0).abs() < 1e-6, "{p:?}: {s}");
            for x in [-3.0, -0.2, 0.0, 0.7, 2.5] {
                let e = 1e-6;
                let fd = (p.log_density_x(x + e).0 - p.log_density_x(x - e).0) / (2.0 * e);
                let (_, g) = p.log_density_x(x);
                assert!(
                    (fd - g).abs() < 1e-6 * (1.0 + g.abs()),
                    "{p:?} x={x}: {fd} {g}"
                );
                let fdp = (p.to_physical(x + e) - p.to_physical(x - e)) / (2.0 * e);
                assert!((fdp - p.dp_dx(x)).abs() < 1e-6 * p.dp_dx(x).abs(), "{p:?}");
            }
        }
    }

    #[test]
    fn transforms_round_trip_and_quantiles_are_inverse_cdfs() {
        for p in families() {
            for u in [0.01, 0.3, 0.5, 0.9] {
                let x = p.quantile_x(u);
                let v = p.to_physical(x);
                assert!(p.contains(v));
                assert!((p.to_unconstrained(v) - x).abs() < 1e-8 * (1.0 + x.abs()));
            }
        }
        // Log-uniform median is the geometric mean.
        let p = Prior::LogUniform { lo: 1.0, hi: 100.0 };
        assert!((p.to_physical(p.quantile_x(0.5)) - 10.0).abs() < 1e-9);
    }

    #[test]
    fn special_functions() {
        assert!((normal_cdf(1.96) - 0.975_002_104_851_780_1).abs() < 1e-14);
        for u in [1e-10, 0.001, 0.2, 0.5, 0.77, 0.999] {
            assert!((normal_cdf(normal_quantile(u)) - u).abs() < 1e-14 * u.max(1e-3) * 10.0);
        }
    }

    #[test]
    fn bad_settings_say_what_to_change() {
        assert!(Prior::LogUniform { lo: 0.0, hi: 1.0 }.validate().is_err());
        assert!(Prior::Uniform { lo: 2.0, hi: 1.0 }.validate().is_err());
        assert!(Prior::LogNormal {
            median: -1.0,
            sigma_ln: 1.0
        }
        .validate()
        .is_err());
        let e = Prior::TruncatedNormal {
            mean: 0.0,
            sd: 0.0,
            lo: 0.0,
            hi: 1.0,
        }
        .validate()
        .unwrap_err();
        assert!(e.0.contains("sd"), "{e}");
    }
}
