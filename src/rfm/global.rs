//! Global RFM updating of a constitutive model over a band (paper eq. 37), and the constant
//! modulus over a band as its two-parameter special case.

use super::linearise::{frac, linearise_mapped, validate, InputMap, Linearisation};
use super::{MeasuredColumn, RfmError, RfmParams, StopReason};
use crate::common::{C64, J};
use crate::frf::{FrfEngine, FrfError};
use crate::material::ConstitutiveModel;
use faer::Mat;

/// One row of the convergence history (the paper's Fig. 8). Record 0 is the initial point.
#[derive(Clone, Debug, PartialEq)]
pub struct IterationRecord {
    /// Iteration number (0 = initial values).
    pub iteration: usize,
    /// Parameters after this update (SI units).
    pub params: Vec<f64>,
    /// max_k |p_k(new) - p_k(old)| / |p_k(old)| (0 for record 0).
    pub relative_change: f64,
    /// Modulus residual ||D|| = sqrt(sum |B_il|^2) at these parameters (Pa).
    pub residual_modulus_pa: f64,
    /// FRF residual sqrt(sum |H'_A - H'_X|^2 / sum |H'_X|^2) at these parameters.
    pub frf_relative_residual: f64,
    /// FRAC per FRF (paper eq. 38) at these parameters.
    pub frac: Vec<f64>,
    /// Numerical rank of U at the linearisation that produced this update (0 for record 0).
    pub rank: usize,
    /// Step scale actually taken (1 = full SVD step; < 1 after limiting or halving).
    pub step_scale: f64,
}

/// A poorly determined parameter combination: a right singular vector of U (in log-parameters,
/// i.e. relative parameter changes) with its singular value.
#[derive(Clone, Debug, PartialEq)]
pub struct WeakDirection {
    pub singular_value: f64,
    /// Unit vector over the parameters (d ln p).
    pub direction: Vec<f64>,
}

/// Result of [`rfm_global`].
#[derive(Clone, Debug)]
pub struct RfmResult {
    pub model_name: String,
    pub param_names: Vec<String>,
    /// Initial parameters.
    pub initial: Vec<f64>,
    /// Final parameters (SI units).
    pub params: Vec<f64>,
    /// Number of updates made.
    pub iterations: usize,
    pub stop_reason: StopReason,
    /// Convergence history, record 0 = initial values.
    pub history: Vec<IterationRecord>,
    /// Singular values of U (columns scaled by p, i.e. in log-parameters) at the last
    /// linearisation, nonincreasing (Pa).
    pub singular_values: Vec<f64>,
    /// s_max / s_min (infinite when s_min = 0).
    pub condition_number: f64,
    /// Numerical rank at the last linearisation (s > rcond s_max).
    pub rank: usize,
    /// Poorly determined combinations: the smallest singular direction, plus all with
    /// s < weak_ratio s_max.
    pub weak_directions: Vec<WeakDirection>,
    /// FRAC per FRF at the final parameters.
    pub frac: Vec<f64>,
    /// E*(w) at the final parameters, one per data line (Pa).
    pub modulus: Vec<C64>,
}

/// Result of [`rfm_band_constant`].
#[derive(Clone, Debug)]
pub struct BandResult {
    /// The constant modulus identified over the band (Pa).
    pub modulus: C64,
    /// The band (Hz) and number of lines used.
    pub band_hz: (f64, f64),
    pub n_lines: usize,
    /// The underlying two-parameter run (parameters E', E'').
    pub run: RfmResult,
}

/// A frequency-independent modulus E* = E' + j E'' (the same law as the paper's Model 1), used
/// by [`rfm_band_constant`].
#[derive(Clone, Copy, Debug, Default)]
pub struct ConstantModulus;

