//! Test planning (`rfmlab design`): where the sensors go, in which directions, where the
//! shaker drives, so that the planned measurement pins down the adhesive law's parameters.
//!
//! For a study (its structure, laws, priors, band, analyser and force levels) and its
//! `[design]` section ([`crate::study::design`]):
//! 1. candidate places on the free faces ([`candidates`]), each with x, y and z outputs, are
//!    added to the study's points and the model is built as `rfmlab run` builds it (the same
//!    mesh rule);
//! 2. one reduced model with an input at every candidate drive point is built and certified
//!    over the band and the moduli of the parameter draws;
//! 3. per drive, model, parameter draw and level, every candidate channel's Fisher information
//!    of the likelihood `rfmlab run` fits, with the noise scales the measurement chain will give
//!    ([`information`]);
//! 4. greedy selection and exchange over the channels, one sensor per place ([`search`]); with
//!    a sensor mass declared, the information is recomputed with the chosen design's masses
//!    on the structure until the design stops changing (at most three passes);
//! 5. the study's own design is scored the same way (with its own sensors' masses), beside
//!    the best one.
//!
//! Results: [`DesignResult`]; `design.parquet`, `design_candidates.parquet`, a figure and
//! `design.md` are written by [`write`].

pub mod candidates;
pub mod information;
pub mod search;
pub mod write;

use crate::common::Axis;
use crate::experiment::{ChainParams, NoiseLevel};
use crate::inference::likelihood::{ErrorLaw, NoiseModel, Scale, DEFAULT_COHERENCE_FLOOR};
use crate::inference::prior::Prior;
use crate::material::ConstitutiveModel;
use crate::study::design::{DesignSettings, ResponseNoise};
use crate::study::{Study, StudyError};
use candidates::Place;
use information::{Chain, Draw};
use search::{Infos, Score, SearchParams};
use std::time::Instant;

/// Why a design cannot be computed.
#[derive(Debug, thiserror::Error)]
pub enum DesignError {
    #[error(transparent)]
    Study(#[from] StudyError),
    #[error("{0}")]
    Failed(String),
}

/// One candidate channel: a place and a direction.
#[derive(Clone, Debug, PartialEq)]
pub struct Channel {
    /// Index into [`DesignResult::places`].
    pub place: usize,
    pub axis: Axis,
    /// Output index in the design's model.
    pub output: usize,
}

/// A scored design.
#[derive(Clone, Debug, PartialEq)]
pub struct Evaluated {
    /// Indices into [`DesignResult::channels`].
    pub channels: Vec<usize>,
    /// Id of the drive point.
    pub drive: u32,
    pub score: Score,
    /// The sensor masses were those of this design (false: of another design's places, a
    /// search step's approximation).
    pub own_masses: bool,
}

/// What `rfmlab design` found.
#[derive(Clone, Debug)]
pub struct DesignResult {
    pub models: Vec<String>,
    /// Parameter names per model.
    pub params: Vec<Vec<String>>,
    pub levels: Vec<String>,
    pub places: Vec<Place>,
    pub channels: Vec<Channel>,
    /// The study's design (its points measured, its excitation), when all its points are
    /// candidate channels.
    pub current: Option<Evaluated>,
    pub best: Evaluated,
    /// The best designs seen (best first), at most [`RANKED`].
    pub ranked: Vec<Evaluated>,
    /// Per channel: the information gain (nats) it adds to the best design (for a channel of
    /// the design: what removing it loses).
    pub channel_gain: Vec<f64>,
    /// Parameter draws per model and level (physical values).
    pub draws: Vec<Vec<Vec<Vec<f64>>>>,
    pub settings: DesignSettings,
    pub notes: Vec<String>,
    /// Seconds per step.
    pub timings: Vec<(String, f64)>,
}

/// Information computed for a drive (output index) and a set of sensor masses.
type CachedInfos = (usize, Vec<(usize, f64)>, std::rc::Rc<Infos>);

/// Rows of the ranked table.
pub const RANKED: usize = 20;

impl DesignResult {
    /// A sensor's label: "id +axis".
    pub fn label(&self, c: usize) -> String {
        let ch = &self.channels[c];
        let pl = &self.places[ch.place];
        format!("{} +{}", pl.id, axis_name(ch.axis))
    }
    /// The design's sensors as "id +axis, ...".
    pub fn sensors(&self, e: &Evaluated) -> String {
        e.channels
            .iter()
            .map(|&c| self.label(c))
            .collect::<Vec<_>>()
            .join(", ")
    }
}

pub fn axis_name(a: Axis) -> &'static str {
    match a {
        Axis::X => "x",
        Axis::Y => "y",
        Axis::Z => "z",
    }
}

