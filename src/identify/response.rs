//! The per-line RFM (paper eq. 10-11, Fig. 13/18) on the data corrected by the best global
//! model's leakage bias, and the normalised sensitivities of the FRFs to E' and E'' (Fig. 9).

use super::leakage::Leakage;
use super::{analysis, frf_of, GlobalResult, Level, RunError, SensitivityCurves};
use crate::common::{C64, J};
use crate::forward::Observation;
use crate::rfm::PerLineEstimate;
use crate::stage::Event;

/// The per-line RFM from `e_start`; with the model whose leakage bias corrected the data.
pub(super) fn per_line(
    ctx: &Level<'_>,
    global: &[GlobalResult],
    e_start: &[C64],
    progress: &(dyn Fn(Event) + Sync),
) -> Result<(Vec<PerLineEstimate>, Option<String>), RunError> {
    let (engine, col, lname) = (
        ctx.inputs.engine,
        &ctx.inputs.level.column,
        &ctx.inputs.level.name,
    );
    let mut per_line_leakage_from = None;
    progress(Event::Start {
        step: format!("{lname}: per-line RFM"),
        total: 0,
    });
    let mean = |g: &GlobalResult| g.frac_updated.iter().sum::<f64>();
    let best = global.iter().max_by(|a, b| mean(a).total_cmp(&mean(b)));
    let data = match best.filter(|g| !g.leakage_bias.is_empty()) {
        Some(g) => {
            per_line_leakage_from = Some(g.result.model_name.clone());
            Leakage::corrected(col, &g.leakage_bias)
        }
        None => col.clone(),
    };
    let r = crate::rfm::rfm_per_line(engine, &data, e_start, &ctx.params.rfm)
        .map_err(|e| analysis(format!("per-line RFM at level {lname}"), e))?;
    progress(Event::Finish);
    Ok((r, per_line_leakage_from))
}

/// Sensitivities at the first updated model, else at the starting modulus `e_start`.
pub(super) fn sensitivity(
    ctx: &Level<'_>,
    global: &[GlobalResult],
    e_start: &[C64],
) -> Result<SensitivityCurves, RunError> {
    let (engine, col, lname) = (
        ctx.inputs.engine,
        &ctx.inputs.level.column,
        &ctx.inputs.level.name,
    );
    let n_out = col.outputs.len();
    let (at, modulus) = match global.first() {
        Some(g) => (
            format!("{} updated", g.result.model_name),
            g.result.modulus.clone(),
        ),
        None => ("initial modulus".to_string(), e_start.to_vec()),
    };
    let (h, dh) = Observation::new(engine, &col.omega_rad_s, col.input, &col.outputs, None)
        .and_then(|o| o.accelerance_with(&col.omega_rad_s, &modulus, true))
        .map_err(|e| analysis(format!("sensitivities at level {lname}"), e))?;
    let mut storage = Vec::new();
    let mut loss = Vec::new();
    for k in 0..n_out {
        let hk = frf_of(&h, n_out, k);
        let peak = hk.iter().map(|z| z.norm()).fold(0.0, f64::max);
        let dk = frf_of(&dh, n_out, k);
        let s: Vec<f64> = dk
            .iter()
            .zip(&modulus)
            .map(|(d, e)| {
                if peak > 0.0 {
                    d.norm() * e.re / peak
                } else {
                    0.0
                }
            })
            .collect();
        // dH'/dE'' = j dH'/dE': same magnitude, scaled by E''.
        let l: Vec<f64> = dk
            .iter()
            .zip(&modulus)
            .map(|(d, e)| {
                if peak > 0.0 {
                    (J * d).norm() * e.im / peak
                } else {
                    0.0
                }
            })
            .collect();
        storage.push(s);
        loss.push(l);
    }
    Ok(SensitivityCurves {
        at,
        modulus,
        storage,
        loss,
    })
}
