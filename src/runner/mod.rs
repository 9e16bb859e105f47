//! The stages of a study's run, sequenced by [`crate::pipeline`] (`rfmlab run STUDY.toml`) and
//! `rfmlab check STUDY.toml`. It sits outside the numerical core (like `study`, `output`,
//! `plot`) and wires them together:
//!
//! 1. load the measured data of every level (UFF58, [`crate::data::frf_set_from_uff`]) and check
//!    it ([`crate::data::check_level`]: excitation channel present, band covered);
//! 2. build the structural model ([`crate::study::build::build_model`]) and the FRF engine: the
//!    certified ROM ([`crate::rom::build_rom`], over the band and a modulus range covering every
//!    model's initial E*(w) and plausible results, prepared for the band's lines) or the full
//!    model ([`crate::frf::FullModel`]) when `solver.engine = "full"`; its inputs are all measured
//!    points (the RFM needs a square engine, see [`crate::rfm`]);
//! 3. per level, the measured accelerance column H'_X,ij (i = channels, j = the excitation point)
//!    and the analyses: per-line RFM (paper eq. 10-11, Fig. 13/18), Model 1 over bands (case
//!    study 1), circle fit (Table 2) and IEM (eq. 20, Table 3), global RFM per model (eq. 37,
//!    Tables 4-5), correlation (FRAC eq. 38, SCC eq. 39, ACC eq. 40) and sensitivities (Fig. 9);
//! 4. the tables, figures and report sections of the results ([`write`] lists the tables, their
//!    columns and units), written by [`crate::report::write`] in one atomic folder swap.

pub mod closed_loop;
mod compute;
mod leakage;
pub mod material;
pub mod preflight;
pub mod prepared;
mod settings;
pub mod simulate;
pub mod terms;
pub mod write;
pub(crate) mod write_bayes;
pub(crate) mod write_compare;
pub(crate) mod write_levels;

pub use crate::stage::{Event, LevelData, LevelTruth, RunError};

// Old paths of the Bayesian stages, removed once every caller moved.
mod bayes_paths;
pub use crate::bayes::{basins, compare, levels, redundancy};
pub use bayes_paths::{declared, posterior};
/// Old path of [`crate::bayes`], removed once every caller moved.
pub mod bayes {
    pub use crate::bayes::*;
}
pub use compute::{
    BandConstantResult, GlobalResult, IemBandResult, LevelResults, SensitivityCurves,
};

use crate::common::C64;
use crate::data::{DataError, FrfLevel, Quantity};
use crate::frf::{FrfEngine, FrfError, Sweep};
use crate::study::build::BuiltModel;
use crate::study::{Engine, Study, StudyError};
use std::path::{Path, PathBuf};

/// Options of a run (beyond the study file).
#[derive(Clone, Debug, Default)]
pub struct RunOptions {
    /// Skip figures even when the study asks for them (tests, benchmarks). Default false.
    pub no_figures: bool,
    /// Override the study's output folder. Default None (use `study.output_dir`).
    pub output_dir: Option<PathBuf>,
    /// Folder of certified ROMs reused across runs (keyed by model, points, band, range and
    /// tolerance; see [`crate::rom::cache`]). Default None: build and certify every run.
    pub rom_cache: Option<PathBuf>,
}

/// What a run produced (also printed by `rfmlab run --json`).
#[derive(Clone, Debug, serde::Serialize)]
pub struct RunSummary {
    pub study: String,
    pub output_dir: PathBuf,
    pub files: Vec<String>,
    /// Per level and model: identified parameters (SI), stop reason and FRAC per FRF.
    pub models: Vec<ModelSummary>,
    pub seconds: f64,
}

/// One global RFM run in the summary.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ModelSummary {
    pub level: String,
    pub model: String,
    pub param_names: Vec<String>,
    pub initial: Vec<f64>,
    pub identified: Vec<f64>,
    pub iterations: usize,
    pub stop_reason: String,
    pub frac: Vec<f64>,
}

/// What `rfmlab check` found.
#[derive(Clone, Debug, serde::Serialize)]
pub struct CheckSummary {
    pub study: String,
    /// Where `rfmlab run` writes the results (without `-o/--output`).
    pub output_dir: PathBuf,
    pub n_dof: usize,
    /// Per level: name, number of lines in the band, channel (response) ids used.
    pub levels: Vec<(String, usize, Vec<u32>)>,
    /// Models checked (name and levels).
    pub models: Vec<(String, Vec<String>)>,
    /// Lines at which each model's initial values were evaluated on the full model.
    pub lines_checked: usize,
    /// Warnings, the engine's cost, the mesh's discretisation error per mode, the first
    /// mode against the data's first peak.
    pub preflight: preflight::Preflight,
}