fn failed(what: &str, e: impl std::fmt::Display) -> DesignError {
    DesignError::Failed(format!("{what}: {e}"))
}

/// The default `[design]` settings of a study without the section.
pub fn default_settings() -> DesignSettings {
    DesignSettings {
        sensors: None,
        keep: Vec::new(),
        candidates: crate::study::design::CandidatePlaces::Surface { spacing_m: 0.0 },
        directions: vec![Axis::X, Axis::Y, Axis::Z],
        drives: None,
        models: None,
        draws: 8,
        sensor_mass_kg: 0.0,
        force_noise: 0.002,
        response_noise: ResponseNoise::Rms(DEFAULT_RESPONSE_NOISE_RMS),
        n_averages: 200,
        posterior: None,
    }
}

/// `study` with `[design] sensors` set to `k` (on the default settings when the study has no
/// `[design]`): what `rfmlab design --sensors` and Python's `Study.design(sensors=...)` ask for.
/// `k` must be at least one and at least the kept sensors; the error names `design.sensors`.
pub fn with_sensors(study: &Study, k: usize) -> Result<Study, StudyError> {
    let mut d = study.design.clone().unwrap_or_else(default_settings);
    let err = |message: String| StudyError {
        file: study.file.display().to_string(),
        key: "design.sensors".into(),
        message,
    };
    if k == 0 {
        return Err(err(
            "0 sensors: a design needs at least one response sensor, e.g. 4".into(),
        ));
    }
    if k < d.keep.len() {
        return Err(err(format!(
            "{k} sensors: fewer than the {} kept sensors ([design] keep); ask for at least {}",
            d.keep.len(),
            d.keep.len()
        )));
    }
    d.sensors = Some(k);
    let mut out = study.clone();
    out.design = Some(d);
    Ok(out)
}

/// Default accelerometer noise (m/s^2 RMS over the analyser's span): the broadband resolution
/// of a general-purpose piezoelectric accelerometer (about 0.00015 g).
pub const DEFAULT_RESPONSE_NOISE_RMS: f64 = 1.5e-3;

/// Certificate tolerance of the design's reduced model (relative FRF error; a study's tighter
/// `[solver] rom_tolerance` applies when given): the information of a channel changes by about
/// twice the relative error of its FRF, far below what separates designs, while the many
/// candidate directions (small transverse FRFs among them) would need several times the basis
/// at the run's 1e-6.
pub const ROM_TOLERANCE: f64 = 1e-4;

