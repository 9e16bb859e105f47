//! The study file as written: serde structs with unknown keys denied. Nothing here is
//! validated beyond TOML types; [`super::validate`] turns it into a [`super::Study`].

use serde::Deserialize;
use std::collections::BTreeMap;

#[derive(Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct RawStudy {
    #[serde(default)]
    pub study: RawMeta,
    pub structure: RawStructure,
    pub measurements: Option<RawMeasurements>,
    #[serde(default)]
    pub models: Vec<RawModel>,
    pub solver: Option<RawSolver>,
    pub analyses: Option<RawAnalyses>,
    /// Bayesian inference (see [`super::inference`]).
    pub inference: Option<super::inference::RawInference>,
    /// The closed loop (see [`super::effects`]).
    pub closed_loop: Option<super::effects::RawClosedLoop>,
    /// Test planning (see [`super::design`]).
    pub design: Option<super::design::RawDesign>,
}

#[derive(Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct RawMeta {
    pub name: Option<String>,
    pub description: Option<String>,
    pub seed: Option<u64>,
    /// Output folder (default `results/<name>`), relative to the current directory.
    pub output_dir: Option<String>,
}

#[derive(Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct RawStructure {
    pub name: Option<String>,
    /// Build the model with the mesher (default) or import matrix files: "matrix_market",
    /// "harwell_boeing" or "abaqus".
    pub source: Option<String>,
    /// The meshed joint's kind: "beam_on_block" (default) or "single_lap" (with [structure.lap]).
    pub joint: Option<String>,
    /// The single-lap joint (joint = "single_lap").
    pub lap: Option<RawLap>,
    pub beam: Option<RawBeam>,
    pub adhesive: Option<RawAdhesive>,
    pub mesh: Option<RawMesh>,
    #[serde(default)]
    pub points: Vec<RawPoint>,
    /// Id of the excitation point (one of `points`).
    pub excitation: Option<u32>,
    /// Imported model (source = "matrix_market", "harwell_boeing" or "abaqus").
    pub import: Option<RawImport>,
    /// Declared effects (see [`super::effects`]).
    #[serde(default)]
    pub effects: Vec<super::effects::RawEffect>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawBeam {
    pub length: f64,
    pub thickness: f64,
    pub width: f64,
    pub material: RawMaterial,
    pub damping: Option<RawDamping>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawMaterial {
    #[serde(rename = "E")]
    pub e: f64,
    pub nu: f64,
    pub rho: f64,
}

#[derive(Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct RawDamping {
    pub rayleigh_alpha: Option<f64>,
    pub rayleigh_beta: Option<f64>,
    pub structural: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawAdhesive {
    pub length: f64,
    pub thickness: f64,
    pub x_start: Option<f64>,
    pub nu: f64,
    pub rho: f64,
}

#[derive(Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct RawMesh {
    pub element_size: Option<f64>,
    pub divisions: Option<RawDivisions>,
    /// "full" (3x3x3 Gauss) or "reduced" (2x2x2, ANSYS SOLID186 default).
    pub integration: Option<String>,
    /// "interpolate" (default) or "snap".
    pub point_mapping: Option<String>,
    /// Growth ratio of a mesh graded towards the bond line's edges.
    pub grading_ratio: Option<f64>,
    /// Largest estimated discretisation error of an in-band mode (relative).
    pub tolerance: Option<f64>,
    /// Refine the mesh until the tolerance is met (default with an element size).
    pub refine: Option<bool>,
    /// The remaining discretisation error enters the results (default true).
    pub allowance: Option<bool>,
    /// Storage modulus of the adhesive for the estimate's modes (Pa).
    pub reference_modulus: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawDivisions {
    pub x_adhesive: usize,
    pub x_outside: usize,
    pub y_beam: usize,
    pub y_adhesive: usize,
    pub z: usize,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawPoint {
    pub id: u32,
    pub position: Vec<f64>,
    pub direction: String,
    /// The point may have no channel in the data (default false: a point without data stops
    /// the run).
    pub optional: Option<bool>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawImport {
    pub mass: String,
    pub stiffness: String,
    pub adhesive_sensitivity: String,
    pub viscous_damping: Option<String>,
    pub structural_damping: Option<String>,
    pub dof_map: String,
    /// ANSYS equation-mapping file (Harwell-Boeing): the DOF map may then name nodes.
    pub mapping: Option<String>,
    /// "SI" (default) or "mm-t-s".
    pub units: Option<String>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawMeasurements {
    pub levels: Vec<RawLevel>,
    /// Band used for identification (Hz), default: the whole grid.
    pub band_hz: Option<Vec<f64>>,
    /// Response point ids to use (default: all measured at the study's points).
    pub channels: Option<Vec<u32>>,
    /// How the analyser estimated H1 (optional): the identification then models its leakage.
    pub estimator: Option<RawEstimator>,
    /// Truth sidecar of simulated data (`rfmlab simulate`), for the report's truth columns.
    pub truth: Option<String>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawEstimator {
    pub window: String,
    pub block_s: f64,
    pub fs_hz: Option<f64>,
    pub shaker: Option<RawEstimatorShaker>,
    /// Band `[lo, hi]` (Hz) the force drives, `(lo, hi]`; default `[0, last data line]`.
    pub force_band_hz: Option<Vec<f64>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawEstimatorShaker {
    pub armature_mass: f64,
    pub stinger_stiffness: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawLevel {
    pub name: String,
    pub files: Vec<String>,
    pub force_rms_n: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawModel {
    /// "model1".."model5", "fractional_zener", "generalized_maxwell".
    pub name: String,
    /// Number of branches (generalized Maxwell only).
    pub branches: Option<usize>,
    /// Initial values by parameter name (SI units), optionally per level:
    /// `initial = { E0 = 6e6, ... }`.
    pub initial: BTreeMap<String, f64>,
    /// Levels to identify this model at (default: all).
    pub levels: Option<Vec<String>>,
}

#[derive(Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct RawSolver {
    /// "rom" (default) or "full".
    pub engine: Option<String>,
    pub max_iterations: Option<usize>,
    pub tolerance: Option<f64>,
    pub svd_rtol: Option<f64>,
    pub rom_tolerance: Option<f64>,
    pub threads: Option<usize>,
}

#[derive(Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct RawAnalyses {
    /// Constant modulus (Model 1) over bands around resonances (case study 1).
    #[serde(default)]
    pub band_constant: Vec<RawBand>,
    /// Circle fit + IEM around resonances.
    #[serde(default)]
    pub iem: Vec<RawBand>,
    /// Per-line nonparametric RFM estimate of E*(w).
    pub per_line: Option<bool>,
    /// FRAC/SCC/ACC and sensitivities.
    pub correlation: Option<bool>,
    pub sensitivity: Option<bool>,
    pub figures: Option<bool>,
    /// The mesh's discretisation error per mode in the results and the report.
    pub mesh_error: Option<bool>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawBand {
    pub center_hz: f64,
    pub width_hz: Option<f64>,
}

/// `[structure.lap]` (validated by [`super::lap`]).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawLap {
    pub length: f64,
    pub thickness: f64,
    pub thickness_upper: Option<f64>,
    pub width: f64,
    pub overlap: f64,
    pub support: Option<String>,
    pub material: RawMaterial,
    pub adhesive: RawLapAdhesive,
    pub damping: Option<RawDamping>,
    pub mesh: Option<RawLapMesh>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawLapAdhesive {
    pub thickness: f64,
    pub nu: f64,
    pub rho: f64,
}

#[derive(Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct RawLapMesh {
    pub element_size: Option<f64>,
    /// Refine the bond line until the tolerance is met (default true).
    pub refine: Option<bool>,
    /// Largest estimated discretisation error of an in-band mode (relative).
    pub tolerance: Option<f64>,
    /// The remaining discretisation error enters the results (default true).
    pub allowance: Option<bool>,
    /// Storage modulus of the adhesive for the estimate's modes (Pa).
    pub reference_modulus: Option<f64>,
    pub y_adhesive: Option<usize>,
    pub y_strip: Option<usize>,
    pub z: Option<usize>,
    pub end_aspect: Option<f64>,
    pub max_aspect: Option<f64>,
    pub grading_ratio: Option<f64>,
    pub integration: Option<String>,
    pub point_mapping: Option<String>,
}