/// The truth of `level` in a sidecar written by `rfmlab simulate` (levels named by `"level"`),
/// or in the `truth.json` of an independent virtual experiment (studies/data/virtual: levels
/// numbered by `"id"` with their `"force_rms_N"`). A numbered level is the study's level when
/// its force RMS equals the study level's `force_rms_n` (to 1e-6), or, without a force RMS in
/// the study, when the study level is named `L<id>`.
fn read_truth(
    study: &Study,
    path: &Path,
    level: &crate::study::Level,
) -> Result<Option<LevelTruth>, RunError> {
    let name = level.name.as_str();
    let bad = |m: String| {
        study_err(
            study,
            "measurements.truth",
            format!("{}: {m}", path.display()),
        )
    };
    let text = std::fs::read_to_string(path).map_err(|e| bad(e.to_string()))?;
    let v: serde_json::Value = serde_json::from_str(&text).map_err(|e| bad(e.to_string()))?;
    let Some(levels) = v.get("levels").and_then(|l| l.as_array()) else {
        return Err(bad(
            "no \"levels\" array: give the .truth.json of `rfmlab simulate` or the truth.json of a virtual experiment".into(),
        ));
    };
    let numbered = |l: &serde_json::Value| {
        let Some(id) = l.get("id").and_then(|n| n.as_u64()) else {
            return false;
        };
        match (
            level.force_rms_n,
            l.get("force_rms_N").and_then(|f| f.as_f64()),
        ) {
            (Some(a), Some(b)) => (a - b).abs() <= 1e-6 * b.abs(),
            _ => name == format!("L{id}"),
        }
    };
    let Some(l) = levels
        .iter()
        .find(|l| l.get("level").and_then(|n| n.as_str()) == Some(name))
        .or_else(|| levels.iter().find(|l| numbered(l)))
    else {
        return Ok(None);
    };
    let law = l
        .get("law")
        .and_then(|x| x.as_str())
        .unwrap_or_default()
        .to_string();
    let m = crate::material::model_from_name(&law, None)
        .map_err(|e| bad(format!("level {name}: {e}")))?;
    let mut params = Vec::new();
    for p in m.param_names() {
        let x = l
            .get("params")
            .and_then(|ps| ps.get(&p))
            .and_then(|x| x.as_f64())
            .ok_or_else(|| bad(format!("level {name}: no parameter {p} of {law}")))?;
        params.push(x);
    }
    Ok(Some(LevelTruth {
        law,
        model: m.into(),
        params,
    }))
}

fn study_err(study: &Study, key: impl Into<String>, message: impl Into<String>) -> RunError {
    RunError::Study(StudyError {
        file: study.file.display().to_string(),
        key: key.into(),
        message: message.into(),
    })
}

const TWO_PI: f64 = 2.0 * std::f64::consts::PI;

/// Convert an FRF value of `q` to accelerance at `freq_hz` (H' = -w^2 H = j w Y).
fn to_accelerance(h: C64, freq_hz: f64, q: Quantity) -> C64 {
    let w = TWO_PI * freq_hz;
    match q {
        Quantity::Accelerance => h,
        Quantity::Mobility => C64::new(0.0, w) * h,
        Quantity::Receptance => -w * w * h,
    }
}

