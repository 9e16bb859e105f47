//! The [`Plan`]: what a run will do, stage by stage, as typed `*Params` made from a validated
//! [`Study`] by [`Study::plan`]. A program may edit the plan before [`super::run`]: drop a
//! model, change the sampler settings of one inference stage, switch the engine.
//!
//! The stages of the runner still read their settings from a study; [`Plan::lowered`] writes
//! the plan's parameters back into a copy of the study the plan was made from, so an edited
//! plan is what runs.

use super::RunError;
use crate::closed_loop::ClosedLoopParams;
use crate::inference::prior::Prior;
use crate::rfm::RfmParams;
use crate::study::comparison::{BasinSettings, LevelSettings};
use crate::study::inference::{
    CorrelationKind, Inference, NoiseSpec, NutsSettings, SteppingStoneSettings,
};
use crate::study::{Band, Engine, Estimator, Level, ModelSpec, Study};
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::Arc;

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

/// The data stage: which files make each level, over which band.
#[derive(Clone, Debug, PartialEq)]
pub struct DataParams {
    pub levels: Vec<Level>,
    /// Lines kept (Hz, inclusive); `None`: every line above 0 Hz.
    pub band_hz: Option<(f64, f64)>,
    /// Response channels kept (point ids); `None`: all measured.
    pub channels: Option<Vec<u32>>,
    /// The analyser's H1 estimator, when the fits model its leakage.
    pub estimator: Option<Estimator>,
    /// Truth sidecar of simulated data (the report compares with it).
    pub truth: Option<PathBuf>,
}

/// The deterministic identification stage (per level): per-line RFM, Model 1 over bands,
/// circle fit + IEM, global RFM per model, correlation, sensitivities.
#[derive(Clone, Debug, PartialEq)]
pub struct IdentificationParams {
    /// The laws identified by the global RFM, with their initial values (SI).
    pub models: Vec<ModelSpec>,
    /// The RFM iteration's stopping rules and SVD truncation.
    pub rfm: RfmParams,
    pub per_line: bool,
    pub correlation: bool,
    pub sensitivity: bool,
    pub band_constant: Vec<Band>,
    pub iem: Vec<Band>,
}

/// Settings of the MAP search and the samplers of an inference stage.
#[derive(Clone, Debug, PartialEq)]
pub struct SamplerParams {
    pub nuts: Option<NutsSettings>,
    pub tmcmc_particles: Option<usize>,
    pub stepping_stone: Option<SteppingStoneSettings>,
    pub noise: NoiseSpec,
    pub noise_scale_prior: Prior,
    pub nu_prior: Prior,
    pub map_starts: usize,
    pub map_max_iterations: u64,
    pub linearised_measurement: bool,
    pub channel_correlation: Option<(CorrelationKind, usize)>,
}

/// The posterior of one model at one level: MAP, samplers, evidence, model-comparison
/// criteria and redundancy.
#[derive(Clone, Debug, PartialEq)]
pub struct InferenceParams {
    pub level: String,
    pub model: String,
    /// One prior per law parameter, then the noise parameters'.
    pub priors: Vec<Prior>,
    pub samplers: SamplerParams,
}

/// A run's stages. Made by [`Study::plan`]; run by [`super::run`].
#[derive(Clone, Debug)]
pub struct Plan {
    study: Arc<Study>,
    pub engine: EngineParams,
    pub data: DataParams,
    pub identification: IdentificationParams,
    /// One stage per (model, level) of `[inference]`, levels in data order.
    pub inference: Vec<InferenceParams>,
    /// The comparison across levels (with inference on two levels or more).
    pub comparison: Option<LevelSettings>,
    /// The basin study of the MAP search (`[inference.basins]`).
    pub basins: Option<BasinSettings>,
    /// The closed loop (`[closed_loop]` with `[inference]`), run on the run's engine.
    pub closed_loop: Option<ClosedLoopParams>,
    /// Where [`crate::report::write`] puts the results by default.
    pub output_dir: PathBuf,
    /// Whether the report draws figures.
    pub figures: bool,
}

impl Study {
    /// Load and validate a study file (TOML as written -> typed study with units and
    /// defaults); errors name the file, the key and the fix.
    pub fn load(path: impl AsRef<std::path::Path>) -> Result<Study, crate::study::StudyError> {
        crate::study::load(path.as_ref())
    }

