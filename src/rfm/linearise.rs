//! The RFM update B_ij(w) (paper eq. 9) from one engine sweep; see the module doc of
//! [`crate::rfm`] for the denominator in terms of the engine's outputs.

use super::{Denominator, MeasuredColumn, RfmError};
use crate::common::C64;
use crate::frf::{FrfEngine, Sweep};

/// Positions of the measured column's points among the engine's inputs.
#[derive(Clone, Debug)]
pub(crate) struct InputMap {
    /// Position of `data.input` in `engine.inputs()`.
    pub j: usize,
    /// Position of each `data.outputs[k]` in `engine.inputs()`.
    pub out_pos: Vec<usize>,
}

/// Check the measured column against the engine and locate its points among the inputs.
pub(crate) fn validate(
    engine: &dyn FrfEngine,
    data: &MeasuredColumn,
) -> Result<InputMap, RfmError> {
    let n_lines = data.n_lines();
    let n_k = data.outputs.len();
    if n_lines == 0 {
        return Err(RfmError::Data("no frequency lines".into()));
    }
    if n_k == 0 {
        return Err(RfmError::Data(
            "no response points (outputs is empty)".into(),
        ));
    }
    if data.accelerance.len() != n_lines * n_k {
        return Err(RfmError::Data(format!(
            "accelerance has {} values, expected lines x outputs = {} x {} = {}",
            data.accelerance.len(),
            n_lines,
            n_k,
            n_lines * n_k
        )));
    }
    if let Some((l, w)) = data
        .omega_rad_s
        .iter()
        .enumerate()
        .find(|(_, w)| !(w.is_finite() && **w > 0.0))
    {
        return Err(RfmError::Data(format!(
            "frequency line {l} is {w} rad/s; lines must be finite and positive (drop the 0 Hz line)"
        )));
    }
    if let Some(i) = data
        .accelerance
        .iter()
        .position(|a| !(a.re.is_finite() && a.im.is_finite()))
    {
        return Err(RfmError::Data(format!(
            "accelerance at line {}, output {} is not finite",
            i / n_k,
            data.outputs[i % n_k]
        )));
    }
    let n_out = engine.n_out();
    let inputs = engine.inputs();
    let find = |p: usize, role: &'static str| -> Result<usize, RfmError> {
        if p >= n_out {
            return Err(RfmError::PointOutOfRange { point: p, n_out });
        }
        inputs
            .iter()
            .position(|&q| q == p)
            .ok_or(RfmError::EngineInputs { point: p, role })
    };
    let j = find(data.input, "excitation point")?;
    let mut out_pos = Vec::with_capacity(n_k);
    for (k, &p) in data.outputs.iter().enumerate() {
        if data.outputs[..k].contains(&p) {
            return Err(RfmError::Data(format!(
                "response point {p} is listed twice"
            )));
        }
        out_pos.push(find(p, "response point")?);
    }
    Ok(InputMap { j, out_pos })
}

/// The RFM quantities at every (line, FRF) of one sweep, `[line][k]` flattened like
/// [`MeasuredColumn::accelerance`].
#[derive(Clone, Debug, Default)]
pub struct Linearisation {
    /// B_ij (Pa): the modulus update of eq. 9-10.
    pub b: Vec<C64>,
    /// Analytical accelerance H'_A,ij = -w^2 H_A,ij (m/s^2/N).
    pub analytical: Vec<C64>,
    /// Denominator d_ij = H_A,i^T S H'_X,j.
    pub denominator: Vec<C64>,
    /// dH'_A,ij/dE* = -w^2 dH_ij/dE' (m/s^2/N/Pa).
    pub sensitivity: Vec<C64>,
}

/// Evaluate eq. 9 on a sweep made with derivatives. `lines[l]` is the data line of sweep line
/// `l` (the sweep may cover a subset of the data's lines).
pub fn rfm_linearise(
    engine: &dyn FrfEngine,
    data: &MeasuredColumn,
    sweep: &Sweep,
    lines: &[usize],
    denominator: Denominator,
) -> Result<Linearisation, RfmError> {
    let map = validate(engine, data)?;
    linearise_mapped(&map, data, sweep, lines, denominator)
}

pub(crate) fn linearise_mapped(
    map: &InputMap,
    data: &MeasuredColumn,
    sweep: &Sweep,
    lines: &[usize],
    denominator: Denominator,
) -> Result<Linearisation, RfmError> {
    let n_k = data.outputs.len();
    if sweep.n_lines != lines.len() || sweep.dh_de.is_empty() || sweep.sh.is_empty() {
        return Err(RfmError::Data(format!(
            "the sweep has {} lines (derivatives: {}), expected {} lines with derivatives",
            sweep.n_lines,
            !sweep.dh_de.is_empty(),
            lines.len()
        )));
    }
    let n = lines.len() * n_k;
    let mut lin = Linearisation {
        b: Vec::with_capacity(n),
        analytical: Vec::with_capacity(n),
        denominator: Vec::with_capacity(n),
        sensitivity: Vec::with_capacity(n),
    };
    let mut delta = vec![C64::new(0.0, 0.0); n_k];
    for (l, &dl) in lines.iter().enumerate() {
        let w = data.omega_rad_s[dl];
        let w2 = w * w;
        // delta_m = H'_X,mj - H'_A,mj at the measured points (output m is data.outputs[m]).
        for (m, d) in delta.iter_mut().enumerate() {
            let h = sweep.h[sweep.idx(l, data.outputs[m], map.j)];
            *d = data.at(dl, m) + w2 * h;
        }
        for k in 0..n_k {
            let i = data.outputs[k];
            let hij = sweep.h[sweep.idx(l, i, map.j)];
            let dh = sweep.dh_de[sweep.idx(l, i, map.j)];
            let a = -w2 * hij;
            // H_A,i^T S H'_A,j = -w^2 H_A,i^T S H_A,j = w^2 dH_ij/dE'.
            let mut den = w2 * dh;
            if denominator == Denominator::MeasuredColumn {
                for (m, d) in delta.iter().enumerate() {
                    den += sweep.sh[sweep.idx(l, data.outputs[m], map.out_pos[k])] * d;
                }
            }
            if den.norm() == 0.0 || !(den.re.is_finite() && den.im.is_finite()) {
                return Err(RfmError::ZeroDenominator {
                    line: dl,
                    freq_hz: w / (2.0 * std::f64::consts::PI),
                    output: i,
                });
            }
            lin.b.push((a - data.at(dl, k)) / den);
            lin.analytical.push(a);
            lin.denominator.push(den);
            lin.sensitivity.push(-w2 * dh);
        }
    }
    Ok(lin)
}

/// FRAC between measured and analytical FRF k over the given lines (paper eq. 38,
/// [`crate::correlation::frac`]). `analytical` is `[line][k]` over `lines`.
pub fn frac(data: &MeasuredColumn, analytical: &[C64], lines: &[usize], k: usize) -> f64 {
    let n_k = data.outputs.len();
    let x: Vec<C64> = lines.iter().map(|&dl| data.at(dl, k)).collect();
    let a: Vec<C64> = (0..lines.len()).map(|l| analytical[l * n_k + k]).collect();
    crate::correlation::frac(&x, &a)
}
