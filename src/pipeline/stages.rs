//! The stages [`super::run`] sequences: the model, data and engines ([`prepare`]), per level the
//! deterministic identification and the inference stages ([`level`]), the comparison across
//! levels ([`across_levels`]) and the closed loop ([`closed_loop`]). Each reads its parameters
//! from the [`Plan`], calls one algorithm layer and records its lap on the [`Executor`].

use super::{closed_loop as plan_loop, Event, Executor, LevelResults, Plan, RunError};
use crate::bayes::{self, declared, levels as across, RunContext};
use crate::frf::FrfEngine;
use crate::material::ConstitutiveModel;
use crate::stage::engine::{build_engine, Engines, ModelsAndData};
use crate::stage::LevelData;
use crate::study::build::BuiltModel;
use crate::study::Study;

/// What every later stage runs on: the laws, the built model, the levels' data, the engines,
/// and the mesh's discretisation error when the plan asks for it.
pub(super) struct Prepared {
    pub laws: Vec<Box<dyn ConstitutiveModel>>,
    pub built: BuiltModel,
    pub data: Vec<LevelData>,
    pub engines: Engines,
    /// How the mesh was chosen and the error it leaves.
    pub mesh: Option<crate::discretisation::Discretisation>,
    /// The term ROM of the study's declared degraded bonds, base springs and adherend damping
    /// (when it declares any and runs inference), over the likelihood's engine.
    pub declared_terms: Option<crate::rom::TermRom>,
    /// The band of the levels' lines (Hz).
    pub band_hz: (f64, f64),
    /// The pre-flight's warnings that bear on the results.
    pub warnings: Vec<String>,
}

impl Prepared {
    /// The engine of the deterministic analyses (inputs at every measured point).
    fn engine(&self) -> &dyn FrfEngine {
        self.engines.engine.as_ref()
    }
    /// The likelihood's engine (the deterministic one when no separate one was built).
    fn likelihood(&self) -> &dyn FrfEngine {
        self.engines.likelihood.as_deref().unwrap_or(self.engine())
    }
    /// The inference stages' engine: the likelihood's, with the declared effects' terms when
    /// the study declares effects with matrices of their own.
    pub fn inference_engine(&self) -> Result<InferenceEngine<'_>, RunError> {
        Ok(match &self.declared_terms {
            Some(t) => InferenceEngine::WithTerms(
                crate::rom::WithTerms::new(self.likelihood(), t)
                    .map_err(|e| RunError::Engine(e.to_string()))?,
            ),
            None => InferenceEngine::Plain(self.likelihood()),
        })
    }
}

/// The engine the inference stages run on ([`Prepared::inference_engine`]).
pub(super) enum InferenceEngine<'a> {
    Plain(&'a dyn FrfEngine),
    WithTerms(crate::rom::WithTerms<'a>),
}

impl InferenceEngine<'_> {
    pub fn get(&self) -> &dyn FrfEngine {
        match self {
            InferenceEngine::Plain(e) => *e,
            InferenceEngine::WithTerms(w) => w,
        }
    }
}