/// Load and check the measured data of every level; returns one [`LevelData`] per level.
pub fn load_levels(study: &Study, built: &BuiltModel) -> Result<Vec<LevelData>, RunError> {
    let meas = study.measurements.as_ref().ok_or_else(|| {
        study_err(
            study,
            "measurements",
            "no [measurements] section: add [[measurements.levels]] with name and files",
        )
    })?;
    let exc_point = &built.model.points[built.excitation];
    let mut out = Vec::new();
    for (li, level) in meas.levels.iter().enumerate() {
        for (fi, f) in level.files.iter().enumerate() {
            if !f.is_file() {
                return Err(study_err(
                    study,
                    format!("measurements.levels[{li}].files[{fi}]"),
                    format!(
                        "data file {} does not exist; check the path (relative paths are relative to the study file's folder)",
                        f.display()
                    ),
                ));
            }
        }
        let files: Vec<(PathBuf, String)> = level
            .files
            .iter()
            .map(|f| (f.clone(), level.name.clone()))
            .collect();
        let set = crate::data::frf_set_from_uff(&files, &crate::data::UffImportOptions::default())?;
        let lvl: &FrfLevel = set
            .levels
            .iter()
            .find(|l| l.name == level.name)
            .ok_or_else(|| {
                study_err(
                    study,
                    format!("measurements.levels[{li}]"),
                    format!(
                        "the files of level {} hold no FRFs of that level",
                        level.name
                    ),
                )
            })?;
        crate::data::check_level(lvl, Some((exc_point.id, exc_point.direction)), meas.band_hz)
            .map_err(|e| {
                RunError::Data(DataError {
                    message: format!(
                        "{} (study {}: measurements.band_hz / structure.excitation)",
                        e.message,
                        study.file.display()
                    ),
                    ..e
                })
            })?;
        let (lo, hi) = meas.band_hz.unwrap_or((0.0, f64::INFINITY));
        let lines: Vec<usize> = (0..lvl.freq_hz.len())
            .filter(|&l| lvl.freq_hz[l] > 0.0 && lvl.freq_hz[l] >= lo && lvl.freq_hz[l] <= hi)
            .collect();
        if lines.is_empty() {
            return Err(study_err(
                study,
                "measurements.band_hz",
                format!(
                    "no positive frequency line of level {} in the band",
                    level.name
                ),
            ));
        }
        // Channels: reference = excitation point, response among the model's points.
        let mut outputs = Vec::new();
        let mut ids = Vec::new();
        let mut chans = Vec::new();
        for ch in &lvl.channels {
            if ch.reference_id != exc_point.id {
                continue;
            }
            if let Some(sel) = &meas.channels {
                if !sel.contains(&ch.response_id) {
                    continue;
                }
            }
            let Some(k) = built
                .model
                .points
                .iter()
                .position(|p| p.id == ch.response_id)
            else {
                continue;
            };
            if outputs.contains(&k) {
                continue;
            }
            // Sign: a channel measured in the opposite direction of the model's point flips.
            let sign = if ch.response_dir == built.model.points[k].direction {
                1.0
            } else {
                -1.0
            };
            outputs.push(k);
            ids.push(ch.response_id);
            chans.push((ch, sign));
        }
        if outputs.is_empty() {
            return Err(study_err(study, "measurements.channels", {
                let mut held: Vec<String> = lvl
                    .channels
                    .iter()
                    .map(|c| format!("{}->{}", c.reference_id, c.response_id))
                    .collect();
                held.dedup();
                let pts: Vec<u32> = built.model.points.iter().map(|p| p.id).collect();
                format!(
                        "level {}: no channel with reference point {} and a response at one of the structure's points {pts:?}; the files hold (reference->response) {}: match structure.points / structure.excitation to these ids",
                        level.name,
                        exc_point.id,
                        held.join(", ")
                    )
            }));
        }
        let n_out = outputs.len();
        let mut acc = vec![C64::new(0.0, 0.0); lines.len() * n_out];
        for (ll, &l) in lines.iter().enumerate() {
            for (k, (ch, sign)) in chans.iter().enumerate() {
                acc[ll * n_out + k] =
                    to_accelerance(ch.values[l], lvl.freq_hz[l], lvl.quantity) * *sign;
            }
        }
        let freq_hz: Vec<f64> = lines.iter().map(|&l| lvl.freq_hz[l]).collect();
        let coherence = if chans.iter().all(|(ch, _)| ch.coherence.is_some()) {
            let mut c = vec![0.0; lines.len() * n_out];
            for (ll, &l) in lines.iter().enumerate() {
                for (k, (ch, _)) in chans.iter().enumerate() {
                    c[ll * n_out + k] = ch.coherence.as_ref().map_or(f64::NAN, |v| v[l]);
                }
            }
            Some(c)
        } else {
            None
        };
        out.push(LevelData {
            coherence,
            n_averages: lvl.n_averages,
            measurement: None,
            name: level.name.clone(),
            column: crate::rfm::MeasuredColumn {
                omega_rad_s: freq_hz.iter().map(|f| TWO_PI * f).collect(),
                input: built.excitation,
                outputs,
                accelerance: acc,
            },
            freq_hz,
            response_ids: ids,
            reference_id: exc_point.id,
            truth: match &meas.truth {
                Some(p) => read_truth(study, p, level)?,
                None => None,
            },
        });
    }
    Ok(out)
}

