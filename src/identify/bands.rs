//! Model 1 over bands (case study 1: a constant E* fitted by the RFM over one band) and the
//! circle fit + IEM around each resonance (paper Tables 2 and 3, eq. 20), each inside the
//! leakage fixed point.

use super::leakage::fixed_point;
use super::{
    analysis, constant, frf_of, BandConstantResult, IemBandResult, IemFailed, Level, RunError,
};
use crate::common::C64;
use crate::iem::{AnalyticalMode, ExperimentalMode, IemParams, IemResult, ModesError};
use crate::modal::circle_fit::{circle_fit, CircleFitParams, CircleFitResult};
use crate::rfm::BandResult;
use crate::stage::Event;

/// A ROM mode counts as seen by the measured points when its largest point response is at
/// least this fraction of the largest among the modes computed.
const OBSERVED: f64 = 1e-3;

/// Model 1 over each band of `ctx.params.band_constant`.
pub(super) fn band_constant(ctx: &Level<'_>) -> Result<Vec<BandConstantResult>, RunError> {
    let (engine, col, lname) = (
        ctx.inputs.engine,
        &ctx.inputs.level.column,
        &ctx.inputs.level.name,
    );
    let (leak, params, model1_e0) = (ctx.leak.as_ref(), &ctx.params.rfm, ctx.model1_e0);
    let mut band_constant = Vec::new();
    for b in &ctx.params.band_constant {
        let band = (
            b.center_hz - b.width_hz / 2.0,
            b.center_hz + b.width_hz / 2.0,
        );
        let sub = col.restrict_to_band(band.0, band.1);
        let name = format!(
            "Model 1 RFM over {:.1}..{:.1} Hz at level {lname}",
            band.0, band.1
        );
        let (r, passes) = fixed_point(
            leak,
            &sub,
            |c, prev: Option<&BandResult>| {
                let e0 = prev.map(|p| p.modulus).unwrap_or(model1_e0);
                // The corrected passes share `max_iterations` (as the global RFM's do); the
                // count is that of every pass together.
                let used = prev.map_or(0, |p| p.run.iterations);
                if let Some(p) = prev.filter(|_| used >= params.max_iterations) {
                    let mut r = p.clone();
                    r.run.stop_reason = crate::rfm::StopReason::MaxIterations;
                    return Ok(r);
                }
                let budget = crate::rfm::RfmParams {
                    max_iterations: params.max_iterations - used,
                    ..params.clone()
                };
                let mut r = crate::rfm::rfm_band_constant(engine, c, band, e0, &budget)
                    .map_err(|e| analysis(&name, e))?;
                r.run.iterations += used;
                Ok(r)
            },
            |r| vec![r.modulus.re, r.modulus.im],
            &constant,
        )?;
        band_constant.push(BandConstantResult {
            center_hz: b.center_hz,
            width_hz: b.width_hz,
            result: r,
            leakage_passes: passes,
        });
    }

    Ok(band_constant)
}

/// Circle fit + IEM around each band of `ctx.params.iem`, started from the Model 1 band fit
/// that covers it.
pub(super) fn iem(
    ctx: &Level<'_>,
    band_constant: &[BandConstantResult],
    progress: &(dyn Fn(Event) + Sync),
) -> Result<Vec<IemBandResult>, RunError> {
    let (engine, level, built) = (ctx.inputs.engine, ctx.inputs.level, ctx.inputs.built);
    let (col, lname) = (&level.column, &level.name);
    let n_out = col.outputs.len();
    let (leak, model1_e0) = (ctx.leak.as_ref(), ctx.model1_e0);
    let mut iem = Vec::new();
    if !ctx.params.iem.is_empty() {
        progress(Event::Start {
            step: format!("{lname}: circle fit + IEM"),
            total: ctx.params.iem.len() as u64,
        });
    }
    for b in &ctx.params.iem {
        let band = (
            b.center_hz - b.width_hz / 2.0,
            b.center_hz + b.width_hz / 2.0,
        );
        let k = col
            .outputs
            .iter()
            .position(|&o| o == col.input)
            .unwrap_or(0);
        let e_band = band_constant
            .iter()
            .find(|bc| (bc.center_hz - b.center_hz).abs() <= b.width_hz)
            .map(|bc| bc.result.modulus)
            .unwrap_or(model1_e0);
        let model = &built.model;
        let axes = built.dof_axes.as_deref();
        // Modes from the engine when it has them (the ROM's reduced pencil: microseconds),
        // else complex modes of the full model.
        let provider = move |e: C64| -> Result<Vec<AnalyticalMode>, ModesError> {
            if let Some(r) = engine.complex_modes(e, 8) {
                let modes = r?;
                // The ROM's basis is driven by the measured (y) loads; it may still carry
                // traces of modes the points do not see (lateral bending, torsion), which
                // these flags leave out.
                let obs = |m: &crate::frf::EngineMode| {
                    m.at_points.iter().map(|z| z.norm()).fold(0.0, f64::max)
                };
                let top = modes.iter().map(obs).fold(0.0, f64::max);
                return Ok(modes
                    .iter()
                    .map(|m| AnalyticalMode {
                        lambda: m.lambda,
                        phi_s_phi: m.phi_s_phi,
                        y_dominant: obs(m) > OBSERVED * top,
                    })
                    .collect());
            }
            let modes = crate::modes::complex_modes(
                model,
                e,
                8,
                axes,
                &crate::modes::ModesParams::default(),
            )?;
            Ok(modes
                .iter()
                .map(|m| AnalyticalMode {
                    lambda: m.lambda,
                    phi_s_phi: m.phi_s_phi,
                    y_dominant: m.y_dominant.unwrap_or(true),
                })
                .collect())
        };
        let sub = col.restrict_to_band(band.0, band.1);
        let sub_hz: Vec<f64> = sub
            .omega_rad_s
            .iter()
            .map(|w| w / std::f64::consts::TAU)
            .collect();
        type IemFit = (CircleFitResult, Result<IemResult, IemFailed>);
        let ((circle, r), passes) = fixed_point(
            leak,
            &sub,
            |c, prev: Option<&IemFit>| {
                let h = frf_of(&c.accelerance, n_out, k);
                let circle = circle_fit(
                    &sub_hz,
                    &h,
                    crate::data::Quantity::Accelerance,
                    band,
                    &CircleFitParams::default(),
                )
                .map_err(|e| {
                    analysis(
                        format!("circle fit around {} Hz at level {lname}", b.center_hz),
                        e,
                    )
                })?;
                let target = ExperimentalMode {
                    freq_hz: circle.freq_hz,
                    loss_factor: circle.loss_factor,
                };
                let e0 = match prev {
                    Some((_, Ok(p))) => p.modulus,
                    _ => e_band,
                };
                let r = crate::iem::iem_mode(&provider, target, e0, &IemParams::default()).map_err(
                    |source| IemFailed {
                        center_hz: b.center_hz,
                        level: lname.clone(),
                        source,
                    },
                );
                Ok((circle, r))
            },
            |(_, r)| match r {
                Ok(r) => vec![r.modulus.re, r.modulus.im],
                Err(_) => Vec::new(),
            },
            &constant,
        )?;
        iem.push(IemBandResult {
            center_hz: b.center_hz,
            width_hz: b.width_hz,
            response_id: level.response_ids[k],
            circle,
            iem: r,
            leakage_passes: passes,
        });
        progress(Event::Advance);
    }
    if !ctx.params.iem.is_empty() {
        progress(Event::Finish);
    }

    Ok(iem)
}