    /// The stages of a run of this study.
    pub fn plan(&self) -> Result<Plan, RunError> {
        Plan::new(Arc::new(self.clone()))
    }
}

impl Plan {
    /// The plan of `study` (see [`Study::plan`]).
    pub fn new(study: Arc<Study>) -> Result<Plan, RunError> {
        let s = &*study;
        let data =
            match &s.measurements {
                Some(m) => DataParams {
                    levels: m.levels.clone(),
                    band_hz: m.band_hz,
                    channels: m.channels.clone(),
                    estimator: m.estimator.clone(),
                    truth: m.truth.clone(),
                },
                None => return Err(RunError::Study(crate::study::StudyError {
                    file: s.file.display().to_string(),
                    key: "measurements".into(),
                    message:
                        "no [measurements] section: add [[measurements.levels]] with name and files"
                            .into(),
                })),
            };
        let mut inference = Vec::new();
        if let Some(inf) = &s.inference {
            let samplers = sampler_params(inf);
            for level in &data.levels {
                if !inf.levels.contains(&level.name) {
                    continue;
                }
                for model in &inf.models {
                    inference.push(InferenceParams {
                        level: level.name.clone(),
                        model: model.clone(),
                        priors: inf.priors.get(model).cloned().unwrap_or_default(),
                        samplers: samplers.clone(),
                    });
                }
            }
        }
        let closed_loop = (s.inference.is_some()
            && s.closed_loop.as_ref().is_some_and(|c| c.enabled))
        .then(|| crate::runner::closed_loop::params_of(s));
        Ok(Plan {
            engine: EngineParams {
                engine: s.solver.engine,
                rom_tolerance: s.solver.rom_tolerance,
                threads: s.solver.threads,
            },
            data,
            identification: IdentificationParams {
                models: s.models.clone(),
                rfm: crate::runner::stages::rfm_params(s),
                per_line: s.analyses.per_line,
                correlation: s.analyses.correlation,
                sensitivity: s.analyses.sensitivity,
                band_constant: s.analyses.band_constant.clone(),
                iem: s.analyses.iem.clone(),
            },
            inference,
            comparison: s.inference.as_ref().map(|i| i.level_change.clone()),
            basins: s.inference.as_ref().and_then(|i| i.basins.clone()),
            closed_loop,
            output_dir: s.output_dir.clone(),
            figures: s.analyses.figures,
            study,
        })
    }

    /// The study the plan was made from (as loaded, before any edit of the plan).
    pub fn study(&self) -> &Study {
        &self.study
    }

    /// The study the stages read: the original with this plan's parameters written in, and
    /// the `[inference]` section per level (`None` for a level without inference stages).
    pub(crate) fn lowered(&self) -> Result<Lowered, RunError> {
        let mut s = (*self.study).clone();
        let bad = |key: &str, message: String| {
            RunError::Study(crate::study::StudyError {
                file: s_file(&self.study),
                key: key.into(),
                message,
            })
        };
        s.solver.engine = self.engine.engine;
        s.solver.rom_tolerance = self.engine.rom_tolerance;
        s.solver.threads = self.engine.threads;
        if let Some(m) = s.measurements.as_mut() {
            m.levels = self.data.levels.clone();
            m.band_hz = self.data.band_hz;
            m.channels = self.data.channels.clone();
            m.estimator = self.data.estimator.clone();
            m.truth = self.data.truth.clone();
        }
        let id = &self.identification;
        s.models = id.models.clone();
        s.solver.tolerance = id.rfm.tol_rel_change;
        s.solver.max_iterations = id.rfm.max_iterations;
        s.solver.svd_rtol = id.rfm.rcond;
        if id.rfm
            != (RfmParams {
                tol_rel_change: id.rfm.tol_rel_change,
                max_iterations: id.rfm.max_iterations,
                rcond: id.rfm.rcond,
                ..RfmParams::default()
            })
        {
            return Err(bad(
                "solver",
                "the plan's RFM settings other than tolerance, max_iterations and rcond must keep their defaults".into(),
            ));
        }
        s.analyses.per_line = id.per_line;
        s.analyses.correlation = id.correlation;
        s.analyses.sensitivity = id.sensitivity;
        s.analyses.band_constant = id.band_constant.clone();
        s.analyses.iem = id.iem.clone();
        s.analyses.figures = self.figures;
        s.output_dir = self.output_dir.clone();
        // Inference: one section per level, and the union for the comparison across levels.
        let mut per_level: Vec<(String, Inference)> = Vec::new();
        let mut union: Option<Inference> = None;
        for st in &self.inference {
            if !s
                .models
                .iter()
                .any(|m| m.name.eq_ignore_ascii_case(&st.model))
            {
                return Err(bad(
                    "inference.models",
                    format!(
                        "inference stage {} at {}: the model is not among the identified models",
                        st.model, st.level
                    ),
                ));
            }
            let u = union.get_or_insert_with(|| inference_of(st, &self.comparison, &self.basins));
            merge(u, st).map_err(|m| bad("inference", m))?;
            match per_level.iter_mut().find(|(l, _)| *l == st.level) {
                Some((_, inf)) => merge(inf, st).map_err(|m| bad("inference", m))?,
                None => {
                    let mut inf = inference_of(st, &self.comparison, &self.basins);
                    merge(&mut inf, st).map_err(|m| bad("inference", m))?;
                    per_level.push((st.level.clone(), inf));
                }
            }
        }
        s.inference = union;
        s.closed_loop = match (&self.closed_loop, s.closed_loop.take()) {
            (Some(_), Some(c)) => Some(c),
            (Some(_), None) => Some(Default::default()),
            (None, Some(c)) => Some(crate::study::effects::ClosedLoopSettings {
                enabled: false,
                ..c
            }),
            (None, None) => None,
        };
        Ok(Lowered {
            study: s,
            per_level,
        })
    }
}