/// Plan the test of `study`; `progress` gets a line per step.
pub fn design(study: &Study, progress: &dyn Fn(&str)) -> Result<DesignResult, DesignError> {
    let file = study.file.display().to_string();
    let settings = study.design.clone().unwrap_or_else(default_settings);
    let input = |key: &str, message: String| {
        DesignError::Study(StudyError {
            file: file.clone(),
            key: key.into(),
            message,
        })
    };
    let mut timings = Vec::new();
    let t0 = Instant::now();
    // Models, laws, priors.
    let names: Vec<String> = settings.models.clone().unwrap_or_else(|| {
        study
            .inference
            .as_ref()
            .map(|i| i.models.clone())
            .unwrap_or_else(|| study.models.iter().map(|m| m.name.clone()).collect())
    });
    if names.is_empty() {
        return Err(input(
            "models",
            "the study has no [[models]]: add the law(s) the test should identify".into(),
        ));
    }
    let mut specs = Vec::new();
    let mut laws: Vec<Box<dyn ConstitutiveModel>> = Vec::new();
    let mut priors: Vec<Vec<Prior>> = Vec::new();
    for n in &names {
        let spec = study
            .models
            .iter()
            .find(|m| m.name.eq_ignore_ascii_case(n))
            .ok_or_else(|| input("design.models", format!("\"{n}\" is not among [[models]]")))?;
        let law = crate::material::model_from_name(&spec.name, spec.branches)
            .map_err(|e| input("models", e.to_string()))?;
        let pr = study
            .inference
            .as_ref()
            .and_then(|i| {
                i.priors
                    .iter()
                    .find(|(k, _)| k.eq_ignore_ascii_case(n))
                    .map(|(_, v)| v[..law.n_params()].to_vec())
            })
            .unwrap_or_else(|| {
                let b = law.bounds();
                spec.initial
                    .iter()
                    .zip(&b)
                    .map(|(v, b)| Prior::default_for(*v, *b))
                    .collect()
            });
        specs.push(spec.clone());
        laws.push(law);
        priors.push(pr);
    }
    // Measurement chain.
    let meas = study.measurements.as_ref().ok_or_else(|| {
        input("measurements", "give [measurements] with band_hz and the [[measurements.levels]] (name, force_rms_n) the test will run at; the files need not exist yet".into())
    })?;
    let band = meas.band_hz.unwrap_or((1.0, 500.0));
    let est = meas.estimator.as_ref();
    let block_s = est.map_or(1.0, |e| e.block_s);
    let fs_hz = est.map_or(2048.0, |e| e.fs_hz);
    let df = 1.0 / block_s;
    let freq_hz: Vec<f64> = ((band.0 / df).ceil() as i64..=(band.1 / df).floor() as i64)
        .filter(|k| *k > 0)
        .map(|k| k as f64 * df)
        .collect();
    if freq_hz.len() < 2 {
        return Err(input(
            "measurements.band_hz",
            format!("the band {band:?} Hz holds fewer than two lines at {df} Hz spacing"),
        ));
    }
    let mut level_names = Vec::new();
    let mut chains = Vec::new();
    for (i, l) in meas.levels.iter().enumerate() {
        let f = l.force_rms_n.ok_or_else(|| {
            input(
                &format!("measurements.levels[{i}].force_rms_n"),
                "the design needs each level's force RMS (N): give force_rms_n".into(),
            )
        })?;
        level_names.push(l.name.clone());
        chains.push(ChainParams {
            force_rms_n: f,
            band_hz: est.map_or((0.0, band.1), |e| e.force_band(band)),
            fs_hz,
            block_s,
            overlap: 0.5,
            n_averages: settings.n_averages,
            window: est.map_or(crate::experiment::Window::Hann, |e| e.window),
            force_noise: NoiseLevel::FractionOfSignalRms(settings.force_noise),
            response_noise: vec![match settings.response_noise {
                ResponseNoise::Fraction(x) => NoiseLevel::FractionOfSignalRms(x),
                ResponseNoise::Rms(x) => NoiseLevel::Rms(x),
            }],
            shaker: est.and_then(|e| e.shaker),
            lines_hz: freq_hz.clone(),
            // The window kernel's quadrature at 8 points per line spacing (the simulator's
            // 32 resolve the leakage bias of the sharpest peaks; the coherence, which only
            // sets the noise scales, moves by less than the spread of the prediction).
            kernel: crate::experiment::KernelParams {
                grid_step_hz: 1.0 / (8.0 * block_s),
                ..Default::default()
            },
            ..ChainParams::default()
        });
    }
    if chains.is_empty() {
        return Err(input(
            "measurements.levels",
            "give at least one level with force_rms_n".into(),
        ));
    }
    let nb = (fs_hz * block_s).round() as usize;
    let n_d = crate::experiment::estimator::effective_averages(
        chains[0].window,
        nb,
        nb / 2,
        settings.n_averages,
    );
    let noise = {
        let (floor, model_error) = study
            .inference
            .as_ref()
            .map(|i| {
                let m = &i.noise.model;
                (
                    match m.scale {
                        Scale::Coherence { floor, .. } => floor,
                        _ => DEFAULT_COHERENCE_FLOOR,
                    },
                    m.model_error,
                )
            })
            .unwrap_or((DEFAULT_COHERENCE_FLOOR, 0.0));
        NoiseModel {
            scale: Scale::Coherence {
                n_averages: n_d,
                floor,
            },
            errors: ErrorLaw::Gaussian,
            model_error,
        }
    };
    // Draws per model and level: a previous run's Laplace posterior (its MAP, and with
    // draws > 0 normal draws around it), the initial values (draws = 0), or a Latin hypercube
    // over the priors.
    let previous = match &settings.posterior {
        None => None,
        Some(dir) => Some(previous_posterior(dir).map_err(|m| input("design.posterior", m))?),
    };
    let mut draws: Vec<Vec<Vec<Draw>>> = Vec::new();
    for (m, (spec, pr)) in specs.iter().zip(&priors).enumerate() {
        let seed = study.seed ^ (m as u64 + 1).wrapping_mul(0x9E37_79B9);
        let mut per_level = Vec::new();
        for level in &level_names {
            let points: Vec<Vec<f64>> = match &previous {
                Some(prev) => {
                    let (map, sd) = prev
                        .iter()
                        .find(|(l, mo, _, _)| l == level && mo.eq_ignore_ascii_case(&spec.name))
                        .map(|(_, _, a, b)| (a.clone(), b.clone()))
                        .ok_or_else(|| {
                            input(
                                "design.posterior",
                                format!("its laplace.parquet has no {} at level {level}: run the study with [inference] models holding it", spec.name),
                            )
                        })?;
                    if map.len() < spec.initial.len() {
                        return Err(input(
                            "design.posterior",
                            format!(
                                "its laplace.parquet has {} parameters of {}, the law has {}",
                                map.len(),
                                spec.name,
                                spec.initial.len()
                            ),
                        ));
                    }
                    let map = map[..spec.initial.len()].to_vec();
                    let sd = sd[..spec.initial.len()].to_vec();
                    if settings.draws == 0 {
                        vec![map]
                    } else {
                        around(&map, &sd, pr, settings.draws, seed)
                    }
                }
                None if settings.draws == 0 => vec![spec.initial.clone()],
                None => latin_hypercube(pr, settings.draws, seed),
            };
            per_level.push(points.iter().map(|p| Draw::at(p, pr)).collect::<Vec<_>>());
        }
        draws.push(per_level);
    }
    // Places and the model.
    let places = candidates::places(&study.structure, &settings.candidates)
        .map_err(|m| input("design.candidates", m))?;
    let mut structure = study.structure.clone();
    // A sensor's mass acts in x, y and z: with one, every place has all three in the model.
    let model_axes = if settings.sensor_mass_kg > 0.0 {
        vec![Axis::X, Axis::Y, Axis::Z]
    } else {
        settings.directions.clone()
    };
    structure.points = candidates::design_points(&study.structure, &places, &model_axes);
    progress(&format!(
        "design: {} candidate places, {} points in the model",
        places.len(),
        structure.points.len()
    ));
    let built = crate::study::build::build_model_with(&structure, &file, progress)?;
    let out_of = |id: u32, axis: Axis| {
        built
            .model
            .points
            .iter()
            .position(|p| p.id == id && p.direction.axis == axis)
    };
    let drive_ids = settings
        .drives
        .clone()
        .unwrap_or_else(|| vec![study.structure.excitation]);
    let mut drives = Vec::new();
    for id in &drive_ids {
        let p = study
            .point(*id)
            .ok_or_else(|| input("design.drives", format!("point {id} is not a study point")))?;
        let o = out_of(*id, p.direction.axis)
            .ok_or_else(|| input("design.drives", format!("point {id} is not in the model")))?;
        drives.push(o);
    }
    // The reduced model's inputs: the candidate drives and the study's own excitation (its
    // design is scored too).
    let mut rom_inputs = drives.clone();
    if let Some(p) = study.point(study.structure.excitation) {
        if let Some(o) = out_of(p.id, p.direction.axis) {
            if !rom_inputs.contains(&o) {
                rom_inputs.push(o);
            }
        }
    }
    let mut channels = Vec::new();
    for (pi, pl) in places.iter().enumerate() {
        for &axis in &settings.directions {
            if let Some(o) = out_of(pl.id, axis) {
                channels.push(Channel {
                    place: pi,
                    axis,
                    output: o,
                });
            }
        }
    }
    let place_outputs: Vec<Vec<usize>> = places
        .iter()
        .map(|pl| {
            [Axis::X, Axis::Y, Axis::Z]
                .iter()
                .filter_map(|&a| out_of(pl.id, a))
                .collect()
        })
        .collect();
    timings.push(("model".to_string(), t0.elapsed().as_secs_f64()));
    // The reduced model: inputs at the drives, certified over the band (with the kernel's
    // reach for the analyser's window) and every draw's moduli.
    let t1 = Instant::now();
    let half = est.map_or(0.0, |_| ChainParams::default().kernel.half_width_hz);
    let rom_band = ((band.0 - half).max(0.25), band.1 + half + 1.0);
    let mut range = crate::rom::ModulusRange::default();
    let as_specs: Vec<crate::study::ModelSpec> = specs
        .iter()
        .zip(&draws)
        .flat_map(|(s, ds)| {
            ds.iter().flatten().map(move |d| crate::study::ModelSpec {
                initial: d.p.clone(),
                ..s.clone()
            })
        })
        .collect();
    crate::stage::engine::widen_to_initial_moduli(&mut range, &as_specs, rom_band, 40);
    let rom_params = crate::rom::RomParams {
        band_hz: rom_band,
        range,
        tolerance: study.solver.rom_tolerance.max(ROM_TOLERANCE),
        allow_uncertified: true,
        reference: crate::rom::Reference::suited(built.model.n_dof()),
        // The certificate judges the study's points and the drives, as a run's does; the
        // candidates ride on the same basis and are spot-checked below.
        certified_outputs: Some(
            study
                .structure
                .points
                .iter()
                .filter_map(|p| out_of(p.id, p.direction.axis))
                .chain(rom_inputs.iter().copied())
                .collect(),
        ),
        ..Default::default()
    };
    progress(&format!(
        "design: reduced model with {} drive point(s), {} DOFs",
        drives.len(),
        built.model.n_dof()
    ));
    let (rom, cert) = crate::rom::build_rom(&built.model, &rom_inputs, &rom_params)
        .map_err(|e| failed("reduced model", e))?;
    let mut notes = vec![format!(
        "Reduced model: {} basis vectors, certified error {:.1e} of each FRF's peak (tolerance {:.0e}){} over {:.1}-{:.1} Hz and E' {:.2}-{:.1} MPa; model {} DOFs, {} candidate places, {} candidate channels.",
        cert.basis_size,
        cert.max_rel_error,
        rom_params.tolerance,
        if cert.passed { "" } else { ", NOT certified" },
        rom_band.0,
        rom_band.1,
        range.e_storage_pa.0 / 1e6,
        range.e_storage_pa.1 / 1e6,
        built.model.n_dof(),
        places.len(),
        channels.len()
    )];
    notes.push(spot_check(
        &built.model,
        &rom,
        &drives,
        laws[0].as_ref(),
        &draws[0][0][0].p,
        rom_band,
    )?);
    timings.push(("reduced model".to_string(), t1.elapsed().as_secs_f64()));
    progress(&format!(
        "design: reduced model {} vectors, error {:.1e}, {:.1} s",
        cert.basis_size,
        cert.max_rel_error,
        t1.elapsed().as_secs_f64()
    ));
    // The analyser's measurement model on the lines (grid by convergence, as a run does).
    let measurement = match est {
        None => None,
        Some(e) => {
            let spec = crate::stage::measurement::estimator_spec(e, &freq_hz);
            let engine = rom
                .with_inputs(&[drives[0]])
                .map_err(|e| failed("reduced model", e))?;
            let omega: Vec<f64> = freq_hz.iter().map(|f| std::f64::consts::TAU * f).collect();
            let obs =
                crate::forward::Observation::new(&engine, &omega, drives[0], &[drives[0]], None)
                    .map_err(|e| failed("measurement model", e))?;
            let (law, d0) = (&laws[0], &draws[0][0][0]);
            let modulus = |w: f64| law.modulus(&d0.p, w);
            let (m, g) = obs
                .converged_measurement(spec, &modulus, crate::forward::GRID_TOLERANCE)
                .map_err(|e| input("measurements.estimator", e.to_string()))?;
            notes.push(format!(
                "H1 measurement model: {} points per line{}.",
                g.points_per_line,
                if g.converged { "" } else { " (not converged)" }
            ));
            Some(m)
        }
    };
    let chain = Chain {
        freq_hz: &freq_hz,
        measurement: measurement.as_ref(),
        levels: &chains,
        noise: &noise,
    };
    let outputs: Vec<usize> = channels.iter().map(|c| c.output).collect();
    let place_of: Vec<usize> = channels.iter().map(|c| c.place).collect();
    let masses_of = |chosen_places: &[usize]| -> Vec<(usize, f64)> {
        if settings.sensor_mass_kg == 0.0 {
            return Vec::new();
        }
        chosen_places
            .iter()
            .flat_map(|&p| {
                place_outputs[p]
                    .iter()
                    .map(|&o| (o, settings.sensor_mass_kg))
            })
            .collect()
    };
    let grids = information::grids(&chain);
    let compute_infos = |drive: usize, masses: &[(usize, f64)]| -> Result<Infos, DesignError> {
        let engine = rom
            .with_inputs(&[drive])
            .and_then(|r| r.with_point_masses(masses))
            .and_then(|r| crate::stage::rom_engine::RomEngine::prepared(r, &grids))
            .map_err(|e| failed("reduced model", e))?;
        let mut info = Vec::new();
        for (m, law) in laws.iter().enumerate() {
            let n_draws = draws[m][0].len();
            // The levels share their draws unless a previous posterior gives each its own:
            // then one prediction serves every level.
            let shared = draws[m].iter().all(|ds| {
                ds.len() == n_draws && ds.iter().zip(&draws[m][0]).all(|(a, b)| a.p == b.p)
            });
            let mut per_level: Vec<Vec<Vec<Vec<f64>>>> = vec![Vec::new(); chains.len()];
            for s in 0..n_draws {
                if shared {
                    let all = information::channel_info(
                        &engine,
                        drive,
                        &outputs,
                        law.as_ref(),
                        &draws[m][0][s],
                        &chain,
                    )
                    .map_err(|e| failed("information", e))?;
                    for (l, v) in all.into_iter().enumerate() {
                        per_level[l].push(v);
                    }
                } else {
                    for (l, pl) in per_level.iter_mut().enumerate() {
                        let one = Chain {
                            levels: &chains[l..l + 1],
                            ..chain
                        };
                        let mut v = information::channel_info(
                            &engine,
                            drive,
                            &outputs,
                            law.as_ref(),
                            &draws[m][l][s],
                            &one,
                        )
                        .map_err(|e| failed("information", e))?;
                        pl.push(v.remove(0));
                    }
                }
            }
            info.push(per_level);
        }
        Ok(Infos {
            info,
            draws: draws.clone(),
        })
    };
    // The information of a drive and a set of masses is computed once (the study's own design
    // and the search's first pass share it when no mass is declared).
    let cache: std::cell::RefCell<Vec<CachedInfos>> = std::cell::RefCell::new(Vec::new());
    let infos_for =
        |drive: usize, masses: &[(usize, f64)]| -> Result<std::rc::Rc<Infos>, DesignError> {
            if let Some((_, _, i)) = cache
                .borrow()
                .iter()
                .find(|(d, m, _)| *d == drive && m.as_slice() == masses)
            {
                return Ok(i.clone());
            }
            let i = std::rc::Rc::new(compute_infos(drive, masses)?);
            cache.borrow_mut().push((drive, masses.to_vec(), i.clone()));
            Ok(i)
        };
    // The study's design: its measured points in their directions.
    let channel_of = |id: u32, axis: Axis| {
        channels
            .iter()
            .position(|c| places[c.place].id == id && c.axis == axis)
    };
    // The study's design: its measured points (optional ones, e.g. candidate drive points,
    // are not sensors).
    let measured: Vec<&crate::study::Point> = study
        .structure
        .points
        .iter()
        .filter(|p| !p.optional)
        .collect();
    let current_channels: Option<Vec<usize>> = measured
        .iter()
        .map(|p| channel_of(p.id, p.direction.axis))
        .collect();
    let keep: Vec<usize> = settings
        .keep
        .iter()
        .map(|id| {
            let p = study.point(*id).expect("validated");
            channel_of(*id, p.direction.axis).ok_or_else(|| {
                input(
                    "design.keep",
                    format!("point {id}'s direction is not among design.directions"),
                )
            })
        })
        .collect::<Result<_, _>>()?;
    let size = settings
        .sensors
        .unwrap_or(study.structure.points.len())
        .max(keep.len());
    let t2 = Instant::now();
    let mut current = None;
    if let Some(cc) = &current_channels {
        let cp: Vec<usize> = cc.iter().map(|&c| place_of[c]).collect();
        let di = drive_ids
            .iter()
            .position(|d| *d == study.structure.excitation);
        let (drive_id, drive) = match di {
            Some(i) => (drive_ids[i], drives[i]),
            None => {
                let p = study.point(study.structure.excitation).expect("validated");
                (p.id, out_of(p.id, p.direction.axis).expect("a study point"))
            }
        };
        progress("design: scoring the study's own design");
        let infos = infos_for(drive, &masses_of(&cp))?;
        current = Some(Evaluated {
            channels: cc.clone(),
            drive: drive_id,
            score: search::score(&infos, cc),
            own_masses: true,
        });
    }
    // The search per drive point, with the sensor masses of the design found (fixed point).
    let mut best: Option<(Evaluated, std::rc::Rc<Infos>)> = None;
    let mut ranked: Vec<Evaluated> = Vec::new();
    for (di, &drive) in drives.iter().enumerate() {
        let mut mass_places: Vec<usize> = keep.iter().map(|&c| place_of[c]).collect();
        for pass in 0..3 {
            progress(&format!(
                "design: drive {} ({} of {}), information pass {}",
                drive_ids[di],
                di + 1,
                drives.len(),
                pass + 1
            ));
            let infos = infos_for(drive, &masses_of(&mass_places))?;
            let (chosen, seen) = search::search(
                &infos,
                &SearchParams {
                    size,
                    keep: &keep,
                    place_of: &place_of,
                },
            );
            let mut cp: Vec<usize> = chosen.iter().map(|&c| place_of[c]).collect();
            cp.sort_unstable();
            let converged = settings.sensor_mass_kg == 0.0 || {
                let mut mp = mass_places.clone();
                mp.sort_unstable();
                mp == cp
            };
            if converged || pass == 2 {
                let s = search::score(&infos, &chosen);
                let ev = Evaluated {
                    channels: chosen.clone(),
                    drive: drive_ids[di],
                    score: s,
                    own_masses: converged,
                };
                ranked.extend(seen.into_iter().take(RANKED).map(|(c, s)| Evaluated {
                    own_masses: settings.sensor_mass_kg == 0.0,
                    channels: c,
                    drive: drive_ids[di],
                    score: s,
                }));
                let better = best
                    .as_ref()
                    .is_none_or(|(b, _)| ev.score.worst < b.score.worst);
                if better {
                    best = Some((ev, infos));
                }
                break;
            }
            mass_places = cp;
        }
    }
    let (best, best_infos) = best.ok_or_else(|| DesignError::Failed("no design found".into()))?;
    ranked.sort_by(|a, b| a.score.worst.total_cmp(&b.score.worst));
    ranked.dedup_by(|a, b| {
        let (mut x, mut y) = (a.channels.clone(), b.channels.clone());
        x.sort_unstable();
        y.sort_unstable();
        x == y && a.drive == b.drive
    });
    ranked.truncate(RANKED);
    // What each channel adds to (or, in it, gives) the best design.
    let base = best.score.info_gain;
    let channel_gain: Vec<f64> = (0..channels.len())
        .map(|c| {
            if let Some(i) = best.channels.iter().position(|&b| b == c) {
                let mut d = best.channels.clone();
                d.remove(i);
                base - search::score(&best_infos, &d).info_gain
            } else {
                let mut d = best.channels.clone();
                d.push(c);
                search::score(&best_infos, &d).info_gain - base
            }
        })
        .collect();
    timings.push((
        "information and search".to_string(),
        t2.elapsed().as_secs_f64(),
    ));
    if settings.sensor_mass_kg > 0.0 {
        notes.push(format!(
            "Each sensor's {:.1} g acts in x, y and z at its place (projected on the reduced model); the search recomputed the information with the chosen design's masses until the design stopped changing{}.",
            settings.sensor_mass_kg * 1e3,
            if best.own_masses { "" } else { " (it had not after three passes: the best design's scores are with the previous design's masses)" }
        ));
    }
    Ok(DesignResult {
        models: specs.iter().map(|s| s.name.clone()).collect(),
        params: laws.iter().map(|l| l.param_names()).collect(),
        levels: level_names,
        places,
        channels,
        current,
        best,
        ranked,
        channel_gain,
        draws: draws
            .iter()
            .map(|ls| {
                ls.iter()
                    .map(|ds| ds.iter().map(|d| d.p.clone()).collect())
                    .collect()
            })
            .collect(),
        settings,
        notes,
        timings,
    })
}

