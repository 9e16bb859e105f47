//! The [`Plan`]: what a run will do, stage by stage, as typed `*Params` made from a validated
//! [`Study`] by [`Study::plan`]. A program may edit the plan before [`super::run`]: drop a
//! model, change the sampler settings of one inference stage, switch the engine.
//!
//! Every stage reads its parameters from the plan. [`Plan::lowered`] also writes them into a
//! copy of the study, which the results carry, so the report describes the plan that ran.

use super::RunError;
pub use crate::bayes::{InferenceParams, SamplerParams};
use crate::closed_loop::ClosedLoopParams;
pub use crate::identify::IdentificationParams;
pub use crate::stage::engine::{EngineParams, LikelihoodInputs};
use crate::study::comparison::{BasinSettings, LevelSettings};
use crate::study::inference::Inference;
use crate::study::Study;
use std::path::PathBuf;
use std::sync::Arc;

/// The data stage: which files make each level, over which band, with the analyser's H1
/// estimator and the truth sidecar of simulated data: the study's validated
/// `[measurements]` section, as it is.
pub type DataParams = crate::study::Measurements;

/// A run's stages. Made by [`Study::plan`]; run by [`super::run`].
#[derive(Clone, Debug)]
pub struct Plan {
    study: Arc<Study>,
    /// The seed of every random stream of the run (`[study] seed`): the samplers' chains, the
    /// MAP searches' space-filling starts, the closed loop's multistart searches and its
    /// simulated replicate experiments all derive their streams from it, and from nothing else
    /// (not the thread count).
    pub seed: u64,
    pub engine: EngineParams,
    pub data: DataParams,
    pub identification: IdentificationParams,
    /// One stage per (model, level) of `[inference]`, levels in data order.
    pub inference: Vec<InferenceParams>,
    /// The comparison across levels (with inference on two levels or more).
    pub comparison: Option<LevelSettings>,
    /// The basin study of the MAP search (`[inference.basins]`).
    pub basins: Option<BasinSettings>,
    /// The closed loop (`[closed_loop]` with `[inference]`), run on the run's engine: the
    /// loop's settings and the stage's (model, levels, candidates, term ROM).
    pub closed_loop: Option<ClosedLoopParams>,
    pub closed_loop_stage: Option<crate::diagnose::DiagnoseParams>,
    /// The term ROM's settings when the study declares effects with matrices of their own (a
    /// degraded bond, base springs, adherend damping): the inference stages' likelihood then
    /// runs on the term ROM ([`crate::diagnose::terms::term_rom_for`]).
    pub declared_terms: Option<crate::diagnose::TermParams>,
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
                Some(m) => m.clone(),
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
        .then(|| crate::diagnose::params_of(s));
        let closed_loop_stage = match closed_loop {
            Some(_) => Some(crate::diagnose::DiagnoseParams::of(s, None)?),
            None => None,
        };
        Ok(Plan {
            seed: s.seed,
            engine: EngineParams::of(s),
            data,
            identification: IdentificationParams {
                models: s.models.clone(),
                rfm: rfm_params(s),
                per_line: s.analyses.per_line,
                correlation: s.analyses.correlation,
                sensitivity: s.analyses.sensitivity,
                mesh_error: s.analyses.mesh_error,
                band_constant: s.analyses.band_constant.clone(),
                iem: s.analyses.iem.clone(),
            },
            inference,
            comparison: s.inference.as_ref().map(|i| i.level_change.clone()),
            basins: s.inference.as_ref().and_then(|i| i.basins.clone()),
            closed_loop,
            closed_loop_stage,
            declared_terms: (!crate::diagnose::with_declared(&s.declared_effects, &[]).is_empty())
                .then(|| crate::diagnose::TermParams::of(s)),
            output_dir: s.output_dir.clone(),
            figures: s.analyses.figures,
            study,
        })
    }

    /// The study the plan was made from (as loaded, before any edit of the plan).
    pub fn study(&self) -> &Study {
        &self.study
    }

    /// The inputs of the likelihood's engine this plan needs, as it stands now: none without
    /// inference or the closed loop, every measured point for the closed loop (its candidate
    /// masses act there) and for declared point masses, else the excitation column.
    pub fn likelihood_inputs(&self) -> Option<LikelihoodInputs> {
        LikelihoodInputs::needed(
            !self.inference.is_empty() || self.closed_loop.is_some(),
            self.closed_loop.is_some(),
            &self.study.declared_effects,
        )
    }
}

/// The sampler settings of an `[inference]` section.
pub(super) fn sampler_params(inf: &Inference) -> SamplerParams {
    SamplerParams::from(inf)
}

/// The RFM settings of a study's `[solver]`.
fn rfm_params(s: &Study) -> crate::rfm::RfmParams {
    crate::rfm::RfmParams {
        tol_rel_change: s.solver.tolerance,
        max_iterations: s.solver.max_iterations,
        rcond: s.solver.svd_rtol,
        ..crate::rfm::RfmParams::default()
    }
}
