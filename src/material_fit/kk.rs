//! Causal (Kramers-Kronig) consistency of measured E'(w) and E''(w).
//!
//! A linear, causal, passive material has a non-negative relaxation spectrum, and every such
//! modulus is (to any accuracy) a generalized Maxwell series with non-negative weights on a
//! fine grid of relaxation times:
//!
//! E'(w) = E_inf + sum_k E_k (w tau_k)^2 / (1 + (w tau_k)^2),  E''(w) = sum_k E_k w tau_k / (1 + (w tau_k)^2).
//!
//! The pair of sums is the Kramers-Kronig pair of one spectrum, so the transforms are computed
//! through it (the discrete-spectrum form of the KK relations, as in Tschoegl 1989, ch. 4):
//!
//! * E'' implied by E': the weights (and E_inf) fitted to E' alone by non-negative least squares
//!   (relative errors), then the loss sum evaluated;
//! * E' implied by E'': the weights fitted to E'' alone, then the storage sum; E' is fixed by
//!   E'' only up to the constant E_inf, which is set by least squares against the measured E';
//! * the best causal fit: both fitted together. Its residual is the floor no causal law with a
//!   positive spectrum (Maxwell branches, fractional branches) can go below.
//!
//! Extrapolation: the grid runs one decade beyond the data's window at each end (`per_decade`
//! times per decade); relaxation beyond the window is represented only by those end terms, so
//! the transforms in the first and last decade of the data are the least certain.
//!
//! The one-sided transforms are ill-posed where one quantity is nearly flat (E'' is about
//! (pi / 2) dE'/d ln w, a derivative of noisy data), so the flag uses the joint causal fit: a
//! point is non-causal when the 5-point moving average of that fit's log residual (E' or E'')
//! exceeds `threshold` times its white-noise sd (the successive-difference scatter over
//! sqrt 5): no non-negative spectrum follows the data there, beyond its scatter.

use super::nnls::nnls;
use super::posterior::MasterCurve;
use super::residual::residual_stats;

/// The result of the check; log10 residuals are measured minus implied.
#[derive(Clone, Debug, PartialEq)]
pub struct KkCheck {
    pub tau_s: Vec<f64>,
    /// E'' implied by E' (Pa), per data point.
    pub loss_from_storage_pa: Vec<f64>,
    /// E' implied by E'' (Pa), per data point.
    pub storage_from_loss_pa: Vec<f64>,
    /// The best causal fit to both (Pa).
    pub causal_storage_pa: Vec<f64>,
    pub causal_loss_pa: Vec<f64>,
    /// log10(measured E'') - log10(E'' implied by E').
    pub res_loss_from_storage: Vec<f64>,
    /// log10(measured E') - log10(E' implied by E'').
    pub res_storage_from_loss: Vec<f64>,
    /// RMS log10 error of the best causal fit, of E' and of E''.
    pub causal_rms_log10_storage: f64,
    pub causal_rms_log10_loss: f64,
    /// Point-to-point scatter (log10) of E' and E'' about the causal fit (successive differences).
    pub scatter_log10_storage: f64,
    pub scatter_log10_loss: f64,
    /// log10 residuals of the best causal fit (measured / causal).
    pub res_causal_storage: Vec<f64>,
    pub res_causal_loss: Vec<f64>,
    /// Per point: the smoothed causal-fit residual exceeds `threshold` white-noise sds.
    pub non_causal: Vec<bool>,
    pub threshold: f64,
    /// Frequency intervals (Hz) of consecutive flagged points.
    pub regions_hz: Vec<(f64, f64)>,
}

fn columns(omega: &[f64], tau: &[f64], with_inf: bool) -> (Vec<f64>, Vec<f64>, usize) {
    let n = tau.len() + usize::from(with_inf);
    let mut s = Vec::with_capacity(omega.len() * n);
    let mut l = Vec::with_capacity(omega.len() * n);
    for &w in omega {
        if with_inf {
            s.push(1.0);
            l.push(0.0);
        }
        for &t in tau {
            let a = w * t;
            let d = 1.0 + a * a;
            s.push(a * a / d);
            l.push(a / d);
        }
    }
    (s, l, n)
}

fn mat_vec(a: &[f64], n: usize, x: &[f64]) -> Vec<f64> {
    a.chunks(n)
        .map(|row| row.iter().zip(x).map(|(a, b)| a * b).sum())
        .collect()
}

/// Rows of `a` divided by `data`, and the right-hand side ones: relative least squares.
fn relative(a: &[f64], n: usize, data: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let mut out = a.to_vec();
    for (row, d) in out.chunks_mut(n).zip(data) {
        row.iter_mut().for_each(|v| *v /= d);
    }
    (out, vec![1.0; data.len()])
}

fn log10_res(data: &[f64], model: &[f64]) -> Vec<f64> {
    data.iter()
        .zip(model)
        .map(|(d, m)| d.log10() - m.max(1e-300).log10())
        .collect()
}

fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
}