impl ConstitutiveModel for ConstantModulus {
    fn name(&self) -> &str {
        "constant"
    }
    fn description(&self) -> String {
        "constant complex modulus over a band: E' + j E''".into()
    }
    fn param_names(&self) -> Vec<String> {
        vec!["E'".into(), "E''".into()]
    }
    fn param_units(&self) -> Vec<String> {
        vec!["Pa".into(), "Pa".into()]
    }
    fn bounds(&self) -> Vec<(f64, f64)> {
        vec![(0.0, f64::INFINITY), (0.0, f64::INFINITY)]
    }
    fn modulus(&self, p: &[f64], _omega_rad_s: f64) -> C64 {
        C64::new(p[0], p[1])
    }
    fn jacobian(&self, _p: &[f64], _omega_rad_s: f64, out: &mut [C64]) {
        out[0] = C64::new(1.0, 0.0);
        out[1] = J;
    }
}

/// The model evaluated at one parameter vector.
struct State {
    lin: Linearisation,
    modulus: Vec<C64>,
    residual_modulus_pa: f64,
    frf_relative_residual: f64,
    frac: Vec<f64>,
}

fn evaluate(
    engine: &dyn FrfEngine,
    map: &InputMap,
    data: &MeasuredColumn,
    model: &dyn ConstitutiveModel,
    p: &[f64],
    params: &RfmParams,
) -> Result<State, RfmError> {
    let lines: Vec<usize> = (0..data.n_lines()).collect();
    let modulus: Vec<C64> = data
        .omega_rad_s
        .iter()
        .map(|&w| model.modulus(p, w))
        .collect();
    if modulus
        .iter()
        .any(|e| !(e.re.is_finite() && e.im.is_finite()))
    {
        return Err(RfmError::Frf(FrfError::Other(format!(
            "model {} gives a non-finite modulus at parameters {p:?}",
            model.name()
        ))));
    }
    let sweep = engine.sweep(&data.omega_rad_s, &modulus, true)?;
    let lin = linearise_mapped(map, data, &sweep, &lines, params.denominator)?;
    let residual_modulus_pa = lin.b.iter().map(|b| b.norm_sqr()).sum::<f64>().sqrt();
    let (mut rr, mut xx) = (0.0, 0.0);
    for (a, x) in lin.analytical.iter().zip(&data.accelerance) {
        rr += (a - x).norm_sqr();
        xx += x.norm_sqr();
    }
    let frf_relative_residual = if xx > 0.0 {
        (rr / xx).sqrt()
    } else {
        rr.sqrt()
    };
    let frac = (0..data.outputs.len())
        .map(|k| frac(data, &lin.analytical, &lines, k))
        .collect();
    Ok(State {
        lin,
        modulus,
        residual_modulus_pa,
        frf_relative_residual,
        frac,
    })
}

