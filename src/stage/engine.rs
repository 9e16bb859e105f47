//! The structural model and the FRF engine of a run: the built model, the check of every
//! model's initial values on the full model, and the engine with inputs at every measured
//! point: the certified ROM ([`crate::rom::build_rom`], over the band and a modulus range
//! covering every model's initial E*(w), prepared for the band's lines; loaded from the ROM
//! cache when it holds it) or the full model ([`crate::frf::FullModel`]), plus the
//! likelihood's engine and the H1 measurement model's grid per level.

use super::measurement::{estimator_spec, measurement_model};
use super::rom_engine::RomEngine;
use super::{input_error, LevelData, RunError};
use crate::frf::FrfEngine;
use crate::material::ConstitutiveModel;
use crate::study::build::BuiltModel;
use crate::study::{Engine, Estimator, ModelSpec};
use std::path::Path;

/// The FRF engine stage.
#[derive(Clone, Debug, PartialEq)]
pub struct EngineParams {
    /// Certified ROM (default) or the full sparse model.
    pub engine: Engine,
    /// Certificate tolerance of the ROM (relative FRF error). Default 1e-6.
    pub rom_tolerance: f64,
    /// Worker threads of the run (`None`: rayon's default, one per core).
    pub threads: Option<usize>,
}

impl EngineParams {
    /// The engine stage's parameters of a study's `[solver]`.
    pub fn of(s: &crate::study::Study) -> EngineParams {
        EngineParams {
            engine: s.solver.engine,
            rom_tolerance: s.solver.rom_tolerance,
            threads: s.solver.threads,
        }
    }
}

/// The inputs of the likelihood's engine (a ROM reduced to the columns the likelihood uses).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LikelihoodInputs {
    /// The excitation column only: the plain likelihood.
    Excitation,
    /// Every measured point: the closed loop's candidate masses and declared point masses or
    /// resonators act there (the Sherman-Morrison-Woodbury update needs their receptances).
    EveryMeasuredPoint,
}

impl LikelihoodInputs {
    /// The likelihood engine's inputs for a run with inference (`inference`), the closed loop
    /// (`closed_loop`) and the declared effects `declared`; `None` when nothing evaluates the
    /// likelihood.
    pub fn needed(
        inference: bool,
        closed_loop: bool,
        declared: &[crate::study::effects::DeclaredEffect],
    ) -> Option<LikelihoodInputs> {
        if !inference {
            return None;
        }
        Some(
            if closed_loop || crate::study::effects::declares_attachment(declared) {
                LikelihoodInputs::EveryMeasuredPoint
            } else {
                LikelihoodInputs::Excitation
            },
        )
    }

    /// The likelihood engine's inputs for `study` as it stands (`[inference]`, an enabled
    /// `[closed_loop]`, declared point masses).
    pub fn of(study: &crate::study::Study) -> Option<LikelihoodInputs> {
        Self::needed(
            study.inference.is_some(),
            study.closed_loop.as_ref().is_some_and(|c| c.enabled),
            &study.declared_effects,
        )
    }
}

/// The laws and the measurement the engine is built for.
#[derive(Clone, Copy)]
pub struct ModelsAndData<'a> {
    /// The identified models, with their initial values.
    pub models: &'a [ModelSpec],
    /// One law per model.
    pub laws: &'a [Box<dyn ConstitutiveModel>],
    /// The H1 estimator of the data, when the study states it.
    pub estimator: Option<&'a Estimator>,
    /// The study file, named by input errors.
    pub file: &'a Path,
}

/// The run's FRF engines.
pub struct Engines {
    /// Inputs at every measured point.
    pub engine: Box<dyn FrfEngine>,
    /// Its description for the report and manifest.
    pub note: String,
    /// The likelihood's engine (the excitation column only, or every measured point for the
    /// closed loop), when the study has an `[inference]` section and uses the ROM.
    pub likelihood: Option<Box<dyn FrfEngine>>,
    /// ROMs built and certified (0: full model, or loaded from the cache).
    pub rom_builds: u64,
    /// ROMs read from the ROM cache instead (0: full model, or built).
    pub rom_cache_loads: u64,
    /// The modulus box the deterministic engine is certified over (the ROM's); `None` for the
    /// full model, valid at every modulus.
    pub certified: Option<crate::rom::ModulusRange>,
}

