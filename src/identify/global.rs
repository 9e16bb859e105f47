//! The global RFM per model (paper eq. 37, Tables 4 and 5) inside the leakage fixed point,
//! with the predicted measurement and its correlation with the data before and after
//! (FRAC eq. 38, SCC eq. 39, ACC eq. 40).

use super::leakage::fixed_point;
use super::{analysis, rows, GlobalResult, Level, RunError};
use crate::common::C64;
use crate::forward::Observation;
use crate::rfm::RfmResult;
use crate::stage::{input_error, Event};

/// The global RFM of every model identified at the level.
pub(super) fn global_models(
    ctx: &Level<'_>,
    progress: &(dyn Fn(Event) + Sync),
) -> Result<Vec<GlobalResult>, RunError> {
    let (engine, laws, file) = (ctx.inputs.engine, ctx.inputs.laws, ctx.inputs.file);
    let (col, lname) = (&ctx.inputs.level.column, &ctx.inputs.level.name);
    let n_out = col.outputs.len();
    let (leak, params) = (ctx.leak.as_ref(), &ctx.params.rfm);
    let mut global = Vec::new();
    let specs: Vec<_> = ctx
        .params
        .models
        .iter()
        .zip(laws)
        .enumerate()
        .filter(|(_, (m, _))| m.levels.contains(lname))
        .collect();
    if !specs.is_empty() {
        progress(Event::Start {
            step: format!("{lname}: global RFM"),
            total: specs.len() as u64,
        });
    }
    let x_rows = rows(&col.accelerance, n_out);
    for (i, (m, law)) in specs {
        let law_modulus = |p: &[f64], w: f64| law.modulus(p, w);
        let (r, passes) = fixed_point(
            leak,
            col,
            |c, prev: Option<&RfmResult>| {
                let p0 = prev.map(|p| p.params.as_slice()).unwrap_or(&m.initial);
                // `max_iterations` bounds the updates of the whole fit: the corrected passes
                // share it. Once it is spent the fixed point stops where it is, at the
                // iteration limit (the previous pass unchanged).
                let used = prev.map_or(0, |p| p.iterations);
                if let Some(p) = prev.filter(|_| used >= params.max_iterations) {
                    let mut r = p.clone();
                    r.stop_reason = crate::rfm::StopReason::MaxIterations;
                    return Ok(r);
                }
                let budget = crate::rfm::RfmParams {
                    max_iterations: params.max_iterations - used,
                    ..params.clone()
                };
                let r = crate::rfm::rfm_global(engine, c, law.as_ref(), p0, &budget);
                // A corrected pass continues the history of the previous one (Fig. 8 shows
                // the whole path from the initial values).
                let r = r.map(|mut r| {
                    if let Some(p) = prev {
                        let n0 = p.history.len();
                        let mut h = p.history.clone();
                        h.extend(r.history.drain(..).skip(1).enumerate().map(|(k, mut x)| {
                            x.iteration = n0 + k;
                            x
                        }));
                        r.history = h;
                        r.iterations += p.iterations;
                        r.initial = p.initial.clone();
                    }
                    r
                });
                r.map_err(|e| match e {
                    crate::rfm::RfmError::SingularInitial { .. }
                    | crate::rfm::RfmError::InadmissibleInitial { .. }
                    | crate::rfm::RfmError::ParamCount { .. } => input_error(
                        file,
                        format!("models[{i}].initial"),
                        format!("{} at level {lname}: {e}", m.name),
                    ),
                    e => analysis(format!("global RFM of {} at level {lname}", m.name), e),
                })
            },
            |r| r.params.clone(),
            &law_modulus,
        )?;
        let initial_modulus: Vec<C64> = col
            .omega_rad_s
            .iter()
            .map(|&w| law.modulus(&m.initial, w))
            .collect();
        // (predicted measurement, its leakage bias: empty without a leakage model)
        let predicted =
            |p: &[f64], modulus: &[C64], what: &str| -> Result<(Vec<C64>, Vec<C64>), RunError> {
                let (mut h, _) =
                    Observation::new(engine, &col.omega_rad_s, col.input, &col.outputs, None)
                        .and_then(|o| o.accelerance_with(&col.omega_rad_s, modulus, false))
                        .map_err(|e| analysis(format!("FRFs of {} {what}", m.name), e))?;
                let bias = match leak {
                    Some(l) => l.bias(col, &|w| law.modulus(p, w))?,
                    None => Vec::new(),
                };
                h.iter_mut().zip(&bias).for_each(|(x, b)| *x += b);
                Ok((h, bias))
            };
        let (initial_frf, _) = predicted(&m.initial, &initial_modulus, "initial")?;
        let (updated_frf, leakage_bias) = predicted(&r.params, &r.modulus, "updated")?;
        let (ri, ru) = (rows(&initial_frf, n_out), rows(&updated_frf, n_out));
        let status = crate::rfm::status::rfm_status(
            &r,
            &law.param_units(),
            &law.bounds(),
            &ctx.inputs.level.freq_hz,
            ctx.inputs.certified,
            params.max_iterations,
        );
        global.push(GlobalResult {
            status,
            leakage_passes: passes,
            leakage_bias,
            frac_initial: crate::correlation::frac_per_frf(&x_rows, &ri),
            frac_updated: crate::correlation::frac_per_frf(&x_rows, &ru),
            scc_initial: crate::correlation::scc_curve(&x_rows, &ri),
            acc_initial: crate::correlation::acc_curve(&x_rows, &ri),
            scc_updated: crate::correlation::scc_curve(&x_rows, &ru),
            acc_updated: crate::correlation::acc_curve(&x_rows, &ru),
            result: r,
            initial_frf,
            updated_frf,
            initial_modulus,
        });
        progress(Event::Advance);
    }
    if !global.is_empty() {
        progress(Event::Finish);
    }

    Ok(global)
}
