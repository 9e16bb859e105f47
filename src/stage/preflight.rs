//! The pre-flight of `rfmlab check` beyond loading the study and its data: at least one
//! model, a writable output folder, the analysis bands against the data's lines, the
//! structure's points against the data's channels, the model's first mode at the initial
//! values against the data's first peak, the cost of the engine, and the mesh's remaining
//! discretisation error per mode.
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

use super::{input_error, LevelData, RunError};
use crate::common::C64;
use crate::identify::IdentificationParams;
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
/// The model's first mode and the data's first peak are "far apart" beyond this ratio.
pub const FIRST_MODE_RATIO_WARN: f64 = 1.5;
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

/// The engine's estimated cost.
#[derive(Clone, Debug, serde::Serialize)]
pub struct CostSummary {
    pub n_dof: usize,
    pub memory_bytes: f64,
    pub factor_seconds: f64,
    pub available_memory_bytes: f64,
}

/// What the pre-flight found besides hard errors.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct Preflight {
    pub warnings: Vec<String>,
    pub cost: Option<CostSummary>,
    /// Per mode: the mesh's discretisation error (meshed structures only).
    pub discretisation: Vec<ModeDiscretisation>,
    /// The model's first y mode at the initial values and the data's first peak (Hz).
    pub first_mode_hz: Option<f64>,
    pub first_peak_hz: Option<f64>,
}

/// Checks that need no model: at least one model, a writable output folder.
pub fn check_settings(
    models: &[ModelSpec],
    output_dir: &Path,
    file: &Path,
) -> Result<(), RunError> {
    if models.is_empty() {
        return Err(input_error(
            file,
            "models",
            "no [[models]] to identify: add at least one, e.g. [[models]] name = \"model1\" with [models.initial] E0 and h",
        ));
    }
    let dir = output_dir;
    let parent = dir
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(std::path::Path::new("."));
    let probe = parent.join(format!(".rfmlab-write-check-{}", std::process::id()));
    let ok = std::fs::create_dir_all(parent)
        .and_then(|_| std::fs::write(&probe, b"check"))
        .and_then(|_| std::fs::remove_file(&probe));
    if let Err(e) = ok {
        return Err(input_error(
            file,
            "study.output_dir",
            format!(
                "the results folder {} cannot be written ({e}): choose a folder you can write to",
                dir.display()
            ),
        ));
    }
    Ok(())
}

/// The analysis bands against each level's lines: an error when a band holds no line of a
/// level, a warning when it reaches beyond the data.
pub fn check_bands(
    params: &IdentificationParams,
    file: &Path,
    levels: &[LevelData],
    warnings: &mut Vec<String>,
) -> Result<(), RunError> {
    let bands = params
        .band_constant
        .iter()
        .enumerate()
        .map(|(i, b)| (format!("analyses.band_constant[{i}]"), b))
        .chain(
            params
                .iem
                .iter()
                .enumerate()
                .map(|(i, b)| (format!("analyses.iem[{i}]"), b)),
        );
    for (key, b) in bands {
        let (lo, hi) = (
            b.center_hz - 0.5 * b.width_hz,
            b.center_hz + 0.5 * b.width_hz,
        );
        for level in levels {
            let (f0, f1) = match (level.freq_hz.first(), level.freq_hz.last()) {
                (Some(&a), Some(&z)) => (a, z),
                _ => continue,
            };
            let inside = level
                .freq_hz
                .iter()
                .filter(|&&f| f >= lo && f <= hi)
                .count();
            if inside == 0 {
                return Err(input_error(
                    file,
                    key,
                    format!(
                        "the band {lo}-{hi} Hz holds no line of level {} (its data cover {f0}-{f1} Hz within measurements.band_hz): move center_hz inside the data",
                        level.name
                    ),
                ));
            }
            if lo < f0 || hi > f1 {
                warnings.push(format!(
                    "{key}: the band {lo}-{hi} Hz reaches beyond level {}'s data ({f0}-{f1} Hz); only its {inside} line(s) inside are used",
                    level.name
                ));
            }
        }
    }
    Ok(())
}

/// The structure's points against each level's channels: a warning listing what the files
/// hold when a point has no channel.
pub fn check_channels(built: &BuiltModel, levels: &[LevelData], warnings: &mut Vec<String>) {
    for level in levels {
        let missing: Vec<u32> = built
            .model
            .points
            .iter()
            .map(|p| p.id)
            .filter(|id| !level.response_ids.contains(id))
            .collect();
        if !missing.is_empty() {
            warnings.push(format!(
                "structure.points: point(s) {missing:?} have no channel in level {}'s files, which hold responses {:?} to the excitation at point {}; they are not used",
                level.name, level.response_ids, level.reference_id
            ));
        }
    }
}

/// Lines of the lowest clear peak of the summed magnitude (a local maximum above a tenth of
/// the largest), in Hz.
pub fn first_peak_hz(level: &LevelData) -> Option<f64> {
    let n_out = level.column.outputs.len().max(1);
    let mag: Vec<f64> = (0..level.freq_hz.len())
        .map(|l| {
            (0..n_out)
                .map(|k| level.column.accelerance[l * n_out + k].norm())
                .sum::<f64>()
        })
        .collect();
    let top = mag.iter().cloned().fold(0.0, f64::max);
    if !(top > 0.0) || mag.len() < 3 {
        return None;
    }
    (1..mag.len() - 1)
        .find(|&l| mag[l] >= mag[l - 1] && mag[l] > mag[l + 1] && mag[l] > 0.1 * top)
        .map(|l| level.freq_hz[l])
}

/// The first model's first y-dominant mode at its initial values (modulus at the data's
/// first peak) against that peak: a warning when they are more than a factor
/// [`FIRST_MODE_RATIO_WARN`] apart.
pub fn check_first_mode(
    models: &[ModelSpec],
    built: &BuiltModel,
    levels: &[LevelData],
    laws: &[Box<dyn crate::material::ConstitutiveModel>],
    out: &mut Preflight,
) -> Result<(), RunError> {
    let (Some(level), Some(spec), Some(law)) = (levels.first(), models.first(), laws.first())
    else {
        return Ok(());
    };
    let Some(peak) = first_peak_hz(level) else {
        return Ok(());
    };
    let e: C64 = law.modulus(&spec.initial, std::f64::consts::TAU * peak);
    let modes = crate::modes::complex_modes(
        &built.model,
        e,
        N_MODES_CHECKED,
        built.dof_axes.as_deref(),
        &crate::modes::ModesParams::default(),
    )
    .map_err(|err| RunError::Engine(format!("the model's modes at the initial values: {err}")))?;
    let first = modes
        .iter()
        .find(|m| m.y_dominant.unwrap_or(true))
        .map(|m| m.freq_hz);
    out.first_peak_hz = Some(peak);
    out.first_mode_hz = first;
    if let Some(f) = first {
        let r = f / peak;
        if !(1.0 / FIRST_MODE_RATIO_WARN..=FIRST_MODE_RATIO_WARN).contains(&r) {
            out.warnings.push(format!(
                "the model's first y mode at {}'s initial values is at {f:.2} Hz but level {}'s first peak is at {peak:.2} Hz: check [structure] (the data may belong to another joint) and models[0].initial",
                spec.name, level.name
            ));
        }
    }
    Ok(())
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