/// Build the FRF engine with inputs = all measured points of every level, and the likelihood's
/// engine with `likelihood`'s inputs (ROM only; the full model serves the likelihood itself).
pub fn build_engine(
    engine_params: &EngineParams,
    likelihood: Option<LikelihoodInputs>,
    models: &ModelsAndData<'_>,
    built: &BuiltModel,
    levels: &mut [LevelData],
    rom_cache: Option<&Path>,
) -> Result<Engines, RunError> {
    let ModelsAndData {
        models,
        laws,
        estimator,
        file,
    } = *models;
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
    match engine_params.engine {
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
            rom_cache_loads: 0,
            certified: None,
        }),
        Engine::Rom => {
            let (lo, hi) = super::data::band_of(levels);
            let params = crate::rom::RomParams {
                band_hz: (lo, hi),
                range: initial_modulus_range(models, (lo, hi)),
                tolerance: engine_params.rom_tolerance,
                // An uncertified ROM is used with a warning in the manifest and report (its
                // measured error is stated) rather than failing the run.
                allow_uncertified: true,
                reference: crate::rom::Reference::suited(built.model.n_dof()),
                ..Default::default()
            };
            let build = || {
                crate::rom::build_rom(&built.model, &inputs, &params)
                    .map_err(|e| RunError::Engine(e.to_string()))
            };
            // the cache entry the ROM was read from, if any
            let ((rom, cert), cache_entry) =
                crate::rom::cache::certified_rom(rom_cache, &built.model, &inputs, &params, build)?;
            let mut grid_note = String::new();
            // The measurement model's grid, chosen per level by convergence at the first
            // model's initial values (on the unprepared ROM: a one-off cost), unless the
            // caller chose it already (another pass of the closed loop on the same structure
            // and data: the grid depends on the measured FRFs, which every basis certified for
            // them reproduces).
            if let (Some(est), Some((law, m0))) = (estimator, laws.iter().zip(models).next()) {
                let probe = RomEngine {
                    rom: rom.clone(),
                    pencils: Vec::new(),
                };
                let modulus = |w: f64| law.modulus(&m0.initial, w);
                for level in levels.iter_mut() {
                    if let Some((_, g)) = &level.measurement {
                        grid_note += &format!(
                            "; H1 measurement model of {}: {} points per line (chosen before)",
                            level.name, g.points_per_line
                        );
                        continue;
                    }
                    let spec = estimator_spec(est, &level.freq_hz);
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
                        .converged_measurement(spec, &modulus, crate::forward::GRID_TOLERANCE)
                        .map_err(|e| input_error(file, "measurements.estimator", e.to_string()))?;
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
            let lik_engine = match likelihood {
                None => None,
                Some(which) => {
                    let lik_inputs = match which {
                        LikelihoodInputs::EveryMeasuredPoint => rom.inputs().to_vec(),
                        LikelihoodInputs::Excitation => vec![built.excitation],
                    };
                    let lik_rom = rom
                        .with_inputs(&lik_inputs)
                        .map_err(|e| RunError::Engine(e.to_string()))?;
                    // With every input (the closed loop's engine), the likelihood's ROM is the
                    // run's: its pencil on the lines is the one prepared above (preparing it
                    // again cost 1.5 s with every point's three directions).
                    let same_rom = lik_inputs == rom.inputs();
                    let mut lp: Vec<crate::rom::PencilSweep> = Vec::new();
                    for level in levels {
                        let mut grids = vec![level.column.omega_rad_s.clone()];
                        if let Some(m) = measurement_model(estimator, level, file)? {
                            grids.push(m.fine_omega());
                        }
                        for g in grids {
                            if lp.iter().any(|p| p.omega_rad_s() == g.as_slice()) {
                                continue;
                            }
                            let prepared = pencils
                                .iter()
                                .find(|p| same_rom && p.omega_rad_s() == g.as_slice());
                            lp.push(match prepared {
                                Some(p) => p.clone(),
                                None => lik_rom
                                    .prepare(&g)
                                    .map_err(|e| RunError::Engine(e.to_string()))?,
                            });
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
            ) + &match &cache_entry {
                Some(f) => format!(" (loaded from the ROM cache {})", f.display()),
                None => String::new(),
            } + &grid_note
                + &match pencils[0].n_fallback_lines() {
                    0 => String::new(),
                    k => format!(
                        "; {k} of {} lines solved by dense LU (ill-conditioned pencil)",
                        pencils[0].omega_rad_s().len()
                    ),
                };
            Ok(Engines {
                engine: Box::new(RomEngine { rom, pencils }),
                note,
                likelihood: lik_engine,
                rom_builds: u64::from(cache_entry.is_none()),
                rom_cache_loads: u64::from(cache_entry.is_some()),
                certified: Some(params.range),
            })
        }
    }
}

/// The modulus range the effect-free ROM must cover: every model's initial E*(w) over the
/// band, the default identification range of the ROM, widened by a factor 2 either way.
pub fn initial_modulus_range(
    models: &[crate::study::ModelSpec],
    band_hz: (f64, f64),
) -> crate::rom::ModulusRange {
    let mut r = crate::rom::ModulusRange::default();
    widen_to_initial_moduli(&mut r, models, band_hz, 20);
    r
}

/// Widen `r` to every model's initial E*(w) on `n + 1` lines across `band_hz`, halved and
/// doubled (admissible moduli only: finite, E' > 0, E'' >= 0).
pub fn widen_to_initial_moduli(
    r: &mut crate::rom::ModulusRange,
    models: &[crate::study::ModelSpec],
    band_hz: (f64, f64),
    n: usize,
) {
    for m in models {
        let Ok(law) = crate::material::model_from_name(&m.name, m.branches) else {
            continue;
        };
        for k in 0..=n {
            let f = band_hz.0 + (band_hz.1 - band_hz.0) * k as f64 / n as f64;
            let e = law.modulus(&m.initial, std::f64::consts::TAU * f.max(1e-3));
            if e.re.is_finite() && e.im.is_finite() && e.re > 0.0 && e.im >= 0.0 {
                r.e_storage_pa.0 = r.e_storage_pa.0.min(e.re / 2.0);
                r.e_storage_pa.1 = r.e_storage_pa.1.max(e.re * 2.0);
                r.e_loss_pa.0 = r.e_loss_pa.0.min(e.im / 2.0);
                r.e_loss_pa.1 = r.e_loss_pa.1.max(e.im * 2.0);
            }
        }
    }
}