/// The model, the data (checked against every model's initial values), the mesh error and the
/// engines.
pub(super) fn prepare(
    plan: &Plan,
    study: &Study,
    ex: &mut Executor,
    progress: &(dyn Fn(Event) + Sync),
) -> Result<Prepared, RunError> {
    let models = &plan.identification.models;
    crate::stage::preflight::check_settings(models, &plan.output_dir, &study.file)?;
    let laws = crate::stage::model_laws(models, &study.file)?;
    progress(Event::Start {
        step: "assembling the FE model".into(),
        total: 0,
    });
    let built = crate::stage::model::build_with(&study.structure, &study.file, &|line| {
        progress(Event::Start {
            step: format!("assembling the FE model: {line}"),
            total: 0,
        })
    })?;
    progress(Event::Finish);
    ex.lap("build model")?;
    // The pre-flight of the data, before anything is fitted.
    let crate::stage::data::LoadedLevels {
        levels: mut data,
        warnings,
    } = crate::stage::preflight::check_data(
        &crate::stage::preflight::DataChecks {
            file: &study.file,
            measurements: Some(&plan.data),
            points: &study.structure.points,
            band_constant: &plan.identification.band_constant,
            iem: &plan.identification.iem,
        },
        &built,
    )?;
    let band_hz = crate::stage::data::band_of(&data);
    crate::stage::model::check_initial_values(models, &study.file, &data, &laws)?;
    ex.lap("load and check data")?;
    let mesh = if built.discretisation.is_some() {
        built.discretisation.clone()
    } else if plan.identification.mesh_error {
        progress(Event::Start {
            step: "estimating the mesh's discretisation error".into(),
            total: 0,
        });
        let d = crate::stage::preflight::mesh_error_at_initial_values(
            models,
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
        None
    };
    let mut warnings = warnings;
    warnings.extend(crate::stage::preflight::mesh_error_warnings(mesh.as_ref()));
    // the model's first y mode against the data's first peak, as `rfmlab check` says it
    let mut first = crate::stage::preflight::Preflight::default();
    crate::stage::preflight::check_first_mode(models, &built, &data, &laws, &mut first)?;
    warnings.extend(first.warnings);
    progress(Event::Start {
        step: "building the FRF engine".into(),
        total: 0,
    });
    let for_models = ModelsAndData {
        models,
        laws: &laws,
        estimator: plan.data.estimator.as_ref(),
        file: &study.file,
    };
    let engines = build_engine(
        &plan.engine,
        plan.likelihood_inputs(),
        &for_models,
        &built,
        &mut data,
        ex.rom_cache_dir(),
    )?;
    progress(Event::Finish);
    ex.count("rom builds", engines.rom_builds);
    ex.count("rom cache loads", engines.rom_cache_loads);
    ex.lap("engine")?;
    Ok(Prepared {
        laws,
        built,
        data,
        engines,
        mesh,
        declared_terms: None,
        band_hz,
        warnings,
    })
}

/// The term ROM of the study's declared degraded bonds, base springs and adherend damping,
/// over the likelihood's engine, when the plan declares any and runs inference.
pub(super) fn declared_terms(
    plan: &Plan,
    study: &Study,
    run: &mut Prepared,
    ex: &mut Executor,
    progress: &(dyn Fn(Event) + Sync),
) -> Result<(), RunError> {
    let Some(terms) = plan
        .declared_terms
        .as_ref()
        .filter(|_| !plan.inference.is_empty())
    else {
        return Ok(());
    };
    progress(Event::Start {
        step: "building the term ROM of the declared effects".into(),
        total: 0,
    });
    let effects = crate::diagnose::with_declared(&study.declared_effects, &[]);
    let t = crate::diagnose::terms::term_rom_for(
        terms,
        &run.built,
        run.likelihood(),
        &effects,
        run.band_hz,
    )?;
    progress(Event::Finish);
    ex.lap("term ROM")?;
    run.declared_terms = t.map(|(rom, _)| rom);
    Ok(())
}

/// One level: the deterministic identification (on the structure with the declared point
/// masses and beam factor), then the level's inference stages and their basin study.
pub(super) fn level(
    plan: &Plan,
    study: &Study,
    run: &Prepared,
    bayes_run: &RunContext<'_>,
    level: &LevelData,
    ex: &mut Executor,
    progress: &(dyn Fn(Event) + Sync),
) -> Result<LevelResults, RunError> {
    let view = declared::deterministic_view(
        &study.declared_effects,
        &study.file,
        run.engine(),
        &run.built,
        level,
    )?;
    let (det_engine, det_built): (&dyn FrfEngine, &BuiltModel) = match &view {
        Some(v) => (&v.engine, &v.built),
        None => (run.engine(), &run.built),
    };
    let inputs = crate::identify::LevelInputs {
        built: det_built,
        engine: det_engine,
        level,
        laws: &run.laws,
        estimator: plan.data.estimator.as_ref(),
        file: &study.file,
        certified: run.engines.certified.as_ref(),
    };
    let id = crate::identify::analyse_level(&plan.identification, &inputs, progress)?;
    let mut r = LevelResults::new(id);
    ex.lap(format!("analyses {}", level.name))?;
    let stages = bayes::stages_at(&plan.inference, &level.name);
    if stages.is_empty() {
        return Ok(r);
    }
    let fits: Vec<&crate::rfm::RfmResult> = r.global.iter().map(|g| &g.result).collect();
    let lik = run.inference_engine()?;
    r.posteriors = bayes::infer_level(bayes_run, &stages, lik.get(), level, &fits, progress)?;
    ex.lap(format!("inference {}", level.name))?;
    for p in &r.posteriors {
        for (step, s) in &p.step_seconds {
            ex.detail(format!("inference {} {}: {step}", level.name, p.model), *s);
        }
    }
    if let Some(settings) = &plan.basins {
        bayes::basins_of_level(
            bayes_run,
            &stages,
            settings,
            &plan.identification.rfm,
            lik.get(),
            run.engine(),
            level,
            &mut r.posteriors,
        )?;
        ex.lap(format!("basins {}", level.name))?;
    }
    Ok(r)
}

/// The comparison across levels (with inference), kept with the higher level's results.
pub(super) fn across_levels(
    plan: &Plan,
    bayes_run: &RunContext<'_>,
    run: &Prepared,
    levels: &mut [LevelResults],
    ex: &mut Executor,
) -> Result<(), RunError> {
    if plan.inference.is_empty() {
        return Ok(());
    }
    let settings = plan.comparison.clone().unwrap_or_default();
    let posteriors: Vec<(&str, &[bayes::PosteriorResult])> = levels
        .iter()
        .map(|r| (r.level.as_str(), r.posteriors.as_slice()))
        .collect();
    let lik = run.inference_engine()?;
    let compared = across::compare(
        bayes_run,
        &plan.inference,
        &settings,
        &plan.data,
        lik.get(),
        &run.data,
        &posteriors,
    )?;
    if let Some(c) = compared {
        if let Some(r) = levels.iter_mut().find(|r| r.level == c.high) {
            r.across_levels = Some(c);
        }
        ex.lap("across levels")?;
    }
    Ok(())
}

/// The closed loop on the run's likelihood engine, when the plan has it.
pub(super) fn closed_loop(
    plan: &Plan,
    study: &Study,
    run: &Prepared,
    bayes_run: &RunContext<'_>,
    ex: &mut Executor,
    progress: &(dyn Fn(Event) + Sync),
) -> Result<Option<crate::diagnose::LoopOutcome>, RunError> {
    let Some(params) = &plan.closed_loop else {
        return Ok(None);
    };
    let mut params = params.clone();
    // The loop's multistart searches and its replicate experiments follow the plan's seed.
    params.map.seed = plan.seed;
    let say = ex.progress();
    params.progress = crate::closed_loop::Progress::new(move |m| {
        say(Event::Start {
            step: format!("closed loop: {m}"),
            total: 0,
        })
    });
    let mut stage = match &plan.closed_loop_stage {
        Some(s) => s.clone(),
        None => crate::diagnose::DiagnoseParams::of(study, None)?,
    };
    stage.null.seed = plan.seed;
    let posterior = plan_loop::PlanPosterior {
        stages: &plan.inference,
        inputs: bayes_run.posterior,
    };
    let inputs = crate::diagnose::LoopInputs {
        built: &run.built,
        levels: &run.data,
        laws: &run.laws,
        engine: run.likelihood(),
        posterior: &posterior,
        starting_fits: &[],
    };
    let outcome = crate::diagnose::loop_stage(&stage, &params, &inputs)?;
    progress(Event::Finish);
    for (step, seconds) in &outcome.timings {
        ex.detail(format!("closed loop {step}"), *seconds);
    }
    ex.lap("closed loop")?;
    Ok(Some(outcome))
}