/// The ROM with a prepared pencil for the band's lines; other grids fall back to the reduced
/// model's LU sweep (both are certified over the same range).
struct RomEngine {
    rom: crate::rom::ReducedModel,
    /// Prepared pencils: the band's lines, and the measurement model's fine grid per level.
    pencils: Vec<crate::rom::PencilSweep>,
}

impl FrfEngine for RomEngine {
    fn n_out(&self) -> usize {
        self.rom.n_out()
    }
    fn inputs(&self) -> &[usize] {
        self.rom.inputs()
    }
    fn sweep_into(
        &self,
        omega_rad_s: &[f64],
        modulus_pa: &[C64],
        with_derivatives: bool,
        out: &mut Sweep,
    ) -> Result<(), FrfError> {
        let same = |p: &crate::rom::PencilSweep| {
            omega_rad_s.len() == p.omega_rad_s().len()
                && omega_rad_s
                    .iter()
                    .zip(p.omega_rad_s())
                    .all(|(a, b)| a.to_bits() == b.to_bits())
        };
        if let Some(p) = self.pencils.iter().find(|p| same(p)) {
            p.sweep_into(omega_rad_s, modulus_pa, with_derivatives, out)
        } else {
            self.rom
                .sweep_into(omega_rad_s, modulus_pa, with_derivatives, out)
        }
    }
    fn complex_modes(
        &self,
        modulus_pa: C64,
        n_modes: usize,
    ) -> Option<Result<Vec<crate::frf::EngineMode>, FrfError>> {
        FrfEngine::complex_modes(&self.rom, modulus_pa, n_modes)
    }
    fn complex_modes_with_masses(
        &self,
        modulus_pa: C64,
        n_modes: usize,
        masses: &[(usize, f64)],
    ) -> Option<Result<Vec<crate::frf::EngineMode>, FrfError>> {
        FrfEngine::complex_modes_with_masses(&self.rom, modulus_pa, n_modes, masses)
    }
}

/// The modulus range the ROM must cover: every model's initial E*(w) over the band, the
/// default identification range of the ROM, widened by a factor 2 either way.
fn modulus_range(study: &Study, band_hz: (f64, f64)) -> crate::rom::ModulusRange {
    let mut r = crate::rom::ModulusRange::default();
    for m in &study.models {
        let Ok(law) = crate::material::model_from_name(&m.name, m.branches) else {
            continue;
        };
        for k in 0..=20 {
            let f = band_hz.0 + (band_hz.1 - band_hz.0) * k as f64 / 20.0;
            let e = law.modulus(&m.initial, TWO_PI * f.max(1e-3));
            if e.re.is_finite() && e.im.is_finite() && e.re > 0.0 {
                r.e_storage_pa.0 = r.e_storage_pa.0.min(e.re / 2.0);
                r.e_storage_pa.1 = r.e_storage_pa.1.max(e.re * 2.0);
                r.e_loss_pa.0 = r.e_loss_pa.0.min(e.im.max(0.0) / 2.0);
                r.e_loss_pa.1 = r.e_loss_pa.1.max(e.im * 2.0);
            }
        }
    }
    r
}

/// The run's FRF engines.
pub(crate) struct Engines {
    /// Inputs at every measured point.
    pub engine: Box<dyn FrfEngine>,
    /// Its description for the report and manifest.
    pub note: String,
    /// The likelihood's engine (the excitation column only, or every measured point for the
    /// closed loop), when the study has an `[inference]` section and uses the ROM.
    pub likelihood: Option<Box<dyn FrfEngine>>,
    /// ROMs built and certified (0: full model, or loaded from the cache).
    pub rom_builds: u64,
}

