//! Lowering a [`Plan`] to the study its results describe: the study the plan was made from with
//! the plan's parameters written in (the inference stages as one `[inference]` section), so the
//! report and the manifest speak of the plan that ran. Lowering also checks that the plan's
//! stages fit together: every inference stage's model is identified, and the stages share their
//! sampler settings and a model's priors. The stages themselves read the plan.

use super::plan::{sampler_params, InferenceParams, Plan};
use super::RunError;
use crate::rfm::RfmParams;
use crate::study::comparison::{BasinSettings, LevelSettings};
use crate::study::inference::Inference;
use crate::study::Study;
use std::collections::BTreeMap;

impl Plan {
    /// The study this plan's results describe: the original with the plan's parameters
    /// written in (module doc).
    pub(crate) fn lowered(&self) -> Result<Lowered, RunError> {
        let mut s = self.study().clone();
        s.seed = self.seed;
        let bad = |key: &str, message: String| {
            RunError::Study(crate::study::StudyError {
                file: self.study().file.display().to_string(),
                key: key.into(),
                message,
            })
        };
        s.solver.engine = self.engine.engine;
        s.solver.rom_tolerance = self.engine.rom_tolerance;
        s.solver.threads = self.engine.threads;
        if let Some(m) = s.measurements.as_mut() {
            *m = self.data.clone();
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
        s.analyses.mesh_error = id.mesh_error;
        s.analyses.band_constant = id.band_constant.clone();
        s.analyses.iem = id.iem.clone();
        s.analyses.figures = self.figures;
        s.output_dir = self.output_dir.clone();
        // Inference: one section for all stages.
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
            merge(u, st).map_err(|m| bad("inference", m.to_string()))?;
        }
        s.inference = union;
        s.closed_loop = match (&self.closed_loop, s.closed_loop.take()) {
            (Some(_), Some(c)) => {
                Some(crate::study::effects::ClosedLoopSettings { enabled: true, ..c })
            }
            (Some(_), None) => Some(Default::default()),
            (None, Some(c)) => Some(crate::study::effects::ClosedLoopSettings {
                enabled: false,
                ..c
            }),
            (None, None) => None,
        };
        Ok(Lowered { study: s })
    }
}

/// The study a run's results describe (see [`Plan::lowered`]).
pub(crate) struct Lowered {
    pub study: Study,
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

/// Why an inference stage cannot join the others of a run.
#[derive(Debug, thiserror::Error)]
enum StageMismatch {
    #[error("inference stage {model} at {level}: the stages of one run share their sampler settings; give every stage the same `samplers`")]
    Samplers { model: String, level: String },
    #[error(
        "inference stage {model} at {level}: the priors of a model must be the same at every level"
    )]
    Priors { model: String, level: String },
}

/// Add stage `st` to `inf`; the stages sharing one section must share its sampler settings
/// and a model's priors.
fn merge(inf: &mut Inference, st: &InferenceParams) -> Result<(), StageMismatch> {
    if sampler_params(inf) != st.samplers {
        return Err(StageMismatch::Samplers {
            model: st.model.clone(),
            level: st.level.clone(),
        });
    }
    match inf.priors.get(&st.model) {
        Some(p) if *p != st.priors => {
            return Err(StageMismatch::Priors {
                model: st.model.clone(),
                level: st.level.clone(),
            })
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
