//! The analyses of one level (no I/O): per-line RFM, Model 1 over bands, circle fit + IEM,
//! global RFM per model, correlation and sensitivity.

use super::leakage::{fixed_point, Leakage};
use super::settings::rfm_params;
use super::{Event, LevelData, RunError};
use crate::common::{C64, J};
use crate::forward::Observation;
use crate::frf::FrfEngine;
use crate::iem::{AnalyticalMode, ExperimentalMode, IemParams, IemResult};
use crate::material::ConstitutiveModel;
use crate::modal::circle_fit::{circle_fit, CircleFitParams, CircleFitResult};
use crate::rfm::{BandResult, PerLineEstimate, RfmResult};
use crate::study::build::BuiltModel;
use crate::study::Study;

/// Default initial modulus where a study gives none (Pa): the paper's IEM value, Level 1 mode 1.
pub const DEFAULT_E0: C64 = C64::new(6.974e6, 1.4827e6);

/// A ROM mode counts as seen by the measured points when its largest point response is at
/// least this fraction of the largest among the modes computed.
const OBSERVED: f64 = 1e-3;

/// Model 1 (constant E*) over one band (case study 1).
#[derive(Clone, Debug)]
pub struct BandConstantResult {
    pub center_hz: f64,
    pub width_hz: f64,
    pub result: BandResult,
    /// Leakage-corrected passes (0 without `[measurements.estimator]`).
    pub leakage_passes: usize,
}

/// Circle fit (Table 2) and IEM (Table 3) around one resonance.
#[derive(Clone, Debug)]
pub struct IemBandResult {
    pub center_hz: f64,
    pub width_hz: f64,
    /// Response id of the FRF the circle fit used (the drive point when measured).
    pub response_id: u32,
    pub circle: CircleFitResult,
    /// The IEM result, or why it failed (the circle fit is kept either way).
    pub iem: Result<IemResult, String>,
    /// Leakage-corrected passes (0 without `[measurements.estimator]`); the circle fit is then
    /// of the corrected data.
    pub leakage_passes: usize,
}

/// One global RFM run with the FRFs and correlation before and after.
#[derive(Clone, Debug)]
pub struct GlobalResult {
    pub result: RfmResult,
    /// Leakage-corrected passes (0 without `[measurements.estimator]`).
    pub leakage_passes: usize,
    /// The H1 estimator's leakage bias at the updated parameters, `[line][k]` flattened (empty
    /// without `[measurements.estimator]`).
    pub leakage_bias: Vec<C64>,
    /// Predicted measurement at the initial and updated parameters, `[line][k]` flattened
    /// like [`MeasuredColumn::accelerance`]: the analytical accelerance, plus the H1
    /// estimator's leakage bias when the study states its estimator.
    pub initial_frf: Vec<C64>,
    pub updated_frf: Vec<C64>,
    /// E*(w) at the initial parameters (Pa), one per line.
    pub initial_modulus: Vec<C64>,
    pub frac_initial: Vec<f64>,
    pub frac_updated: Vec<f64>,
    pub scc_initial: Vec<f64>,
    pub acc_initial: Vec<f64>,
    pub scc_updated: Vec<f64>,
    pub acc_updated: Vec<f64>,
}

/// Normalised sensitivities |dH'_ij/dE'| E' / max|H'_ij| and |dH'_ij/dE''| E'' / max|H'_ij|
/// per FRF and line (the paper's Fig. 9), at the modulus `modulus` (Pa, per line).
#[derive(Clone, Debug)]
pub struct SensitivityCurves {
    /// Where the modulus came from, e.g. "model4 updated".
    pub at: String,
    pub modulus: Vec<C64>,
    /// `[k][line]`.
    pub storage: Vec<Vec<f64>>,
    pub loss: Vec<Vec<f64>>,
}

/// Everything computed for one level.
#[derive(Clone, Debug)]
pub struct LevelResults {
    pub level: String,
    pub per_line: Option<Vec<PerLineEstimate>>,
    /// The model whose leakage bias corrected the per-line data, if any.
    pub per_line_leakage_from: Option<String>,
    pub band_constant: Vec<BandConstantResult>,
    pub iem: Vec<IemBandResult>,
    pub global: Vec<GlobalResult>,
    pub sensitivity: Option<SensitivityCurves>,
    /// Posteriors of the `[inference]` models at this level.
    pub posteriors: Vec<crate::bayes::PosteriorResult>,
    /// The change from the lower `[inference]` level to this one (set on the higher level).
    pub across_levels: Option<crate::bayes::levels::LevelComparison>,
}

