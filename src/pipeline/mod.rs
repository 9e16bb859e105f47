//! The pipeline: a validated [`crate::Study`] -> its [`Plan`] ([`crate::Study::plan`]) -> [`run`] with an
//! [`Executor`] -> [`Results`] in memory -> [`crate::report::write`] (parquet, figures,
//! report.md and manifest.json in one atomic folder swap).
//!
//! Stages, in order: the structural model and the FRF engine (certified ROM, built once per
//! run or loaded from the executor's cache), the measured data of every level, per level the
//! deterministic identification and the inference stages of that level (MAP, samplers,
//! evidence, comparison criteria, redundancy, basins), then the comparison across levels.
//! The executor's cancellation flag is checked between stages.
//!
//! ```no_run
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let study = rfmlab::Study::load("studies/default.toml")?;
//! let plan = study.plan()?;
//! let mut ex = rfmlab::pipeline::Executor::new();
//! let results = rfmlab::pipeline::run(&plan, &mut ex)?;
//! let p = results.identified_at("L1", "model4").expect("model4 ran at L1");
//! println!("{:?} = {:?}", p.names, p.identified);
//! rfmlab::report::write(&results, "results/default")?;
//! # Ok(())
//! # }
//! ```

mod check;
mod closed_loop;
mod executor;
mod level_results;
mod lower;
mod plan;
pub(crate) mod results;
pub(crate) mod tables;

pub use crate::stage::{Event, RunError};
pub use check::{check, check_study, CheckSummary};
pub use executor::{Executor, Observer};
pub use level_results::LevelResults;
pub use plan::{
    DataParams, EngineParams, IdentificationParams, InferenceParams, Plan, SamplerParams,
};
pub use results::ModelSummary;
pub use results::{IdentifiedParameters, Results, LOOP_DIR};

use crate::frf::FrfEngine;
use crate::study::build::BuiltModel;
use std::sync::Arc;
use std::time::Instant;

/// Run `plan`: every stage in memory, nothing written (see [`crate::report::write`]).
/// Timings and counters go to `executor` and into the results.
pub fn run(plan: &Plan, executor: &mut Executor) -> Result<Results, RunError> {
    run_with(plan, executor, &|_| {})
}

/// [`run`] with one more progress callback (borrowed, for callers without `'static` ones).
pub(crate) fn run_with(
    plan: &Plan,
    executor: &mut Executor,
    extra: &(dyn Fn(Event) + Sync),
) -> Result<Results, RunError> {
    let lowered = plan.lowered()?;
    executor.reset();
    executor.check()?;
    // `threads`: a pool of that size for the whole run (results do not depend on it).
    if let Some(t) = plan.engine.threads {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(t)
            .build()
            .map_err(|e| RunError::Engine(format!("thread pool of {t} threads: {e}")))?;
        return pool.install(|| run_here(plan, lowered, executor, extra));
    }
    run_here(plan, lowered, executor, extra)
}