/// A study as the stages read it (see [`Plan::lowered`]).
pub(crate) struct Lowered {
    pub study: Study,
    pub per_level: Vec<(String, Inference)>,
}

impl Lowered {
    /// The inference section of `level`, when it has inference stages.
    pub fn inference(&self, level: &str) -> Option<&Inference> {
        self.per_level
            .iter()
            .find(|(l, _)| l == level)
            .map(|(_, i)| i)
    }
}

fn s_file(s: &Study) -> String {
    s.file.display().to_string()
}

fn sampler_params(inf: &Inference) -> SamplerParams {
    SamplerParams {
        nuts: inf.nuts.clone(),
        tmcmc_particles: inf.tmcmc_particles,
        stepping_stone: inf.stepping_stone.clone(),
        noise: inf.noise.clone(),
        noise_scale_prior: inf.noise_scale_prior.clone(),
        nu_prior: inf.nu_prior.clone(),
        map_starts: inf.map_starts,
        map_max_iterations: inf.map_max_iterations,
        linearised_measurement: inf.linearised_measurement,
        channel_correlation: inf.channel_correlation,
    }
}

/// An empty `[inference]` section with the settings of stage `st`.
fn inference_of(
    st: &InferenceParams,
    comparison: &Option<LevelSettings>,
    basins: &Option<BasinSettings>,
) -> Inference {
    let p = &st.samplers;
    Inference {
        models: Vec::new(),
        levels: Vec::new(),
        nuts: p.nuts.clone(),
        tmcmc_particles: p.tmcmc_particles,
        stepping_stone: p.stepping_stone.clone(),
        noise: p.noise.clone(),
        priors: BTreeMap::new(),
        noise_scale_prior: p.noise_scale_prior.clone(),
        nu_prior: p.nu_prior.clone(),
        map_starts: p.map_starts,
        map_max_iterations: p.map_max_iterations,
        linearised_measurement: p.linearised_measurement,
        channel_correlation: p.channel_correlation,
        level_change: comparison.clone().unwrap_or_default(),
        basins: basins.clone(),
    }
}

/// Add stage `st` to `inf`; the stages sharing one section must share its sampler settings
/// and a model's priors.
fn merge(inf: &mut Inference, st: &InferenceParams) -> Result<(), String> {
    if sampler_params(inf) != st.samplers {
        return Err(format!(
            "inference stage {} at {}: the stages of one run share their sampler settings; give every stage the same `samplers`",
            st.model, st.level
        ));
    }
    match inf.priors.get(&st.model) {
        Some(p) if *p != st.priors => {
            return Err(format!(
                "inference stage {} at {}: the priors of a model must be the same at every level",
                st.model, st.level
            ))
        }
        Some(_) => {}
        None => {
            inf.priors.insert(st.model.clone(), st.priors.clone());
        }
    }
    if !inf.models.contains(&st.model) {
        inf.models.push(st.model.clone());
    }
    if !inf.levels.contains(&st.level) {
        inf.levels.push(st.level.clone());
    }
    Ok(())
}
