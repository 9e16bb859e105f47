//! Study files: the TOML as written ([`raw`], serde with unknown keys denied), validated into a
//! typed [`Study`] in SI units. Every error names the file, the key and the fix.
//!
//! Relative paths in a study file are relative to the study file's folder.

pub mod raw;

use crate::common::Direction;
use std::path::{Path, PathBuf};

/// An error in a study file: names the file, the key and the fix.
#[derive(Debug, thiserror::Error)]
#[error("{file}: {key}: {message}")]
pub struct StudyError {
    pub file: String,
    pub key: String,
    pub message: String,
}

/// Adherend damping (optional): C_b = alpha M + beta K_b, D_b = g K_b.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Damping {
    pub rayleigh_alpha_per_s: f64,
    pub rayleigh_beta_s: f64,
    pub structural_loss_factor: f64,
}

/// Mesh size: uniform element size or explicit divisions.
#[derive(Clone, Debug, PartialEq)]
pub enum MeshSize {
    ElementSize(f64),
    Divisions {
        x_adhesive: usize,
        x_outside: usize,
        y_beam: usize,
        y_adhesive: usize,
        z: usize,
    },
}

/// A measurement / excitation point on the beam surface.
#[derive(Clone, Debug, PartialEq)]
pub struct Point {
    pub id: u32,
    pub position_m: [f64; 3],
    pub direction: Direction,
    /// The point may have no channel in the measured data (`optional = true`); otherwise a
    /// point without data is an input error.
    pub optional: bool,
}

/// The bonded joint built by the mesher.
#[derive(Clone, Debug, PartialEq)]
pub struct Joint {
    pub beam_length_m: f64,
    pub beam_thickness_m: f64,
    pub beam_width_m: f64,
    pub beam_e_pa: f64,
    pub beam_nu: f64,
    pub beam_rho_kg_m3: f64,
    pub damping: Damping,
    pub adhesive_length_m: f64,
    pub adhesive_thickness_m: f64,
    pub adhesive_x_start_m: f64,
    pub adhesive_nu: f64,
    pub adhesive_rho_kg_m3: f64,
    pub mesh: MeshSize,
    /// true: 3x3x3 Gauss; false: 2x2x2 (ANSYS SOLID186 default).
    pub full_integration: bool,
    /// true: snap points to the nearest node; false: interpolate with shape functions.
    pub snap_points: bool,
    /// Growth ratio of a mesh graded towards the bond line's edges (`structure.mesh.grading_ratio`).
    pub mesh_grading: Option<f64>,
    /// How the mesh is chosen and what its remaining error does (`structure.mesh.refine`,
    /// `tolerance`, `allowance`).
    pub mesh_rule: MeshRule,
}

/// How a meshed joint's discretisation is chosen and what its remaining error does
/// (docs/method.md, "The mesh's discretisation error").
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MeshRule {
    /// Refine the mesh (grading towards the bond line's edges, halving the edge cells) until
    /// the estimated error of every in-band mode is below `tolerance`; false: the mesh as
    /// given (`divisions`, or `refine = false`).
    pub refine: bool,
    /// Largest estimated relative discretisation error of an in-band mode
    /// (`structure.mesh.tolerance`, default [`MeshRule::DEFAULT_TOLERANCE`]).
    pub tolerance: f64,
    /// The remaining estimated error enters the results (the adhesive's stiffness corrected by
    /// it and its uncertainty added to the intervals); false: the data were made on this very
    /// discretisation (a simulation), so the mesh is the truth's.
    pub allowance: bool,
    /// Storage modulus of the adhesive at which the modes of the estimate are computed
    /// (`structure.mesh.reference_modulus`, Pa; within a factor of a few of the adhesive's is
    /// enough).
    pub reference_modulus_pa: f64,
}

impl MeshRule {
    /// Default `structure.mesh.tolerance`: 0.5 % of each in-band mode's frequency. What is left
    /// of it is carried into the results, so the tolerance sets the cost of the mesh against
    /// the width it adds to the intervals (docs/method.md).
    pub const DEFAULT_TOLERANCE: f64 = 5e-3;
    /// Default `structure.mesh.reference_modulus` (Pa): a flexible polyurethane adhesive's
    /// storage modulus at tens of hertz (Sikaflex-252: 5-9 MPa).
    pub const DEFAULT_REFERENCE_MODULUS_PA: f64 = 5e6;
}

impl Default for MeshRule {
    fn default() -> Self {
        MeshRule {
            refine: true,
            tolerance: Self::DEFAULT_TOLERANCE,
            allowance: true,
            reference_modulus_pa: Self::DEFAULT_REFERENCE_MODULUS_PA,
        }
    }
}

/// Matrix files of an externally assembled model (Matrix Market, Harwell-Boeing or Abaqus,
/// see [`crate::fe::foreign`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Import {
    pub format: crate::fe::foreign::ImportFormat,
    pub mapping: Option<PathBuf>,
    pub units: crate::fe::foreign::Units,
    pub mass: PathBuf,
    pub stiffness: PathBuf,
    pub adhesive_sensitivity: PathBuf,
    pub viscous_damping: Option<PathBuf>,
    pub structural_damping: Option<PathBuf>,
    pub dof_map: PathBuf,
}

/// Where the structural model comes from.
#[derive(Clone, Debug, PartialEq)]
pub enum StructureSource {
    Mesher(Joint),
    /// A single-lap joint built by the mesher (`structure.joint = "single_lap"`); its points
    /// are the study's, added when the model is built.
    Lap(crate::fe::lap::LapSpec, MeshRule),
    MatrixMarket(Import),
}

/// The validated structure section.
#[derive(Clone, Debug, PartialEq)]
pub struct Structure {
    pub name: String,
    pub source: StructureSource,
    pub points: Vec<Point>,
    /// Id of the excitation point.
    pub excitation: u32,
}