fn run_here(
    plan: &Plan,
    lowered: lower::Lowered,
    ex: &mut Executor,
    extra: &(dyn Fn(Event) + Sync),
) -> Result<Results, RunError> {
    use crate::bayes::{self, declared, levels};
    let t0 = Instant::now();
    let observers = ex.progress();
    let progress = |e: Event| {
        observers(e.clone());
        extra(e);
    };
    let study = &lowered.study;
    let laws = crate::stage::model_laws(&plan.identification.models, &study.file)?;
    progress(Event::Start {
        step: "assembling the FE model".into(),
        total: 0,
    });
    let built = crate::stage::model::build(&study.structure, &study.file)?;
    progress(Event::Finish);
    ex.lap("build model")?;
    let mut data = crate::stage::data::load_levels(Some(&plan.data), &built, &study.file)?;
    crate::stage::model::check_initial_values(
        &plan.identification.models,
        &study.file,
        &built,
        &data,
        &laws,
    )?;
    ex.lap("load and check data")?;
    let mesh_error = if plan.identification.mesh_error {
        progress(Event::Start {
            step: "estimating the mesh's discretisation error".into(),
            total: 0,
        });
        let d = crate::stage::preflight::mesh_error_at_initial_values(
            &plan.identification.models,
            &study.structure,
            &study.file,
            &built,
            &data,
            &laws,
        )?;
        progress(Event::Finish);
        ex.lap("mesh error")?;
        d
    } else {
        Vec::new()
    };
    progress(Event::Start {
        step: "building the FRF engine".into(),
        total: 0,
    });
    let models = crate::stage::engine::ModelsAndData {
        models: &plan.identification.models,
        laws: &laws,
        estimator: plan.data.estimator.as_ref(),
        file: &study.file,
    };
    // The closed loop needs the receptances of every measured point, also when it was added
    // to the plan after planning (its candidate masses act there).
    let mut engine_params = plan.engine.clone();
    if plan.closed_loop.is_some() {
        if let Some(all_inputs) = engine_params.likelihood.as_mut() {
            *all_inputs = true;
        }
    }
    let engines = crate::stage::engine::build_engine(
        &engine_params,
        &models,
        &built,
        &mut data,
        ex.rom_cache_dir(),
    )?;
    progress(Event::Finish);
    ex.count("rom builds", engines.rom_builds);
    ex.lap("engine")?;
    let engine: &dyn FrfEngine = engines.engine.as_ref();
    let lik: &dyn FrfEngine = engines.likelihood.as_deref().unwrap_or(engine);
    let point_ids: Vec<u32> = study.structure.points.iter().map(|p| p.id).collect();
    let checkpoints = checkpoint_folder(&plan.output_dir);
    let bayes_run = bayes::RunContext {
        posterior: bayes::PosteriorInputs {
            file: &study.file,
            estimator: plan.data.estimator.as_ref(),
            point_ids: &point_ids,
            declared: &study.declared_effects,
        },
        seed: study.seed,
        models: &plan.identification.models,
        laws: &laws,
        checkpoints: bayes::Checkpoints {
            folder: &checkpoints,
            study: &study.name,
            study_sha256: &study.sha256,
        },
    };
    let mut results = Vec::new();
    for level in &data {
        // Declared point masses and beam factor change the deterministic analyses' structure.
        let view = declared::deterministic_view(
            &study.declared_effects,
            &study.file,
            engine,
            &built,
            level,
        )?;
        let (det_engine, det_built): (&dyn FrfEngine, &BuiltModel) = match &view {
            Some(v) => (&v.engine, &v.built),
            None => (engine, &built),
        };
        let inputs = crate::identify::LevelInputs {
            built: det_built,
            engine: det_engine,
            level,
            laws: &laws,
            measurement: crate::stage::measurement::measurement_model(
                plan.data.estimator.as_ref(),
                level,
                &study.file,
            )?,
            file: &study.file,
        };
        let id = crate::identify::analyse_level(&plan.identification, &inputs, &progress)?;
        let mut r = results::LevelResults::new(id);
        ex.lap(format!("analyses {}", level.name))?;
        let stages = bayes::stages_at(&plan.inference, &level.name);
        if !stages.is_empty() {
            let fits: Vec<&crate::rfm::RfmResult> = r.global.iter().map(|g| &g.result).collect();
            r.posteriors = bayes::infer_level(&bayes_run, &stages, lik, level, &fits, &progress)?;
            ex.lap(format!("inference {}", level.name))?;
            if let Some(settings) = &plan.basins {
                bayes::basins_of_level(
                    &bayes_run,
                    &stages,
                    settings,
                    &plan.identification.rfm,
                    lik,
                    engine,
                    level,
                    &mut r.posteriors,
                )?;
                ex.lap(format!("basins {}", level.name))?;
            }
        }
        results.push(r);
    }
    if !plan.inference.is_empty() {
        let settings = plan.comparison.clone().unwrap_or_default();
        let posteriors: Vec<(&str, &[bayes::PosteriorResult])> = results
            .iter()
            .map(|r| (r.level.as_str(), r.posteriors.as_slice()))
            .collect();
        let across = levels::compare(
            &bayes_run,
            &plan.inference,
            &settings,
            &plan.data,
            lik,
            &data,
            &posteriors,
        )?;
        if let Some(c) = across {
            if let Some(r) = results.iter_mut().find(|r| r.level == c.high) {
                r.across_levels = Some(c);
            }
            ex.lap("across levels")?;
        }
    }
    let closed_loop = match &plan.closed_loop {
        Some(params) => {
            let mut params = params.clone();
            let say = ex.progress();
            params.progress = crate::closed_loop::Progress::new(move |m| {
                say(Event::Start {
                    step: format!("closed loop: {m}"),
                    total: 0,
                })
            });
            let stage = match &plan.closed_loop_stage {
                Some(s) => s.clone(),
                None => crate::diagnose::DiagnoseParams::of(study, None)?,
            };
            let posterior = closed_loop::PlanPosterior {
                stages: &plan.inference,
                inputs: bayes_run.posterior,
            };
            let inputs = crate::diagnose::LoopInputs {
                built: &built,
                levels: &data,
                laws: &laws,
                engine: lik,
                posterior: &posterior,
            };
            let o = crate::diagnose::loop_stage(&stage, &params, &inputs)?;
            progress(Event::Finish);
            ex.lap("closed loop")?;
            Some(o)
        }
        None => None,
    };
    Results::new(
        Arc::new(lowered.study.clone()),
        data,
        results,
        engines.note,
        ex.timings().to_vec(),
        ex.counters().to_vec(),
        t0.elapsed().as_secs_f64(),
        plan.figures,
        plan.output_dir.clone(),
        closed_loop,
        mesh_error,
    )
}

/// The samplers' and the stepping-stone's checkpoints of a run writing to `output_dir`:
/// `.checkpoints/` beside it.
fn checkpoint_folder(output_dir: &std::path::Path) -> std::path::PathBuf {
    output_dir
        .parent()
        .unwrap_or(std::path::Path::new("."))
        .join(".checkpoints")
}