fn describe_params(model: &dyn ConstitutiveModel, p: &[f64]) -> String {
    let names = model.param_names();
    let units = model.param_units();
    p.iter()
        .enumerate()
        .map(|(k, v)| {
            format!(
                "{} = {v:e} {}",
                names.get(k).map(String::as_str).unwrap_or("?"),
                units.get(k).map(String::as_str).unwrap_or("")
            )
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// p exp(dq) for positive-bounded parameters, p + |p| dq otherwise.
fn apply_step(p: &[f64], dq: &[f64], t: f64, bounds: &[(f64, f64)]) -> Vec<f64> {
    p.iter()
        .zip(dq)
        .zip(bounds)
        .map(|((&pk, &d), &(lo, _))| {
            if lo >= 0.0 && pk > 0.0 {
                pk * (t * d).exp()
            } else {
                pk + pk.abs().max(f64::MIN_POSITIVE) * t * d
            }
        })
        .collect()
}

fn admissible(p: &[f64], bounds: &[(f64, f64)]) -> bool {
    p.iter()
        .zip(bounds)
        .all(|(&v, &(lo, hi))| v.is_finite() && v > lo && v < hi)
}

/// Truncated SVD solution of U dq = D.
struct SvdSolution {
    dq: Vec<f64>,
    /// Singular values, nonincreasing.
    s: Vec<f64>,
    rank: usize,
    /// Right singular vectors as columns.
    v: Mat<f64>,
}

/// Minimum-norm solution of U dq = D over the singular values above `rcond * s_max`.
fn svd_solve(u: &Mat<f64>, d: &[f64], rcond: f64) -> Result<SvdSolution, RfmError> {
    let svd = u.thin_svd().map_err(|e| RfmError::Svd(format!("{e:?}")))?;
    let s: Vec<f64> = svd.S().column_vector().iter().copied().collect();
    let uu = svd.U();
    let v = svd.V().to_owned();
    let n_p = u.ncols();
    let s_max = s.first().copied().unwrap_or(0.0);
    let cut = rcond * s_max;
    let rank = s.iter().filter(|&&x| x > cut && x > 0.0).count();
    let mut dq = vec![0.0; n_p];
    for c in 0..rank {
        let coef: f64 = (0..u.nrows()).map(|r| uu[(r, c)] * d[r]).sum::<f64>() / s[c];
        for (k, x) in dq.iter_mut().enumerate() {
            *x += v[(k, c)] * coef;
        }
    }
    Ok(SvdSolution { dq, s, rank, v })
}

/// Global RFM updating of a constitutive model over the data's lines (paper eq. 37), see the
/// module doc of [`crate::rfm`]. `p0` are the initial parameters (SI units), inside the
/// model's admissible range.
pub fn rfm_global(
    engine: &dyn FrfEngine,
    data: &MeasuredColumn,
    model: &dyn ConstitutiveModel,
    p0: &[f64],
    params: &RfmParams,
) -> Result<RfmResult, RfmError> {
    let map = validate(engine, data)?;
    let n_p = model.n_params();
    if p0.len() != n_p {
        return Err(RfmError::ParamCount {
            model: model.name().to_string(),
            expected: n_p,
            got: p0.len(),
        });
    }
    let bounds = model.bounds();
    let names = model.param_names();
    for (k, (&v, &(lo, hi))) in p0.iter().zip(&bounds).enumerate() {
        if !(v.is_finite() && v > lo && v < hi) {
            return Err(RfmError::InadmissibleInitial {
                name: names.get(k).cloned().unwrap_or_default(),
                value: v,
                lo,
                hi,
            });
        }
    }
    let mut state = match evaluate(engine, &map, data, model, p0, params) {
        Ok(s) => s,
        Err(RfmError::Frf(source)) => {
            return Err(RfmError::SingularInitial {
                params: describe_params(model, p0),
                source,
            })
        }
        Err(e) => return Err(e),
    };
    let residual0 = state.residual_modulus_pa;
    let mut p = p0.to_vec();
    let mut history = vec![IterationRecord {
        iteration: 0,
        params: p.clone(),
        relative_change: 0.0,
        residual_modulus_pa: state.residual_modulus_pa,
        frf_relative_residual: state.frf_relative_residual,
        frac: state.frac.clone(),
        rank: 0,
        step_scale: 0.0,
    }];
    let n_k = data.outputs.len();
    let n_rows = 2 * data.n_lines() * n_k;
    let mut jac = vec![C64::new(0.0, 0.0); n_p];
    let mut stop = StopReason::MaxIterations;
    let mut last_svd: Option<(Vec<f64>, usize, Mat<f64>)> = None;
    let mut iterations = 0;
    for it in 1..=params.max_iterations {
        // U (rows [Re; Im] per (line, FRF)) in log-parameters, D = [Re B; Im B].
        let mut u = Mat::<f64>::zeros(n_rows, n_p);
        let mut d = vec![0.0; n_rows];
        for (l, &w) in data.omega_rad_s.iter().enumerate() {
            model.jacobian(&p, w, &mut jac);
            for k in 0..n_k {
                let r = 2 * (l * n_k + k);
                let b = state.lin.b[l * n_k + k];
                d[r] = b.re;
                d[r + 1] = b.im;
                for c in 0..n_p {
                    let scale = if bounds[c].0 >= 0.0 && p[c] > 0.0 {
                        p[c]
                    } else {
                        p[c].abs().max(f64::MIN_POSITIVE)
                    };
                    u[(r, c)] = jac[c].re * scale;
                    u[(r + 1, c)] = jac[c].im * scale;
                }
            }
        }
        if !u.as_ref().is_all_finite() {
            stop = StopReason::Diverged;
            break;
        }
        let SvdSolution { dq, s, rank, v } = svd_solve(&u, &d, params.rcond)?;
        last_svd = Some((s, rank, v));
        // Limit the log step, then halve until admissible and non-singular.
        let max_step = dq.iter().fold(0.0_f64, |a, x| a.max(x.abs()));
        let mut t = if max_step > params.max_log_step {
            params.max_log_step / max_step
        } else {
            1.0
        };
        let mut accepted = None;
        for _ in 0..=params.max_step_halvings {
            let cand = apply_step(&p, &dq, t, &bounds);
            if admissible(&cand, &bounds) {
                if let Ok(s) = evaluate(engine, &map, data, model, &cand, params) {
                    if s.residual_modulus_pa.is_finite() {
                        accepted = Some((cand, s));
                        break;
                    }
                }
            }
            t *= 0.5;
        }
        let Some((cand, new_state)) = accepted else {
            stop = StopReason::Diverged;
            break;
        };
        iterations = it;
        let rel = p
            .iter()
            .zip(&cand)
            .map(|(a, b)| (b - a).abs() / a.abs().max(f64::MIN_POSITIVE))
            .fold(0.0_f64, f64::max);
        p = cand;
        state = new_state;
        history.push(IterationRecord {
            iteration: it,
            params: p.clone(),
            relative_change: rel,
            residual_modulus_pa: state.residual_modulus_pa,
            frf_relative_residual: state.frf_relative_residual,
            frac: state.frac.clone(),
            rank,
            step_scale: t,
        });
        if state.residual_modulus_pa > params.divergence_factor * residual0.max(f64::MIN_POSITIVE) {
            stop = StopReason::Diverged;
            break;
        }
        if rel < params.tol_rel_change {
            stop = if rank < n_p {
                StopReason::RankDeficient
            } else {
                StopReason::Converged
            };
            break;
        }
    }
    let (singular_values, rank, v) =
        last_svd.unwrap_or_else(|| (Vec::new(), 0, Mat::zeros(n_p, 0)));
    let s_max = singular_values.first().copied().unwrap_or(0.0);
    let s_min = singular_values.last().copied().unwrap_or(0.0);
    let condition_number = if s_min > 0.0 {
        s_max / s_min
    } else {
        f64::INFINITY
    };
    let mut weak_directions = Vec::new();
    for (c, &s) in singular_values.iter().enumerate() {
        if c + 1 == singular_values.len() || s < params.weak_ratio * s_max {
            weak_directions.push(WeakDirection {
                singular_value: s,
                direction: (0..n_p).map(|k| v[(k, c)]).collect(),
            });
        }
    }
    Ok(RfmResult {
        model_name: model.name().to_string(),
        param_names: names,
        initial: p0.to_vec(),
        params: p,
        iterations,
        stop_reason: stop,
        history,
        singular_values,
        condition_number,
        rank,
        weak_directions,
        frac: state.frac,
        modulus: state.modulus,
    })
}

/// A constant modulus E* over the band [lo_hz, hi_hz] of the data (Model 1 over a 10 Hz band
/// around a resonance, case study 1): eq. 37 with dE*/dp = [1, j], i.e. the least-squares mean
/// of B over all lines and FRFs in the band, iterated. `e0` is the initial modulus (Pa), with
/// positive real and imaginary parts.
pub fn rfm_band_constant(
    engine: &dyn FrfEngine,
    data: &MeasuredColumn,
    band_hz: (f64, f64),
    e0: C64,
    params: &RfmParams,
) -> Result<BandResult, RfmError> {
    let sub = data.restrict_to_band(band_hz.0, band_hz.1);
    if sub.n_lines() == 0 {
        return Err(RfmError::EmptyBand {
            lo_hz: band_hz.0,
            hi_hz: band_hz.1,
        });
    }
    let run = rfm_global(engine, &sub, &ConstantModulus, &[e0.re, e0.im], params)?;
    Ok(BandResult {
        modulus: C64::new(run.params[0], run.params[1]),
        band_hz,
        n_lines: sub.n_lines(),
        run,
    })
}