/// Build the FRF engine with inputs = all measured points of every level.
pub(crate) fn build_engine(
    study: &Study,
    built: &BuiltModel,
    levels: &mut [LevelData],
    laws: &[Box<dyn crate::material::ConstitutiveModel>],
    rom_cache: Option<&Path>,
) -> Result<Engines, RunError> {
    let mut inputs: Vec<usize> = Vec::new();
    for l in levels.iter() {
        for &k in l
            .column
            .outputs
            .iter()
            .chain(std::iter::once(&l.column.input))
        {
            if !inputs.contains(&k) {
                inputs.push(k);
            }
        }
    }
    // The other directions of a measured point, when the model has them (the closed loop's
    // sensor-mass candidate), are inputs too.
    let ids: Vec<u32> = inputs.iter().map(|&k| built.model.points[k].id).collect();
    for (k, p) in built.model.points.iter().enumerate() {
        if ids.contains(&p.id) && !inputs.contains(&k) {
            inputs.push(k);
        }
    }
    inputs.sort_unstable();
    match study.solver.engine {
        Engine::Full => Ok(Engines {
            engine: Box::new(
                crate::frf::FullModel::new(
                    &built.model,
                    &inputs,
                    crate::frf::FullParams::default(),
                )
                .map_err(|e| RunError::Engine(e.to_string()))?,
            ),
            note: format!("engine: full model, {} DOFs", built.model.n_dof()),
            likelihood: None,
            rom_builds: 0,
        }),
        Engine::Rom => {
            let lo = levels
                .iter()
                .flat_map(|l| l.freq_hz.first().copied())
                .fold(f64::INFINITY, f64::min);
            let hi = levels
                .iter()
                .flat_map(|l| l.freq_hz.last().copied())
                .fold(0.0, f64::max);
            let params = crate::rom::RomParams {
                band_hz: (lo, hi),
                range: modulus_range(study, (lo, hi)),
                tolerance: study.solver.rom_tolerance,
                // An uncertified ROM is used with a warning in the manifest and report (its
                // measured error is stated) rather than failing the run.
                allow_uncertified: true,
                ..Default::default()
            };
            let key = crate::rom::cache::key(&built.model, &inputs, &params);
            let file = rom_cache.map(|d| d.join(format!("rom-{}.json", &key[..16])));
            let cached = file
                .as_deref()
                .and_then(|f| crate::rom::cache::load(f, &key));
            let from_cache = cached.is_some();
            let (rom, cert) = match cached {
                Some(rc) => rc,
                None => {
                    let rc = crate::rom::build_rom(&built.model, &inputs, &params)
                        .map_err(|e| RunError::Engine(e.to_string()))?;
                    if let Some(f) = &file {
                        // A cache that cannot be written costs time next run, nothing else.
                        let _ = crate::rom::cache::save(f, &key, &rc.0, &rc.1);
                    }
                    rc
                }
            };
            let mut grid_note = String::new();
            // The measurement model's grid, chosen per level by convergence at the first
            // model's initial values (on the unprepared ROM: a one-off cost).
            if let (Some(est), Some((law, m0))) = (
                study
                    .measurements
                    .as_ref()
                    .and_then(|m| m.estimator.as_ref()),
                laws.iter().zip(&study.models).next(),
            ) {
                let probe = RomEngine {
                    rom: rom.clone(),
                    pencils: Vec::new(),
                };
                let modulus = |w: f64| law.modulus(&m0.initial, w);
                for level in levels.iter_mut() {
                    let c = &level.column;
                    let obs = crate::forward::Observation::new(
                        &probe,
                        &c.omega_rad_s,
                        c.input,
                        &c.outputs,
                        None,
                    )
                    .map_err(|e| RunError::Engine(e.to_string()))?;
                    let chosen = obs
                        .converged_measurement(
                            posterior::estimator_spec(est, &level.freq_hz),
                            &modulus,
                            crate::forward::GRID_TOLERANCE,
                        )
                        .map_err(|e| study_err(study, "measurements.estimator", e.to_string()))?;
                    let g = &chosen.1;
                    grid_note += &format!(
                        "; H1 measurement model of {}: {} points per line{} (largest change of E[H1] when the grid is doubled, relative to |H| per line: {})",
                        level.name,
                        g.points_per_line,
                        if g.converged { "" } else { ", NOT CONVERGED to the tolerance" },
                        g.history
                            .iter()
                            .map(|(m, c)| format!("{m}->{}: {c:.1e}", 2 * m))
                            .collect::<Vec<_>>()
                            .join(", ")
                    );
                    level.measurement = Some(chosen);
                }
            }
            // Prepare the pencil for the first level's grid (all levels normally share it).
            let omega = &levels[0].column.omega_rad_s;
            let pencils = vec![rom
                .prepare(omega)
                .map_err(|e| RunError::Engine(e.to_string()))?];
            // The likelihood's engine: the excitation column only, prepared on each level's
            // lines and, with a measurement model, on its fine grid.
            let lik_engine = match &study.inference {
                None => None,
                Some(_) => {
                    // The closed loop and declared point masses need the receptances of
                    // every measured point: then all inputs.
                    let lik_inputs = if closed_loop::needs_all_inputs(study) {
                        rom.inputs().to_vec()
                    } else {
                        vec![built.excitation]
                    };
                    let lik_rom = rom
                        .with_inputs(&lik_inputs)
                        .map_err(|e| RunError::Engine(e.to_string()))?;
                    let mut lp: Vec<crate::rom::PencilSweep> = Vec::new();
                    for level in levels {
                        let mut grids = vec![level.column.omega_rad_s.clone()];
                        if let Some(m) = posterior::measurement_model(study, level)? {
                            grids.push(m.fine_omega());
                        }
                        for g in grids {
                            if !lp.iter().any(|p| p.omega_rad_s() == g.as_slice()) {
                                lp.push(
                                    lik_rom
                                        .prepare(&g)
                                        .map_err(|e| RunError::Engine(e.to_string()))?,
                                );
                            }
                        }
                    }
                    Some(Box::new(RomEngine {
                        rom: lik_rom,
                        pencils: lp,
                    }) as Box<dyn FrfEngine>)
                }
            };
            let note = format!(
                "engine: ROM with {} basis vectors over {:.1}..{:.1} Hz, E' {:.3e}..{:.3e} Pa, E'' {:.3e}..{:.3e} Pa; certificate max relative error {:.2e} (tolerance {:.1e}){}",
                cert.basis_size,
                lo,
                hi,
                params.range.e_storage_pa.0,
                params.range.e_storage_pa.1,
                params.range.e_loss_pa.0,
                params.range.e_loss_pa.1,
                cert.max_rel_error,
                params.tolerance,
                if cert.passed { "" } else { ": WARNING, NOT CERTIFIED" }
            ) + &match (&file, from_cache) {
                (Some(f), true) => format!(" (loaded from the ROM cache {})", f.display()),
                _ => String::new(),
            } + &grid_note;
            Ok(Engines {
                engine: Box::new(RomEngine { rom, pencils }),
                note,
                likelihood: lik_engine,
                rom_builds: u64::from(!from_cache),
            })
        }
    }
}