/// `n` points of a Latin hypercube over the priors' central half (quantiles 0.25-0.75 at
/// stratified uniforms), seeded: what the parameters are likely to be, without the tails of a
/// vague prior (a decade either side would ask the reduced model to cover moduli a hundred
/// times apart, and a design for an adhesive ten times stiffer than believed is not the plan).
fn latin_hypercube(priors: &[Prior], n: usize, seed: u64) -> Vec<Vec<f64>> {
    use rand::seq::SliceRandom;
    use rand::{RngExt, SeedableRng};
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let cols: Vec<Vec<f64>> = priors
        .iter()
        .map(|pr| {
            let mut u: Vec<f64> = (0..n)
                .map(|k| 0.25 + 0.5 * (k as f64 + rng.random::<f64>()) / n as f64)
                .collect();
            u.shuffle(&mut rng);
            u.iter()
                .map(|&u| pr.to_physical(pr.quantile_x(u)))
                .collect()
        })
        .collect();
    (0..n)
        .map(|k| cols.iter().map(|c| c[k]).collect())
        .collect()
}

/// `n` draws around `map` with independent normal spreads `sd` (physical), kept inside the
/// priors' support, seeded.
fn around(map: &[f64], sd: &[f64], priors: &[Prior], n: usize, seed: u64) -> Vec<Vec<f64>> {
    use rand::SeedableRng;
    use rand_distr::{Distribution, StandardNormal};
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    (0..n)
        .map(|_| {
            map.iter()
                .zip(sd)
                .zip(priors)
                .map(|((m, s), pr)| {
                    for _ in 0..100 {
                        let z: f64 = StandardNormal.sample(&mut rng);
                        let v = m + s * z;
                        if pr.contains(v) {
                            return v;
                        }
                    }
                    *m
                })
                .collect()
        })
        .collect()
}