/// The relaxation-time grid of the check: `per_decade` per decade, one decade beyond the
/// data's window at each end.
pub fn tau_grid(curve: &MasterCurve, per_decade: f64) -> Vec<f64> {
    let omega = curve.omega();
    let m = omega.len();
    let (t_lo, t_hi) = (0.1 / omega[m - 1], 10.0 / omega[0]);
    let nt = ((t_hi / t_lo).log10() * per_decade).ceil().max(2.0) as usize + 1;
    (0..nt)
        .map(|k| t_lo * (t_hi / t_lo).powf(k as f64 / (nt - 1) as f64))
        .collect()
}

/// The best causal fit (E', E'' in Pa per point): non-negative E_inf and weights on `tau`
/// minimising sum ((E'_model - E')/(s' E'))^2 + sum ((E''_model - E'')/(s'' E''))^2, the
/// linearisation of a log-residual fit with scatters `s'` and `s''`.
pub fn causal_fit(
    curve: &MasterCurve,
    tau: &[f64],
    s_storage: f64,
    s_loss: f64,
) -> (Vec<f64>, Vec<f64>) {
    let omega = curve.omega();
    let m = omega.len();
    let (s1, l1, n1) = columns(&omega, tau, true);
    let ws: Vec<f64> = curve.storage_pa.iter().map(|v| v * s_storage).collect();
    let wl: Vec<f64> = curve.loss_pa.iter().map(|v| v * s_loss).collect();
    let (mut a, mut b) = relative(&s1, n1, &ws);
    let (a_l, b_l) = relative(&l1, n1, &wl);
    b.iter_mut().for_each(|v| *v /= s_storage);
    a.extend(a_l);
    b.extend(b_l.iter().map(|v| v / s_loss));
    let c = nnls(&a, 2 * m, n1, &b);
    (mat_vec(&s1, n1, &c), mat_vec(&l1, n1, &c))
}

/// The check on `curve` with `per_decade` relaxation times per decade and the flag threshold
/// `threshold` (in white-noise sds of the smoothed causal residual, e.g. 3).
pub fn kk_check(curve: &MasterCurve, per_decade: f64, threshold: f64) -> KkCheck {
    let omega = curve.omega();
    let m = omega.len();
    let tau = tau_grid(curve, per_decade);
    let (s1, l1, n1) = columns(&omega, &tau, true);
    // E'' from E'.
    let (a, b) = relative(&s1, n1, &curve.storage_pa);
    let c = nnls(&a, m, n1, &b);
    let loss_from_storage = mat_vec(&l1, n1, &c);
    // E' from E'' (E_inf by least squares on E' afterwards).
    let (_, l0, n0) = columns(&omega, &tau, false);
    let (s0, _, _) = columns(&omega, &tau, false);
    let (a, b) = relative(&l0, n0, &curve.loss_pa);
    let c = nnls(&a, m, n0, &b);
    let s_part = mat_vec(&s0, n0, &c);
    let (num, den) = curve
        .storage_pa
        .iter()
        .zip(&s_part)
        .fold((0.0, 0.0), |(n, d), (e, s)| {
            (n + (e - s) / (e * e), d + 1.0 / (e * e))
        });
    let e_inf = (num / den).max(0.0);
    let storage_from_loss: Vec<f64> = s_part.iter().map(|v| v + e_inf).collect();
    // Joint causal fit, equal relative weights.
    let (causal_storage, causal_loss) = causal_fit(curve, &tau, 1.0, 1.0);
    let rs = log10_res(&curve.storage_pa, &causal_storage);
    let rl = log10_res(&curve.loss_pa, &causal_loss);
    let ss = residual_stats(&rs).scatter_sd;
    let sl = residual_stats(&rl).scatter_sd;
    let res_l = log10_res(&curve.loss_pa, &loss_from_storage);
    let res_s = log10_res(&curve.storage_pa, &storage_from_loss);
    let smooth = |r: &[f64]| -> Vec<f64> {
        (0..m)
            .map(|i| {
                let (a, b) = (i.saturating_sub(2), (i + 3).min(m));
                r[a..b].iter().sum::<f64>() / (b - a) as f64
            })
            .collect()
    };
    let (ms, ml) = (smooth(&rs), smooth(&rl));
    let k5 = threshold / 5f64.sqrt();
    let non_causal: Vec<bool> = (0..m)
        .map(|i| ms[i].abs() > k5 * ss || ml[i].abs() > k5 * sl)
        .collect();
    let mut regions = Vec::new();
    let mut i = 0;
    while i < m {
        if non_causal[i] {
            let j0 = i;
            while i + 1 < m && non_causal[i + 1] {
                i += 1;
            }
            regions.push((curve.freq_hz[j0], curve.freq_hz[i]));
        }
        i += 1;
    }
    KkCheck {
        tau_s: tau,
        loss_from_storage_pa: loss_from_storage,
        storage_from_loss_pa: storage_from_loss,
        causal_rms_log10_storage: rms(&rs),
        causal_rms_log10_loss: rms(&rl),
        causal_storage_pa: causal_storage,
        causal_loss_pa: causal_loss,
        res_loss_from_storage: res_l,
        res_storage_from_loss: res_s,
        res_causal_storage: rs,
        res_causal_loss: rl,
        scatter_log10_storage: ss,
        scatter_log10_loss: sl,
        non_causal,
        threshold,
        regions_hz: regions,
    }
}