/// Build the model of a study (errors name the study file).
pub(crate) fn build(study: &Study) -> Result<BuiltModel, RunError> {
    Ok(crate::study::build::build_model(
        &study.structure,
        &study.file.display().to_string(),
    )?)
}

/// Check every model spec: known name, parameters in range (the study validation does most).
pub(crate) fn model_laws(
    study: &Study,
) -> Result<Vec<Box<dyn crate::material::ConstitutiveModel>>, RunError> {
    let mut laws = Vec::new();
    for (i, m) in study.models.iter().enumerate() {
        let law = crate::material::model_from_name(&m.name, m.branches)
            .map_err(|e| study_err(study, format!("models[{i}].name"), e.to_string()))?;
        crate::material::check_params(law.as_ref(), &m.initial)
            .map_err(|e| study_err(study, format!("models[{i}].initial"), e.to_string()))?;
        laws.push(law);
    }
    Ok(laws)
}

/// Evaluate the full model at every model's initial E*(w) on 3 lines of each level
/// (both band ends included): a singular or ill-conditioned Z is an input error naming the model.
pub(crate) fn check_initial_values(
    study: &Study,
    built: &BuiltModel,
    levels: &[LevelData],
    laws: &[Box<dyn crate::material::ConstitutiveModel>],
) -> Result<usize, RunError> {
    let full = crate::frf::FullModel::new(
        &built.model,
        &[built.excitation],
        crate::frf::FullParams::default(),
    )
    .map_err(|e| RunError::Engine(e.to_string()))?;
    let mut n_checked = 0;
    for level in levels {
        let n = level.freq_hz.len();
        // Band ends and centre: a sparse LU per line on the full model is the expensive part
        // of `rfmlab check`, and a law that is admissible (check_params) cannot make Z
        // singular in between except at an undamped resonance, which the RFM reports itself.
        let picks: Vec<usize> = if n <= 3 {
            (0..n).collect()
        } else {
            vec![0, n / 2, n - 1]
        };
        let omega: Vec<f64> = picks.iter().map(|&l| level.column.omega_rad_s[l]).collect();
        for (i, (m, law)) in study.models.iter().zip(laws).enumerate() {
            if !m.levels.contains(&level.name) {
                continue;
            }
            let moduli: Vec<C64> = omega.iter().map(|&w| law.modulus(&m.initial, w)).collect();
            let sw = full.sweep(&omega, &moduli, false).map_err(|e| {
                study_err(
                    study,
                    format!("models[{i}].initial"),
                    format!(
                        "the initial values of {} make the system singular at level {}: {e}; choose different initial values",
                        m.name, level.name
                    ),
                )
            })?;
            if sw.h.iter().any(|z| !(z.re.is_finite() && z.im.is_finite())) {
                return Err(study_err(
                    study,
                    format!("models[{i}].initial"),
                    format!(
                        "the initial values of {} give non-finite FRFs at level {}; choose different initial values",
                        m.name, level.name
                    ),
                ));
            }
        }
        n_checked += omega.len();
    }
    Ok(n_checked)
}

