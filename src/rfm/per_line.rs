//! Nonparametric RFM: an independent E*(w) at every frequency line (paper eq. 10-11 iterated;
//! the per-line estimates of the paper's Fig. 13 and 18).

use super::linearise::{linearise_mapped, validate};
use super::{MeasuredColumn, RfmError, RfmParams};
use crate::common::C64;
use crate::frf::FrfEngine;

/// The per-line estimates at one frequency line.
#[derive(Clone, Debug, PartialEq)]
pub struct PerLineEstimate {
    pub omega_rad_s: f64,
    /// E*(w) from FRF k alone (E* <- E* + B_k), one per output of the data (Pa).
    pub modulus_per_frf: Vec<C64>,
    /// Whether each per-FRF iteration converged (|dE*|/|E*| < tol).
    pub converged_per_frf: Vec<bool>,
    /// Iterations used per FRF.
    pub iterations_per_frf: Vec<usize>,
    /// E*(w) from all FRFs together: E* <- E* + mean_k B_k, the least-squares solution of the
    /// stacked eq. 11 at this line (Pa).
    pub modulus_combined: C64,
    pub converged_combined: bool,
    pub iterations_combined: usize,
}

/// Per line: the modulus, whether it converged, and the iterations used.
type Track = (Vec<C64>, Vec<bool>, Vec<usize>);

/// Iterate E*(w) <- E*(w) + update at every line; `select` = Some(k) uses B of FRF k, None the
/// mean over FRFs. Lines iterate independently (one sweep per iteration covers the lines still
/// active). A line stops unconverged when E* becomes non-finite, E' <= 0, or the engine fails.
fn iterate(
    engine: &dyn FrfEngine,
    map: &super::linearise::InputMap,
    data: &MeasuredColumn,
    e0: &[C64],
    select: Option<usize>,
    params: &RfmParams,
) -> Result<Track, RfmError> {
    let n_lines = data.n_lines();
    let n_k = data.outputs.len();
    let mut e: Vec<C64> = e0.to_vec();
    let mut converged = vec![false; n_lines];
    let mut iterations = vec![0usize; n_lines];
    let mut active: Vec<usize> = (0..n_lines).collect();
    for _ in 0..params.max_iterations {
        if active.is_empty() {
            break;
        }
        let omega: Vec<f64> = active.iter().map(|&l| data.omega_rad_s[l]).collect();
        let modulus: Vec<C64> = active.iter().map(|&l| e[l]).collect();
        let lin = match engine.sweep(&omega, &modulus, true) {
            Ok(sweep) => linearise_mapped(map, data, &sweep, &active, params.denominator),
            Err(err) => Err(RfmError::Frf(err)),
        };
        // One bad line must not stop the others: on failure, fall back to line-by-line evaluation.
        let lin = lin.ok();
        let mut still = Vec::with_capacity(active.len());
        for (a, &l) in active.iter().enumerate() {
            let bs: Option<Vec<C64>> = match &lin {
                Some(lin) => Some(lin.b[a * n_k..(a + 1) * n_k].to_vec()),
                None => engine
                    .sweep(&[data.omega_rad_s[l]], &[e[l]], true)
                    .ok()
                    .and_then(|s| linearise_mapped(map, data, &s, &[l], params.denominator).ok())
                    .map(|lin| lin.b),
            };
            let Some(bs) = bs else {
                continue; // engine failed at this line: stop it, unconverged
            };
            let mut de = match select {
                Some(k) => bs[k],
                None => bs.iter().sum::<C64>() / n_k as f64,
            };
            let limit = params.max_rel_modulus_step * e[l].norm();
            if de.norm() > limit {
                de *= limit / de.norm();
            }
            let new = e[l] + de;
            iterations[l] += 1;
            if !(new.re.is_finite() && new.im.is_finite()) || new.re <= 0.0 {
                continue; // diverged: keep the last finite value, unconverged
            }
            e[l] = new;
            if de.norm() <= params.tol_rel_change * new.norm() {
                converged[l] = true;
            } else {
                still.push(l);
            }
        }
        active = still;
    }
    Ok((e, converged, iterations))
}

/// Nonparametric per-line RFM estimates of E*(w), per FRF and combined. `e0` holds the
/// initial modulus (Pa): one value for every line, or one per data line.
pub fn rfm_per_line(
    engine: &dyn FrfEngine,
    data: &MeasuredColumn,
    e0: &[C64],
    params: &RfmParams,
) -> Result<Vec<PerLineEstimate>, RfmError> {
    let map = validate(engine, data)?;
    let n_lines = data.n_lines();
    let init: Vec<C64> = match e0.len() {
        1 => vec![e0[0]; n_lines],
        n if n == n_lines => e0.to_vec(),
        n => {
            return Err(RfmError::Data(format!(
                "{n} initial moduli given; give one, or one per line ({n_lines})"
            )))
        }
    };
    if let Some(bad) = init
        .iter()
        .find(|e| !(e.re.is_finite() && e.im.is_finite() && e.re > 0.0))
    {
        return Err(RfmError::Data(format!(
            "initial modulus {bad} Pa: the storage modulus must be finite and positive"
        )));
    }
    let n_k = data.outputs.len();
    let mut per_frf = Vec::with_capacity(n_k);
    for k in 0..n_k {
        per_frf.push(iterate(engine, &map, data, &init, Some(k), params)?);
    }
    let (ec, cc, ic) = iterate(engine, &map, data, &init, None, params)?;
    Ok((0..n_lines)
        .map(|l| PerLineEstimate {
            omega_rad_s: data.omega_rad_s[l],
            modulus_per_frf: per_frf.iter().map(|(e, _, _)| e[l]).collect(),
            converged_per_frf: per_frf.iter().map(|(_, c, _)| c[l]).collect(),
            iterations_per_frf: per_frf.iter().map(|(_, _, i)| i[l]).collect(),
            modulus_combined: ec[l],
            converged_combined: cc[l],
            iterations_combined: ic[l],
        })
        .collect())
}
