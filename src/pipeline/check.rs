//! `rfmlab check`: a study validated without running it. The data files, channels,
//! excitation channel and band; the model parameters; the full model evaluated at every
//! model's initial values; and the pre-flight ([`crate::stage::preflight`]): a writable
//! results folder, the analysis bands against the lines, the first mode against the data's
//! first peak, the engine's cost and the mesh's discretisation error.

use super::plan::Plan;
use crate::stage::preflight;
use crate::stage::{input_error, model, RunError};
use crate::study::Study;
use std::path::PathBuf;

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

/// Validate a study without running it: data files, channels, excitation channel, band,
/// model parameters, and the full model evaluated at every model's initial values.
pub fn check(plan: &Plan) -> Result<CheckSummary, RunError> {
    check_with(plan, &|_| {})
}

/// [`check`] with a line per mesh of the refinement to `progress`.
pub fn check_with(plan: &Plan, progress: &dyn Fn(&str)) -> Result<CheckSummary, RunError> {
    let study = plan.study();
    let (models, file) = (&plan.identification.models, study.file.as_path());
    preflight::check_settings(models, &plan.output_dir, file)?;
    let laws = crate::stage::model_laws(models, file)?;
    let built = model::build_with(&study.structure, file, progress)?;
    let spec = crate::study::build::chosen_spec(&study.structure, &file.display().to_string())?;
    let cost = match &spec {
        Some(spec) => Some(
            crate::fe::joint::joint_cost_estimate(spec)
                .map_err(|e| input_error(file, e.key().to_string(), e.detail()))?,
        ),
        None => None,
    };
    let id = &plan.identification;
    let loaded = preflight::check_data(
        &preflight::DataChecks {
            file,
            measurements: Some(&plan.data),
            points: &study.structure.points,
            band_constant: &id.band_constant,
            iem: &id.iem,
        },
        &built,
    )?;
    let levels = loaded.levels;
    let mut pf = preflight::Preflight {
        cost: cost.map(|c| preflight::CostSummary {
            n_dof: c.n_dof,
            memory_bytes: c.memory_bytes,
            factor_seconds: c.factor_seconds,
            available_memory_bytes: crate::fe::cost::available_memory_bytes(),
        }),
        warnings: loaded.warnings,
        ..Default::default()
    };
    preflight::check_channels(&built, &levels, &mut pf.warnings);
    let lines_checked = model::check_initial_values(models, file, &levels, &laws)?;
    preflight::check_first_mode(models, &built, &levels, &laws, &mut pf)?;
    // the refinement's or the fixed mesh's record; an estimate of a mesh declared exact
    // (`allowance = false`) only when `[analyses] mesh_error` asks for it
    if built.discretisation.is_some() || id.mesh_error {
        match preflight::mesh_error_at_initial_values(
            models,
            &study.structure,
            file,
            &built,
            &levels,
            &laws,
        ) {
            Ok(d) => pf.mesh = d,
            // a refined mesh beyond the machine, or a solver that cannot resolve it, leaves the
            // estimate out with a warning (the study's own mesh is fine)
            Err(err) => pf.warnings.push(format!(
                "structure.mesh: no discretisation-error estimate ({err})"
            )),
        }
    }
    pf.discretisation = pf
        .mesh
        .as_ref()
        .map(|d| d.modes.clone())
        .unwrap_or_default();
    pf.warnings
        .extend(preflight::mesh_error_warnings(pf.mesh.as_ref()));
    Ok(CheckSummary {
        preflight: pf,
        study: study.name.clone(),
        output_dir: plan.output_dir.clone(),
        n_dof: built.model.n_dof(),
        levels: levels
            .iter()
            .map(|l| (l.name.clone(), l.freq_hz.len(), l.response_ids.clone()))
            .collect(),
        models: models
            .iter()
            .map(|m| (m.name.clone(), m.levels.clone()))
            .collect(),
        lines_checked,
    })
}

/// [`check`] of the plan of `study`.
pub fn check_study(study: &Study) -> Result<CheckSummary, RunError> {
    check(&study.plan()?)
}

/// [`check_with`] of the plan of `study`.
pub fn check_study_with(study: &Study, progress: &dyn Fn(&str)) -> Result<CheckSummary, RunError> {
    check_with(&study.plan()?, progress)
}