/// Validate a study without running it: data files, channels, excitation channel, band,
/// model parameters, and the full model evaluated at every model's initial values.
pub fn check_study(study: &Study) -> Result<CheckSummary, RunError> {
    preflight::check_study_settings(study)?;
    let laws = model_laws(study)?;
    let spec = crate::study::build::joint_spec(&study.structure);
    let cost = match &spec {
        Some(spec) => Some(
            crate::fe::joint::joint_cost_estimate(spec)
                .map_err(|e| study_err(study, e.key().to_string(), e.detail()))?,
        ),
        None => None,
    };
    let built = build(study)?;
    let levels = load_levels(study, &built)?;
    let mut pf = preflight::Preflight {
        cost: cost.map(|c| preflight::CostSummary {
            n_dof: c.n_dof,
            memory_bytes: c.memory_bytes,
            factor_seconds: c.factor_seconds,
            available_memory_bytes: crate::fe::cost::available_memory_bytes(),
        }),
        ..Default::default()
    };
    preflight::check_bands(study, &levels, &mut pf.warnings)?;
    preflight::check_channels(&built, &levels, &mut pf.warnings);
    let lines_checked = check_initial_values(study, &built, &levels, &laws)?;
    preflight::check_first_mode(study, &built, &levels, &laws, &mut pf)?;
    match preflight::mesh_error_at_initial_values(study, &built, &levels, &laws) {
        Ok(d) => pf.discretisation = d,
        // a refined mesh beyond the machine, or a solver that cannot resolve it, leaves the
        // estimate out with a warning (the study's own mesh is fine)
        Err(err) => pf.warnings.push(format!(
            "structure.mesh: no discretisation-error estimate ({err})"
        )),
    }
    pf.warnings
        .extend(preflight::mesh_error_warnings(&pf.discretisation));
    Ok(CheckSummary {
        preflight: pf,
        study: study.name.clone(),
        output_dir: study.output_dir.clone(),
        n_dof: built.model.n_dof(),
        levels: levels
            .iter()
            .map(|l| (l.name.clone(), l.freq_hz.len(), l.response_ids.clone()))
            .collect(),
        models: study
            .models
            .iter()
            .map(|m| (m.name.clone(), m.levels.clone()))
            .collect(),
        lines_checked,
    })
}

/// The stages of a run, for [`crate::pipeline`].
pub(crate) mod stages {
    pub(crate) use super::compute::analyse_level;
    pub(crate) use super::settings::rfm_params;
    pub(crate) use super::{build, build_engine, check_initial_values, load_levels, model_laws};
}

/// The folder of cached ROMs of `study` (`.rom-cache/` beside its output folder): where
/// `rfmlab run` keeps its certified ROM and `rfmlab diagnose` its term ROM.
pub fn rom_cache_dir(study: &Study) -> PathBuf {
    study
        .output_dir
        .parent()
        .unwrap_or(Path::new("."))
        .join(".rom-cache")
}

/// Path helper: `<dir>.<suffix>` next to `dir`.
pub(crate) fn sibling(dir: &Path, suffix: &str) -> PathBuf {
    let name = dir
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "results".into());
    dir.with_file_name(format!("{name}.{suffix}"))
}