fn analysis(name: impl Into<String>, e: impl std::fmt::Display) -> RunError {
    RunError::Analysis {
        analysis: name.into(),
        message: e.to_string(),
    }
}

/// Rows `[line][k]` of a flattened column.
fn rows(v: &[C64], n_out: usize) -> Vec<&[C64]> {
    v.chunks(n_out).collect()
}

/// FRF k of a flattened `[line][k]` array.
pub fn frf_of(v: &[C64], n_out: usize, k: usize) -> Vec<C64> {
    v.iter().skip(k).step_by(n_out).copied().collect()
}

/// Run every analysis the study asks for on one level.
pub fn analyse_level(
    study: &Study,
    built: &BuiltModel,
    engine: &dyn FrfEngine,
    level: &LevelData,
    laws: &[Box<dyn ConstitutiveModel>],
    progress: &(dyn Fn(Event) + Sync),
) -> Result<LevelResults, RunError> {
    let params = rfm_params(study);
    let col = &level.column;
    let n_out = col.outputs.len();
    let lname = &level.name;
    // A starting modulus per line: the first model's initial E*(w), else the default.
    let first_model = study
        .models
        .iter()
        .zip(laws)
        .find(|(m, _)| m.levels.contains(lname));
    let e_start: Vec<C64> = match first_model {
        Some((m, law)) => col
            .omega_rad_s
            .iter()
            .map(|&w| law.modulus(&m.initial, w))
            .collect(),
        None => vec![DEFAULT_E0; col.n_lines()],
    };
    let model1_e0 = study
        .models
        .iter()
        .find(|m| m.name.eq_ignore_ascii_case("model1"))
        .map(|m| C64::new(m.initial[0], m.initial[1]))
        .unwrap_or(DEFAULT_E0);

    let leak = super::posterior::measurement_model(study, level)?.map(|measurement| Leakage {
        engine,
        measurement,
    });
    let leak = leak.as_ref();
    let constant = |p: &[f64], _w: f64| C64::new(p[0], p[1]);

    // Model 1 over bands (case study 1).
    let mut band_constant = Vec::new();
    for b in &study.analyses.band_constant {
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
                crate::rfm::rfm_band_constant(engine, c, band, e0, &params)
                    .map_err(|e| analysis(&name, e))
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

    // Circle fit + IEM (Tables 2 and 3).
    let mut iem = Vec::new();
    if !study.analyses.iem.is_empty() {
        progress(Event::Start {
            step: format!("{lname}: circle fit + IEM"),
            total: study.analyses.iem.len() as u64,
        });
    }
    for b in &study.analyses.iem {
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
        let provider = move |e: C64| -> Result<Vec<AnalyticalMode>, String> {
            if let Some(r) = engine.complex_modes(e, 8) {
                let modes = r.map_err(|e| e.to_string())?;
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
            )
            .map_err(|e| e.to_string())?;
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
        type IemFit = (CircleFitResult, Result<IemResult, String>);
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
                    |e| format!("IEM around {} Hz at level {lname} failed: {e}", b.center_hz),
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
    if !study.analyses.iem.is_empty() {
        progress(Event::Finish);
    }

    // Global RFM per model (Tables 4 and 5).
    let mut global = Vec::new();
    let specs: Vec<_> = study
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
                let r = crate::rfm::rfm_global(engine, c, law.as_ref(), p0, &params);
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
                    | crate::rfm::RfmError::ParamCount { .. } => super::study_err(
                        study,
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
        global.push(GlobalResult {
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

    // Per-line RFM (Fig. 13 / 18), on data corrected by the leakage of the best-correlated
    // global model when the study states its estimator.
    let mut per_line_leakage_from = None;
    let per_line = if study.analyses.per_line {
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
        let r = crate::rfm::rfm_per_line(engine, &data, &e_start, &params)
            .map_err(|e| analysis(format!("per-line RFM at level {lname}"), e))?;
        progress(Event::Finish);
        Some(r)
    } else {
        None
    };

    // Sensitivity (Fig. 9) at the first updated model, else the starting modulus.
    let sensitivity = if study.analyses.sensitivity {
        let (at, modulus) = match global.first() {
            Some(g) => (
                format!("{} updated", g.result.model_name),
                g.result.modulus.clone(),
            ),
            None => ("initial modulus".to_string(), e_start.clone()),
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
        Some(SensitivityCurves {
            at,
            modulus,
            storage,
            loss,
        })
    } else {
        None
    };

    Ok(LevelResults {
        level: lname.clone(),
        per_line,
        per_line_leakage_from,
        band_constant,
        iem,
        global,
        sensitivity,
        posteriors: Vec::new(),
        across_levels: None,
    })
}
