//! The evidence under priors widened ten-fold. Each law parameter's prior keeps its centre and
//! family and gets ten times its width in its natural scale: log-uniform `[lo, hi]` becomes
//! log-uniform about the geometric centre `c = sqrt(lo hi)` with `ln(hi'/c) = 10 ln(hi/c)`;
//! uniform and truncated normal get ten times their half-width (and sd) about the centre
//! (mean); log-normal ten times `sigma_ln`. Noise priors are unchanged. The widened evidence is
//! `Z_w = Z E_post[p_w(theta) / p(theta)]` (importance reweighting of posterior draws), exact
//! when the likelihood is negligible outside the declared support; `inside_sd`, the smallest
//! distance of any law parameter's posterior mean to a bound of its declared support in
//! posterior sds (in the prior's own coordinate: log for log priors), says whether that holds
//! (it does beyond about 5). For log-uniform priors the ratio is constant inside the support
//! and the shift is exactly `-d ln 10` for `d` parameters (the unit test below; the suite's
//! `model_comparison` test checks it on a run).

use crate::inference::prior::Prior;

/// The prior widened ten-fold about its centre (see the module documentation).
pub fn widened(p: &Prior) -> Prior {
    match *p {
        Prior::LogUniform { lo, hi } => {
            let c = (lo.ln() + hi.ln()) / 2.0;
            let h = (hi.ln() - lo.ln()) / 2.0;
            Prior::LogUniform {
                lo: (c - 10.0 * h).exp(),
                hi: (c + 10.0 * h).exp(),
            }
        }
        Prior::Uniform { lo, hi } => {
            let (c, h) = ((lo + hi) / 2.0, (hi - lo) / 2.0);
            Prior::Uniform {
                lo: c - 10.0 * h,
                hi: c + 10.0 * h,
            }
        }
        Prior::LogNormal { median, sigma_ln } => Prior::LogNormal {
            median,
            sigma_ln: 10.0 * sigma_ln,
        },
        Prior::TruncatedNormal { mean, sd, lo, hi } => Prior::TruncatedNormal {
            mean,
            sd: 10.0 * sd,
            lo: mean - 10.0 * (mean - lo),
            hi: mean + 10.0 * (hi - mean),
        },
    }
}

fn log_mean_exp(v: &[f64]) -> f64 {
    let m = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if !m.is_finite() {
        return m;
    }
    m + (v.iter().map(|x| (x - m).exp()).sum::<f64>() / v.len() as f64).ln()
}

/// `ln E_post[p_w / p]` over posterior draws `values[param][row]` of the law's `nl`
/// parameters, with its delta-method standard error (independent draws assumed).
pub fn widening_shift(priors: &[Prior], values: &[Vec<f64>], nl: usize) -> (f64, f64) {
    let n = values.first().map_or(0, |c| c.len());
    if n == 0 {
        return (f64::NAN, f64::NAN);
    }
    let lr: Vec<f64> = (0..n)
        .map(|r| {
            (0..nl)
                .map(|k| {
                    let v = values[k][r];
                    widened(&priors[k]).log_density_physical(v) - priors[k].log_density_physical(v)
                })
                .sum()
        })
        .collect();
    let lme = log_mean_exp(&lr);
    let w: Vec<f64> = lr.iter().map(|l| (l - lme).exp()).collect();
    let var = w.iter().map(|x| (x - 1.0).powi(2)).sum::<f64>() / n as f64;
    (lme, (var / n as f64).sqrt())
}

/// Distance of each posterior mean to the declared bounds in posterior sds, minimum over
/// the law's parameters (in log coordinates for log-uniform priors).
pub(super) fn inside_sd(priors: &[Prior], values: &[Vec<f64>], nl: usize) -> f64 {
    let mut out = f64::INFINITY;
    for (prior, values) in priors.iter().zip(values).take(nl) {
        let (bounds, log) = match *prior {
            Prior::LogUniform { lo, hi } => ((lo, hi), true),
            Prior::Uniform { lo, hi } | Prior::TruncatedNormal { lo, hi, .. } => ((lo, hi), false),
            Prior::LogNormal { .. } => continue,
        };
        let f = |v: f64| if log { v.ln() } else { v };
        let col: Vec<f64> = values.iter().map(|v| f(*v)).collect();
        let n = col.len() as f64;
        let m = col.iter().sum::<f64>() / n;
        let sd = (col.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
        let d = (m - f(bounds.0)).min(f(bounds.1) - m) / sd;
        out = out.min(d);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn widening_a_log_uniform_prior_costs_ln_10_per_parameter() {
        let priors = vec![
            Prior::LogUniform { lo: 1e5, hi: 1e7 },
            Prior::LogUniform { lo: 1.0, hi: 1e2 },
        ];
        let w = widened(&priors[0]);
        match w {
            Prior::LogUniform { lo, hi } => {
                assert!((lo.log10() + 4.0).abs() < 1e-12 && (hi.log10() - 16.0).abs() < 1e-12)
            }
            _ => panic!(),
        }
        let values = vec![vec![1e6, 2e6, 3e6], vec![10.0, 11.0, 12.0]];
        let (s, se) = widening_shift(&priors, &values, 2);
        assert!((s + 2.0 * 10f64.ln()).abs() < 1e-12, "{s}");
        assert!(se.abs() < 1e-12);
    }
}