/// `(level, model, MAP, sd)` rows of a previous run's `laplace.parquet` in `dir`.
type PreviousPosterior = Vec<(String, String, Vec<f64>, Vec<f64>)>;

fn previous_posterior(dir: &std::path::Path) -> Result<PreviousPosterior, String> {
    let f = dir.join("laplace.parquet");
    let t = crate::output::Table::read_parquet(&f).map_err(|e| {
        format!(
            "cannot read {}: {e}; give the results folder of a run of this study with [inference]",
            f.display()
        )
    })?;
    let strs = |name: &str| -> Result<Vec<String>, String> {
        match t.column(name) {
            Some(crate::output::ColumnData::Str(v)) => Ok(v.clone()),
            _ => Err(format!("{} has no text column {name}", f.display())),
        }
    };
    let nums = |name: &str| -> Result<Vec<f64>, String> {
        t.column(name)
            .and_then(|c| c.as_f64())
            .map(|v| v.to_vec())
            .ok_or_else(|| format!("{} has no number column {name}", f.display()))
    };
    let (level, model, map, sd) = (strs("level")?, strs("model")?, nums("map")?, nums("sd")?);
    let mut out: PreviousPosterior = Vec::new();
    for i in 0..level.len() {
        match out
            .iter_mut()
            .find(|(l, m, _, _)| *l == level[i] && *m == model[i])
        {
            Some(row) => {
                row.2.push(map[i]);
                row.3.push(sd[i]);
            }
            None => out.push((
                level[i].clone(),
                model[i].clone(),
                vec![map[i]],
                vec![sd[i]],
            )),
        }
    }
    Ok(out)
}

