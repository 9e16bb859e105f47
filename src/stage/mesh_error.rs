//! The mesh's remaining discretisation error per mode, estimated before a run (`rfmlab check`,
//! `analyses.mesh_error`).
//!
//! Discretisation error (Richardson extrapolation): with f_h the frequency of a mode on the
//! study's mesh and f_{h/2} on the same mesh with every cell split in two per direction, and
//! an error that falls as h^p, f = f_{h/2} + (f_{h/2} - f_h) / (2^p - 1), so the study mesh's
//! error is e_h = f_h - f = (f_h - f_{h/2}) 2^p / (2^p - 1). The order p depends on whether the
//! mesh resolves the bond line's edge layers, whose width is about the layer's thickness t_a:
//! - cells no larger than t_a in the bond line's plane ([`RICHARDSON_ORDER`], p = 2): the
//!   paper's 10 mm block under 5 mm cells converges so (10 -> 5 -> 2.5 mm: 23.63, 22.14,
//!   21.80 Hz, an observed p of 2.1);
//! - cells larger than t_a ([`RICHARDSON_ORDER_THIN`], p = 1): a 3 mm bond line under 5 mm
//!   cells (a 400 x 8 x 25 mm beam) converges more slowly. An independent graded 27-node model
//!   of that joint, extrapolated, puts its first mode 1.8 % below the 5 mm mesh's; p = 2 would
//!   have estimated 0.9 %, p = 1 estimates 1.4 %.
//!
//! Both remain estimates from two meshes; `check` warns when they exceed what the data resolve.
//! The modes are those of the real pencil (K_b + E' S, M) at the first model's initial storage
//! modulus, paired in order.

use super::data::first_peak_hz;
use super::{input_error, LevelData, RunError};
use crate::study::build::BuiltModel;
use crate::study::{ModelSpec, Structure};
use std::path::Path;

/// Order of convergence assumed by the Richardson estimate when the mesh's cells are no
/// larger than the bond line's thickness in its plane (see the module doc).
pub const RICHARDSON_ORDER: f64 = 2.0;
/// Order assumed when the cells are larger than the bond line's thickness (a thin bond line
/// under a coarser mesh; see the module doc).
pub const RICHARDSON_ORDER_THIN: f64 = 1.0;

/// The Richardson order for a bond line `adhesive_thickness_m` thick under cells at most
/// `cell_m` long in its plane (module doc).
pub fn richardson_order(adhesive_thickness_m: f64, cell_m: f64) -> f64 {
    if cell_m > adhesive_thickness_m * (1.0 + 1e-9) {
        RICHARDSON_ORDER_THIN
    } else {
        RICHARDSON_ORDER
    }
}

/// Relative frequency error above which `check` warns that the mesh limits what the data can
/// say: the frequency uncertainty of a posterior from such data is typically 1e-4-1e-3 of
/// the frequency (a 3 % mesh error pushed Model 4's parameters 13-20 % off and outside their
/// intervals), so the mesh must be well below it.
pub const MESH_ERROR_WARN_REL: f64 = 1e-3;

/// Modes in the discretisation-error table.
pub const N_MODES_CHECKED: usize = 6;
/// Largest refined mesh (free DOFs) the discretisation-error estimate solves; beyond it the
/// estimate is left out with a message (a graded mesh refined twice per direction can reach
/// a million DOFs and minutes of work).
pub const MAX_REFINED_DOFS: usize = 400_000;

/// One mode's discretisation error estimate.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ModeDiscretisation {
    /// Mode number (1 = lowest).
    pub mode: usize,
    /// Frequency on the study's mesh (Hz).
    pub freq_hz: f64,
    /// On the mesh refined twice per direction (Hz).
    pub freq_refined_hz: f64,
    /// Estimated error of the study mesh's frequency, f_h - f (Hz).
    pub error_hz: f64,
    /// error_hz / freq_hz.
    pub rel_error: f64,
    /// The convergence order p the estimate assumed (module doc).
    pub order: f64,
}

