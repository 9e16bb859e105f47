//! Constitutive models of the adhesive in the frequency domain: E*(w; p) = E'(w) + j E''(w)
//! with analytic Jacobians dE*/dp (method.md, "Constitutive models"; paper eq. 21-36).
//!
//! Parameters are in SI units (Pa, Pa s, ...); w is in rad/s.

use crate::common::C64;

/// A frequency-domain constitutive law of the adhesive.
pub trait ConstitutiveModel: Send + Sync + std::fmt::Debug {
    /// Short name, e.g. "model4".
    fn name(&self) -> &str;
    /// One-line description for reports, e.g. "SLS + structural damper: E0 + j h + j w eta1 E1/(E1 + j w eta1)".
    fn description(&self) -> String;
    /// Parameter names, e.g. ["E0", "h", "E1", "eta1"].
    fn param_names(&self) -> Vec<String>;
    /// SI unit of each parameter, e.g. ["Pa", "Pa", "Pa", "Pa s"].
    fn param_units(&self) -> Vec<String>;
    /// Number of parameters.
    fn n_params(&self) -> usize {
        self.param_names().len()
    }
    /// Admissible (open) range of each parameter, SI units.
    fn bounds(&self) -> Vec<(f64, f64)>;
    /// E*(w; p) in Pa.
    fn modulus(&self, p: &[f64], omega_rad_s: f64) -> C64;
    /// dE*/dp_k for k = 0..n_params, written into `out` (len n_params).
    fn jacobian(&self, p: &[f64], omega_rad_s: f64, out: &mut [C64]);
}

mod error;
mod models;
mod registry;

pub use error::MaterialError;
pub use models::{
    maxwell_branch, maxwell_branch_jacobian, FractionalZener, GeneralizedMaxwell, Model1, Model2,
    Model3, Model4, Model5,
};
pub use registry::{
    check_params, level2_model4_standin, model_from_name, paper_table4, try_paper_table4,
    MODEL_NAMES,
};
