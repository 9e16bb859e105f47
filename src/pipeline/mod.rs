//! The pipeline: a validated [`Study`] -> its [`Plan`] ([`Study::plan`]) -> [`run`] with an
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

mod executor;
mod lower;
mod plan;
pub(crate) mod results;

pub use crate::runner::{Event, RunError, RunOptions, RunSummary};
pub use executor::{Executor, Observer};
pub use plan::{
    DataParams, EngineParams, IdentificationParams, InferenceParams, Plan, SamplerParams,
};
pub use results::{IdentifiedParameters, Results, LOOP_DIR};

use crate::frf::FrfEngine;
use crate::study::build::BuiltModel;
use crate::study::Study;
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
    use crate::runner::stages;
    let t0 = Instant::now();
    let observers = ex.progress();
    let progress = |e: Event| {
        observers(e.clone());
        extra(e);
    };
    let study = &lowered.study;
    let laws = stages::model_laws(study)?;
    progress(Event::Start {
        step: "assembling the FE model".into(),
        total: 0,
    });
    let built = stages::build(study)?;
    progress(Event::Finish);
    ex.lap("build model")?;
    let mut data = stages::load_levels(study, &built)?;
    stages::check_initial_values(study, &built, &data, &laws)?;
    ex.lap("load and check data")?;
    let mesh_error = if study.analyses.mesh_error {
        progress(Event::Start {
            step: "estimating the mesh's discretisation error".into(),
            total: 0,
        });
        let d =
            crate::runner::preflight::mesh_error_at_initial_values(study, &built, &data, &laws)?;
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
    let engines = stages::build_engine(study, &built, &mut data, &laws, ex.rom_cache_dir())?;
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
        let mut r = stages::analyse_level(study, det_built, det_engine, level, &laws, &progress)?;
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
            let o = crate::runner::closed_loop::loop_stage(
                study, &built, &data, &laws, lik, None, &params,
            )?;
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

/// Run a study: identification, correlation, tables, figures, report and manifest in
/// `study.output_dir` (or `opts.output_dir`), replaced atomically as a whole (module doc).
/// The same path as [`run`] then [`crate::report::write`].
pub fn run_study(
    study: &Study,
    opts: &RunOptions,
    progress: &(dyn Fn(Event) + Sync),
) -> Result<RunSummary, RunError> {
    let mut plan = study.plan()?;
    if let Some(d) = &opts.output_dir {
        plan.output_dir = d.clone();
    }
    plan.figures &= !opts.no_figures;
    let mut ex = Executor::new();
    if let Some(d) = &opts.rom_cache {
        ex = ex.rom_cache(d.clone());
    }
    let results = run_with(&plan, &mut ex, progress)?;
    let written = crate::report::write_with(&results, &plan.output_dir, progress)?;
    Ok(RunSummary {
        study: study.name.clone(),
        output_dir: plan.output_dir.clone(),
        files: written.files,
        models: results.model_summaries(),
        seconds: results.seconds() + written.seconds,
    })
}

/// The samplers' and the stepping-stone's checkpoints of a run writing to `output_dir`:
/// `.checkpoints/` beside it.
fn checkpoint_folder(output_dir: &std::path::Path) -> std::path::PathBuf {
    output_dir
        .parent()
        .unwrap_or(std::path::Path::new("."))
        .join(".checkpoints")
}
