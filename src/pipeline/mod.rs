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
mod stages;
pub(crate) mod tables;

pub use crate::stage::{Event, RunError};
pub use check::{check, check_study, check_study_with, check_with, CheckSummary};
pub use executor::{Executor, Observer};
pub use level_results::LevelResults;
pub use plan::{
    DataParams, EngineParams, IdentificationParams, InferenceParams, LikelihoodInputs, Plan,
    SamplerParams,
};
pub use results::{FlaggedFit, ModelSummary};
pub use results::{IdentifiedParameters, ModelProbabilities, ModelProbability, Results, LOOP_DIR};

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
    let t0 = Instant::now();
    let observers = ex.progress();
    let progress = |e: Event| {
        observers(e.clone());
        extra(e);
    };
    let study = &lowered.study;
    let point_ids: Vec<u32> = study.structure.points.iter().map(|p| p.id).collect();
    let checkpoints = checkpoint_folder(&plan.output_dir);
    let mut run = stages::prepare(plan, study, ex, &progress)?;
    stages::declared_terms(plan, study, &mut run, ex, &progress)?;
    let bayes_run = crate::bayes::RunContext {
        posterior: crate::bayes::PosteriorInputs {
            file: &study.file,
            estimator: plan.data.estimator.as_ref(),
            point_ids: &point_ids,
            declared: &study.declared_effects,
        },
        seed: plan.seed,
        models: &plan.identification.models,
        laws: &run.laws,
        checkpoints: crate::bayes::Checkpoints {
            folder: &checkpoints,
            study: &study.name,
            study_sha256: &study.sha256,
        },
    };
    let mut levels = Vec::new();
    for level in &run.data {
        levels.push(stages::level(
            plan, study, &run, &bayes_run, level, ex, &progress,
        )?);
    }
    stages::across_levels(plan, &bayes_run, &run, &mut levels, ex)?;
    let closed_loop = stages::closed_loop(plan, study, &run, &bayes_run, ex, &progress)?;
    // The mesh's remaining error, after the comparisons across levels (which share the mesh).
    if let Some(d) = &run.mesh {
        let law_of: Vec<(&str, &dyn crate::material::ConstitutiveModel)> = plan
            .identification
            .models
            .iter()
            .zip(&run.laws)
            .map(|(m, l)| (m.name.as_str(), l.as_ref()))
            .collect();
        for r in &mut levels {
            crate::bayes::mesh_allowance::apply(
                &mut r.posteriors,
                d,
                &law_of,
                run.band_hz.1,
                plan.seed,
            );
        }
    }
    let stages::Prepared {
        data,
        engines,
        mesh,
        warnings,
        ..
    } = run;
    let mut results = Results::new(
        Arc::new(lowered.study.clone()),
        data,
        levels,
        engines.note,
        ex.timings().to_vec(),
        ex.counters().to_vec(),
        t0.elapsed().as_secs_f64(),
        plan.figures,
        plan.output_dir.clone(),
        closed_loop,
        mesh,
    )?;
    results.preflight_warnings = warnings;
    Ok(results)
}

/// The samplers' and the stepping-stone's checkpoints of a run writing to `output_dir`:
/// `.checkpoints/` beside it.
fn checkpoint_folder(output_dir: &std::path::Path) -> std::path::PathBuf {
    output_dir
        .parent()
        .unwrap_or(std::path::Path::new("."))
        .join(".checkpoints")
}