/// [`discretisation_errors`] at the first model's initial storage modulus at the first level's
/// first peak (20 Hz without data peaks).
pub fn mesh_error_at_initial_values(
    models: &[ModelSpec],
    structure: &Structure,
    file: &Path,
    built: &BuiltModel,
    levels: &[LevelData],
    laws: &[Box<dyn crate::material::ConstitutiveModel>],
) -> Result<Vec<ModeDiscretisation>, RunError> {
    let (Some(m), Some(law)) = (models.first(), laws.first()) else {
        return Ok(Vec::new());
    };
    let f = levels.first().and_then(first_peak_hz).unwrap_or(20.0);
    let e = law.modulus(&m.initial, std::f64::consts::TAU * f).re;
    discretisation_errors(structure, file, built, e)
}

/// One warning per mode whose estimated error exceeds [`MESH_ERROR_WARN_REL`].
pub fn mesh_error_warnings(modes: &[ModeDiscretisation]) -> Vec<String> {
    modes
        .iter()
        .filter(|d| d.rel_error.abs() > MESH_ERROR_WARN_REL)
        .map(|d| {
            format!(
                "structure.mesh: mode {} ({:.3} Hz) has an estimated discretisation error of {:+.3} Hz ({:+.2} %), more than the {:.2} % such data resolve, and the posterior's intervals do not include it: refine the mesh (a smaller element_size, or more divisions)",
                d.mode,
                d.freq_hz,
                d.error_hz,
                100.0 * d.rel_error,
                100.0 * MESH_ERROR_WARN_REL
            )
        })
        .collect()
}

/// Richardson estimate of each of the lowest modes' discretisation error on the study's
/// mesh (module doc), at the storage modulus `e_storage_pa`.
pub fn discretisation_errors(
    structure: &Structure,
    file: &Path,
    built: &BuiltModel,
    e_storage_pa: f64,
) -> Result<Vec<ModeDiscretisation>, RunError> {
    let Some(spec) = crate::study::build::joint_spec(structure) else {
        return Ok(Vec::new());
    };
    let fail = |message: String| RunError::Analysis {
        analysis: "the discretisation-error estimate".into(),
        message,
    };
    // the refined mesh has about 8 times the study mesh's DOFs
    let refined_dofs = 8 * built.model.n_dof();
    if refined_dofs > MAX_REFINED_DOFS {
        return Err(fail(format!(
            "the mesh refined twice per direction would have about {refined_dofs} DOFs, more than the {MAX_REFINED_DOFS} it solves: compare two meshes with `rfmlab convergence` instead"
        )));
    }
    let (fine, _) = crate::fe::joint::build_joint_model_refined(&spec, 2)
        .map_err(|e| input_error(file, e.key().to_string(), e.detail()))?;
    let n = N_MODES_CHECKED.min(built.model.n_dof() / 3).max(1);
    // the frequencies converge as the square of the residual: 1e-6 gives them to ~1e-12
    let params = crate::modes::EigenParams {
        tol: 1e-6,
        ..crate::modes::EigenParams::default()
    };
    let freqs = |m: &crate::fe::StructuralModel| -> Result<Vec<f64>, RunError> {
        let k = crate::modes::real::sp_add(&m.k_b, &m.s, e_storage_pa)
            .map_err(|e| fail(e.to_string()))?;
        let (lam, _) =
            crate::modes::real_modes(&k, &m.m, n, &params).map_err(|e| fail(e.to_string()))?;
        Ok(lam
            .iter()
            .map(|l| l.max(0.0).sqrt() / std::f64::consts::TAU)
            .collect())
    };
    let coarse = freqs(&built.model)?;
    let refined = freqs(&fine)?;
    let cell = built
        .mesh
        .as_ref()
        .map_or(0.0, |m| m.element_size_m[0].max(m.element_size_m[2]));
    let order = richardson_order(spec.geometry.adhesive_thickness_m, cell);
    let g = 2f64.powf(order);
    Ok(coarse
        .iter()
        .zip(&refined)
        .enumerate()
        .map(|(i, (&fh, &ff))| {
            let err = (fh - ff) * g / (g - 1.0);
            ModeDiscretisation {
                mode: i + 1,
                freq_hz: fh,
                freq_refined_hz: ff,
                error_hz: err,
                rel_error: err / fh,
                order,
            }
        })
        .collect())
}