/// The candidates' FRFs on the reduced model against the full model at seven lines across the
/// band (at one draw's modulus): the largest error relative to the largest FRF of each drive's
/// column, as a sentence for the report.
fn spot_check(
    model: &crate::fe::model::StructuralModel,
    rom: &crate::rom::ReducedModel,
    drives: &[usize],
    law: &dyn ConstitutiveModel,
    p: &[f64],
    band: (f64, f64),
) -> Result<String, DesignError> {
    use crate::frf::FrfEngine;
    let lines: Vec<f64> = (0..7)
        .map(|k| std::f64::consts::TAU * (band.0 + (band.1 - band.0) * (k as f64 + 0.37) / 7.0))
        .collect();
    let moduli: Vec<_> = lines.iter().map(|&w| law.modulus(p, w)).collect();
    let full = crate::frf::FullModel::new(model, drives, crate::frf::FullParams::default())
        .map_err(|e| failed("full model", e))?;
    let a = full
        .sweep(&lines, &moduli, false)
        .map_err(|e| failed("full model", e))?;
    let b = rom
        .sweep(&lines, &moduli, false)
        .map_err(|e| failed("reduced model", e))?;
    let mut worst: f64 = 0.0;
    for j in 0..drives.len() {
        let scale = (0..lines.len())
            .flat_map(|l| (0..a.n_out).map(move |o| (l, o)))
            .map(|(l, o)| a.h[a.idx(l, o, j)].norm())
            .fold(0.0, f64::max);
        for l in 0..lines.len() {
            for o in 0..a.n_out {
                let d = (a.h[a.idx(l, o, j)] - b.h[b.idx(l, o, j)]).norm();
                worst = worst.max(d / scale.max(f64::MIN_POSITIVE));
            }
        }
    }
    Ok(format!(
        "Spot check of every candidate's FRF on the reduced model against the full model at 7 lines: largest error {worst:.1e} of the drive column's largest FRF."
    ))
}
