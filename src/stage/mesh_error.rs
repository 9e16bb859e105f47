//! The mesh's remaining discretisation error per mode, as `rfmlab check`, `run` and the
//! report show it. The estimate and the refinement are [`crate::discretisation`]'s: a joint
//! meshed with an element size is refined to `structure.mesh.tolerance` and carries its
//! estimate in [`BuiltModel::discretisation`]; a fixed mesh (`divisions`, `refine = false`) is
//! compared with itself refined twice per direction, unless the study declares that its data
//! were made on this very mesh (`allowance = false`), when no estimate is made unless
//! `[analyses] mesh_error` asks for one.

use super::data::first_peak_hz;
use super::{input_error, LevelData, RunError};
use crate::discretisation::Discretisation;
use crate::study::build::BuiltModel;
use crate::study::{ModelSpec, Structure};
use std::path::Path;

/// One mode's discretisation error estimate.
pub type ModeDiscretisation = crate::discretisation::ModeError;

/// Relative frequency error above which a fixed mesh without allowance is flagged: the
/// frequency uncertainty of a posterior from such data is typically 1e-4-1e-3 of the
/// frequency (a 3 % mesh error pushed Model 4's parameters 13-20 % off and outside their
/// intervals).
pub const MESH_ERROR_WARN_REL: f64 = 1e-3;

/// Largest refined mesh (free DOFs) the estimate of a fixed mesh solves.
pub const MAX_REFINED_DOFS: usize = 400_000;

/// The estimate of a fixed mesh without allowance (`[analyses] mesh_error`), at the first
/// model's initial storage modulus at the first level's first peak (20 Hz without data peaks).
pub fn mesh_error_at_initial_values(
    models: &[ModelSpec],
    structure: &Structure,
    file: &Path,
    built: &BuiltModel,
    levels: &[LevelData],
    laws: &[Box<dyn crate::material::ConstitutiveModel>],
) -> Result<Option<Discretisation>, RunError> {
    if let Some(d) = &built.discretisation {
        return Ok(Some(d.clone()));
    }
    let (Some(m), Some(law)) = (models.first(), laws.first()) else {
        return Ok(None);
    };
    let Some(spec) = crate::study::build::joint_spec(structure) else {
        return Ok(None);
    };
    let f = levels.first().and_then(first_peak_hz).unwrap_or(20.0);
    let e = law.modulus(&m.initial, std::f64::consts::TAU * f).re;
    let refined_dofs = 8 * built.model.n_dof();
    if refined_dofs > MAX_REFINED_DOFS {
        return Err(RunError::Analysis {
            analysis: "the discretisation-error estimate".into(),
            message: format!(
                "the mesh refined twice per direction would have about {refined_dofs} DOFs, more than the {MAX_REFINED_DOFS} it solves: compare two meshes with `rfmlab convergence` instead"
            ),
        });
    }
    let p = crate::discretisation::RefineParams {
        tolerance: MESH_ERROR_WARN_REL,
        allowance: false,
        reference_modulus_pa: e,
    };
    crate::discretisation::fixed(&spec, &built.model, &p)
        .map(Some)
        .map_err(|e| input_error(file, e.key().to_string(), e.detail()))
}

/// The warnings of a discretisation record: a mesh short of its tolerance, a fixed mesh's
/// error, and what the results do with it.
pub fn mesh_error_warnings(d: Option<&Discretisation>) -> Vec<String> {
    let Some(d) = d else {
        return Vec::new();
    };
    let mut out = Vec::new();
    let worst = d.worst_rel_error();
    if d.allowance && !d.reached {
        out.push(format!(
            "structure.mesh: the mesh's estimated discretisation error ({:.2} % at worst) is above the tolerance ({:.2} %){}; the posteriors carry it (the law's parameters moved and widened by the per-mode errors), the deterministic fits do not",
            100.0 * worst,
            100.0 * d.tolerance,
            if d.note.is_empty() { String::new() } else { format!(" ({})", d.note) },
        ));
    } else if !d.allowance && worst > d.tolerance.max(MESH_ERROR_WARN_REL) {
        for m in d
            .modes
            .iter()
            .filter(|m| m.rel_error.abs() > d.tolerance.max(MESH_ERROR_WARN_REL))
        {
            out.push(format!(
                "structure.mesh: mode {} ({:.3} Hz) has an estimated discretisation error of {:+.3} Hz ({:+.2} %), more than the {:.2} % such data resolve, and the results do not include it (allowance = false): refine the mesh (drop divisions and refine = false), or keep allowance = true",
                m.mode,
                m.freq_hz,
                m.error_hz,
                100.0 * m.rel_error,
                100.0 * d.tolerance.max(MESH_ERROR_WARN_REL)
            ));
        }
    }
    out
}

/// One line per mesh and per mode of a discretisation record, for the console.
pub fn describe(d: &Discretisation) -> Vec<String> {
    let mut out = Vec::new();
    let chosen = d.levels.get(d.chosen);
    out.push(match (d.rule.as_str(), chosen) {
        ("refined", Some(l)) => format!(
            "mesh: refined to level {} (edge cells {:.3} mm, {} DOFs); estimated error at worst {:.3} %, tolerance {:.3} %{}",
            l.level,
            1e3 * l.edge_m,
            l.n_dof,
            100.0 * d.worst_rel_error(),
            100.0 * d.tolerance,
            if d.reached { "" } else { " (not reached)" }
        ),
        _ => format!(
            "mesh: fixed; estimated error at worst {:.3} % (the mesh refined twice per direction, order {})",
            100.0 * d.worst_rel_error(),
            crate::discretisation::ORDER
        ),
    });
    for m in &d.modes {
        out.push(format!(
            "  mode {:>2} {:>10.4} Hz  error {:+.2e} Hz ({:+.4} %)  observed order {:.2}  adhesive share {:.3}",
            m.mode,
            m.freq_hz,
            m.error_hz,
            100.0 * m.rel_error,
            m.order,
            m.adhesive_share
        ));
    }
    if d.allowance {
        out.push(format!(
            "  allowance: the adhesive's stiffness on this mesh exceeds the continuum's by about {:+.3} % (sd {:.3} %){}; the posteriors carry the per-mode errors",
            100.0 * d.stiffness_excess,
            100.0 * d.stiffness_excess_sd,
            d.adherends_clause()
        ));
    }
    out
}