/// One excitation level of the measurements.
#[derive(Clone, Debug, PartialEq)]
pub struct Level {
    pub name: String,
    pub files: Vec<PathBuf>,
    pub force_rms_n: Option<f64>,
}

/// The validated measurements section.
#[derive(Clone, Debug, PartialEq)]
pub struct Measurements {
    pub levels: Vec<Level>,
    pub band_hz: Option<(f64, f64)>,
    pub channels: Option<Vec<u32>>,
    /// The analyser's H1 estimator, when the study models its leakage.
    pub estimator: Option<Estimator>,
    /// Truth sidecar (JSON written by `rfmlab simulate`) of simulated data: the report then
    /// compares every identified modulus and parameter with the law that made the data.
    pub truth: Option<PathBuf>,
}

/// How the measured H1 was estimated (`[measurements.estimator]`): window, block length and
/// sampling rate, and optionally the shaker whose interaction colours the force spectrum.
/// With it, every identification fits the model's expected H1 (window-kernel average, see
/// [`crate::experiment::leakage_bias`]) instead of its exact FRF.
#[derive(Clone, Debug, PartialEq)]
pub struct Estimator {
    pub window: crate::experiment::Window,
    pub block_s: f64,
    pub fs_hz: f64,
    pub shaker: Option<crate::experiment::Shaker>,
    /// Band `(lo, hi]` (Hz) over which the force drives the structure (`force_band_hz`).
    /// `None`: a baseband random source, `(0, last data line]`: the analyser's source fills its
    /// span from DC (excluded) to the top line. The force below the first line and its
    /// negative-frequency mirror leak into the lowest lines, so this matters there.
    pub force_band_hz: Option<(f64, f64)>,
}

impl Estimator {
    /// The force band used with data whose lines span `data_band_hz`: the declared one, or
    /// `(0, data_band_hz.1]`.
    pub fn force_band(&self, data_band_hz: (f64, f64)) -> (f64, f64) {
        self.force_band_hz.unwrap_or((0.0, data_band_hz.1))
    }
}

/// A constitutive model to identify, with initial values in the model's parameter order (SI).
#[derive(Clone, Debug, PartialEq)]
pub struct ModelSpec {
    pub name: String,
    pub branches: Option<usize>,
    pub initial: Vec<f64>,
    pub param_names: Vec<String>,
    pub levels: Vec<String>,
}

/// Which FRF engine the identification uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Engine {
    Rom,
    Full,
}

/// Solver settings.
#[derive(Clone, Debug, PartialEq)]
pub struct Solver {
    pub engine: Engine,
    pub max_iterations: usize,
    pub tolerance: f64,
    pub svd_rtol: f64,
    pub rom_tolerance: f64,
    pub threads: Option<usize>,
}

impl Default for Solver {
    fn default() -> Self {
        Solver {
            engine: Engine::Rom,
            max_iterations: 100,
            tolerance: 1e-8,
            svd_rtol: 1e-10,
            rom_tolerance: 1e-6,
            threads: None,
        }
    }
}

/// A band around a resonance.
#[derive(Clone, Debug, PartialEq)]
pub struct Band {
    pub center_hz: f64,
    pub width_hz: f64,
}

/// Analyses to run.
#[derive(Clone, Debug, PartialEq)]
pub struct Analyses {
    pub band_constant: Vec<Band>,
    pub iem: Vec<Band>,
    pub per_line: bool,
    pub correlation: bool,
    pub sensitivity: bool,
    pub figures: bool,
    /// Estimate each low mode's discretisation error (Richardson, the mesh refined twice per
    /// direction) and put it in the results and the report.
    pub mesh_error: bool,
}

impl Default for Analyses {
    fn default() -> Self {
        Analyses {
            band_constant: Vec::new(),
            iem: Vec::new(),
            per_line: true,
            correlation: true,
            sensitivity: true,
            figures: true,
            mesh_error: false,
        }
    }
}

/// A validated study.
#[derive(Clone, Debug, PartialEq)]
pub struct Study {
    /// The study file.
    pub file: PathBuf,
    /// SHA-256 of the study file's bytes (hex).
    pub sha256: String,
    pub name: String,
    pub description: String,
    pub seed: u64,
    pub output_dir: PathBuf,
    pub structure: Structure,
    pub measurements: Option<Measurements>,
    pub models: Vec<ModelSpec>,
    pub solver: Solver,
    pub analyses: Analyses,
    /// The `[inference]` section, when the study asks for posteriors.
    pub inference: Option<inference::Inference>,
    /// Effects the study declares (`[[structure.effects]]`); every forward model carries them.
    pub declared_effects: Vec<effects::DeclaredEffect>,
    /// The `[closed_loop]` section, when given.
    pub closed_loop: Option<effects::ClosedLoopSettings>,
    /// The `[design]` section (`rfmlab design`), when given.
    pub design: Option<design::DesignSettings>,
}

mod ctx;
mod validate;
pub(crate) use validate::toml_error;

pub use validate::{load, parse_str};

impl Study {
    /// The point with the given id.
    pub fn point(&self, id: u32) -> Option<&Point> {
        self.structure.points.iter().find(|p| p.id == id)
    }
}

/// Resolve `p` relative to the folder of `file`.
pub(crate) fn resolve(file: &Path, p: &str) -> PathBuf {
    let pb = PathBuf::from(p);
    if pb.is_absolute() {
        pb
    } else {
        file.parent().unwrap_or(Path::new(".")).join(pb)
    }
}

pub mod build;
pub mod comparison;
pub mod design;
pub mod effects;
pub mod experiment;
pub mod inference;
pub mod lap;
pub mod material;
