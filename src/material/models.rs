//! The constitutive models: the paper's Models 1-5 (eq. 21, 25, 27, 33, 35), a fractional
//! Zener law and a generalized Maxwell series, each with its analytic Jacobian dE*/dp.
//!
//! Conventions: time dependence e^{j w t}, so a positive loss modulus E'' > 0 dissipates
//! energy for w > 0. All formulas are written for w >= 0 (the rational models are also
//! evaluated as written for w < 0). Parameters are SI: Pa, Pa s, s, dimensionless.

use super::ConstitutiveModel;
use crate::common::{C64, J};

const POS: (f64, f64) = (0.0, f64::INFINITY);

const NAN: C64 = C64::new(f64::NAN, f64::NAN);

/// True (and `out` filled with NaN) when `p` or `out` is shorter than `n`: the models never
/// panic on a short vector, they return NaN (callers validate with `check_params`).
fn short(p: &[f64], n: usize, out: Option<&mut [C64]>) -> bool {
    match out {
        Some(o) if p.len() < n || o.len() < n => {
            o.iter_mut().for_each(|v| *v = NAN);
            true
        }
        _ => p.len() < n,
    }
}

fn strings(v: &[&str]) -> Vec<String> {
    v.iter().map(|s| s.to_string()).collect()
}

/// The Maxwell branch (spring E1 in series with dashpot eta1) of the SLS, paper eq. 27:
/// M(w) = j w eta1 E1 / (E1 + j w eta1).
///
/// Its real and imaginary parts are paper eq. 28 (minus E0):
/// Re M = w^2 E1 eta1^2 / D, Im M = w E1^2 eta1 / D with D = E1^2 + w^2 eta1^2.
pub fn maxwell_branch(e1_pa: f64, eta1_pa_s: f64, omega_rad_s: f64) -> C64 {
    let jwe = J * (omega_rad_s * eta1_pa_s);
    jwe * e1_pa / (e1_pa + jwe)
}

/// Partial derivatives (dM/dE1, dM/deta1) of [`maxwell_branch`]:
/// dM/dE1 = (j w eta1)^2 / (E1 + j w eta1)^2, dM/deta1 = j w E1^2 / (E1 + j w eta1)^2.
///
/// Their real and imaginary parts are the entries of the paper's eq. 32 (checked in
/// tests/material.rs).
pub fn maxwell_branch_jacobian(e1_pa: f64, eta1_pa_s: f64, omega_rad_s: f64) -> (C64, C64) {
    let jwe = J * (omega_rad_s * eta1_pa_s);
    let den = e1_pa + jwe;
    let den2 = den * den;
    (jwe * jwe / den2, J * (omega_rad_s * e1_pa * e1_pa) / den2)
}

/// Model 1, spring + structural damper (paper eq. 21): E* = E0 + j h.
/// Parameters [E0 (Pa), h (Pa)].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Model1;

impl ConstitutiveModel for Model1 {
    fn name(&self) -> &str {
        "model1"
    }
    fn description(&self) -> String {
        "Model 1, spring + structural damper: E* = E0 + j h".into()
    }
    fn param_names(&self) -> Vec<String> {
        strings(&["E0", "h"])
    }
    fn param_units(&self) -> Vec<String> {
        strings(&["Pa", "Pa"])
    }
    fn n_params(&self) -> usize {
        2
    }
    fn bounds(&self) -> Vec<(f64, f64)> {
        vec![POS; 2]
    }
    fn modulus(&self, p: &[f64], _omega_rad_s: f64) -> C64 {
        if short(p, 2, None) {
            return NAN;
        }
        C64::new(p[0], p[1])
    }
    fn jacobian(&self, p: &[f64], _omega_rad_s: f64, out: &mut [C64]) {
        if short(p, 2, Some(out)) {
            return;
        }
        out[0] = C64::new(1.0, 0.0);
        out[1] = J;
    }
}

/// Model 2, Kelvin-Voigt (paper eq. 25): E* = E0 + j w eta0.
/// Parameters [E0 (Pa), eta0 (Pa s)].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Model2;

impl ConstitutiveModel for Model2 {
    fn name(&self) -> &str {
        "model2"
    }
    fn description(&self) -> String {
        "Model 2, Kelvin-Voigt: E* = E0 + j w eta0".into()
    }
    fn param_names(&self) -> Vec<String> {
        strings(&["E0", "eta0"])
    }
    fn param_units(&self) -> Vec<String> {
        strings(&["Pa", "Pa s"])
    }
    fn n_params(&self) -> usize {
        2
    }
    fn bounds(&self) -> Vec<(f64, f64)> {
        vec![POS; 2]
    }
    fn modulus(&self, p: &[f64], omega_rad_s: f64) -> C64 {
        if short(p, 2, None) {
            return NAN;
        }
        C64::new(p[0], omega_rad_s * p[1])
    }
    fn jacobian(&self, p: &[f64], omega_rad_s: f64, out: &mut [C64]) {
        if short(p, 2, Some(out)) {
            return;
        }
        out[0] = C64::new(1.0, 0.0);
        out[1] = C64::new(0.0, omega_rad_s);
    }
}

/// Model 3, standard linear solid (paper eq. 27): E* = E0 + j w eta1 E1 / (E1 + j w eta1).
/// Parameters [E0 (Pa), E1 (Pa), eta1 (Pa s)]. Limits: E*(0) = E0, E*(inf) = E0 + E1.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Model3;

impl ConstitutiveModel for Model3 {
    fn name(&self) -> &str {
        "model3"
    }
    fn description(&self) -> String {
        "Model 3, standard linear solid: E* = E0 + j w eta1 E1 / (E1 + j w eta1)".into()
    }
    fn param_names(&self) -> Vec<String> {
        strings(&["E0", "E1", "eta1"])
    }
    fn param_units(&self) -> Vec<String> {
        strings(&["Pa", "Pa", "Pa s"])
    }
    fn n_params(&self) -> usize {
        3
    }
    fn bounds(&self) -> Vec<(f64, f64)> {
        vec![POS; 3]
    }
    fn modulus(&self, p: &[f64], omega_rad_s: f64) -> C64 {
        if short(p, 3, None) {
            return NAN;
        }
        p[0] + maxwell_branch(p[1], p[2], omega_rad_s)
    }
    fn jacobian(&self, p: &[f64], omega_rad_s: f64, out: &mut [C64]) {
        if short(p, 3, Some(out)) {
            return;
        }
        let (d_e1, d_eta1) = maxwell_branch_jacobian(p[1], p[2], omega_rad_s);
        out[0] = C64::new(1.0, 0.0);
        out[1] = d_e1;
        out[2] = d_eta1;
    }
}

/// Model 4, SLS + structural damper (paper eq. 33):
/// E* = E0 + j h + j w eta1 E1 / (E1 + j w eta1).
/// Parameters in the paper's eq. 34 order: [E0 (Pa), h (Pa), E1 (Pa), eta1 (Pa s)].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Model4;

impl ConstitutiveModel for Model4 {
    fn name(&self) -> &str {
        "model4"
    }
    fn description(&self) -> String {
        "Model 4, SLS + structural damper: E* = E0 + j h + j w eta1 E1 / (E1 + j w eta1)".into()
    }
    fn param_names(&self) -> Vec<String> {
        strings(&["E0", "h", "E1", "eta1"])
    }
    fn param_units(&self) -> Vec<String> {
        strings(&["Pa", "Pa", "Pa", "Pa s"])
    }
    fn n_params(&self) -> usize {
        4
    }
    fn bounds(&self) -> Vec<(f64, f64)> {
        vec![POS; 4]
    }
    fn modulus(&self, p: &[f64], omega_rad_s: f64) -> C64 {
        if short(p, 4, None) {
            return NAN;
        }
        C64::new(p[0], p[1]) + maxwell_branch(p[2], p[3], omega_rad_s)
    }
    fn jacobian(&self, p: &[f64], omega_rad_s: f64, out: &mut [C64]) {
        if short(p, 4, Some(out)) {
            return;
        }
        let (d_e1, d_eta1) = maxwell_branch_jacobian(p[2], p[3], omega_rad_s);
        out[0] = C64::new(1.0, 0.0);
        out[1] = J;
        out[2] = d_e1;
        out[3] = d_eta1;
    }
}

/// Model 5, SLS + viscous damper (Maxwell || Voigt, paper eq. 35):
/// E* = E0 + j w eta0 + j w eta1 E1 / (E1 + j w eta1).
/// Parameters in the paper's eq. 36 order: [E0 (Pa), eta0 (Pa s), E1 (Pa), eta1 (Pa s)].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Model5;

impl ConstitutiveModel for Model5 {
    fn name(&self) -> &str {
        "model5"
    }
    fn description(&self) -> String {
        "Model 5, SLS + viscous damper: E* = E0 + j w eta0 + j w eta1 E1 / (E1 + j w eta1)".into()
    }
    fn param_names(&self) -> Vec<String> {
        strings(&["E0", "eta0", "E1", "eta1"])
    }
    fn param_units(&self) -> Vec<String> {
        strings(&["Pa", "Pa s", "Pa", "Pa s"])
    }
    fn n_params(&self) -> usize {
        4
    }
    fn bounds(&self) -> Vec<(f64, f64)> {
        vec![POS; 4]
    }
    fn modulus(&self, p: &[f64], omega_rad_s: f64) -> C64 {
        if short(p, 4, None) {
            return NAN;
        }
        C64::new(p[0], omega_rad_s * p[1]) + maxwell_branch(p[2], p[3], omega_rad_s)
    }
    fn jacobian(&self, p: &[f64], omega_rad_s: f64, out: &mut [C64]) {
        if short(p, 4, Some(out)) {
            return;
        }
        let (d_e1, d_eta1) = maxwell_branch_jacobian(p[2], p[3], omega_rad_s);
        out[0] = C64::new(1.0, 0.0);
        out[1] = C64::new(0.0, omega_rad_s);
        out[2] = d_e1;
        out[3] = d_eta1;
    }
}

/// Fractional Zener (fractional standard linear solid), written as a spring E0 in parallel
/// with a fractional Maxwell branch:
///
/// E*(w) = E0 + E1 (j w tau)^alpha / (1 + (j w tau)^alpha),
///
/// parameters [E0 (Pa), E1 (Pa), tau (s), alpha (-)], 0 < alpha < 1.
/// This is the same law as the "standard" form (E0 + E_inf (j w tau)^alpha) / (1 + (j w tau)^alpha)
/// with E_inf = E0 + E1; this parametrisation is chosen because positive E0, E1, tau and
/// alpha in (0, 1) are then exactly the thermodynamically admissible laws (E_inf > E0),
/// which box bounds can express. Limits: E*(0) = E0, E*(inf) = E0 + E1; at alpha = 1 it is
/// Model 3 with eta1 = E1 tau. (j w tau)^alpha uses the principal branch,
/// (w tau)^alpha e^{j pi alpha / 2} for w > 0.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FractionalZener;

impl FractionalZener {
    /// (z, ln(j w tau)) with z = (j w tau)^alpha; z = 0 (and the log unused) at w tau = 0.
    fn z(tau: f64, alpha: f64, omega_rad_s: f64) -> Option<(C64, C64)> {
        let s = J * (omega_rad_s * tau);
        if s.norm() == 0.0 {
            return None;
        }
        let ln_s = s.ln();
        Some(((alpha * ln_s).exp(), ln_s))
    }
}

impl ConstitutiveModel for FractionalZener {
    fn name(&self) -> &str {
        "fractional_zener"
    }
    fn description(&self) -> String {
        "Fractional Zener: E* = E0 + E1 (j w tau)^alpha / (1 + (j w tau)^alpha), 0 < alpha < 1"
            .into()
    }
    fn param_names(&self) -> Vec<String> {
        strings(&["E0", "E1", "tau", "alpha"])
    }
    fn param_units(&self) -> Vec<String> {
        strings(&["Pa", "Pa", "s", "1"])
    }
    fn n_params(&self) -> usize {
        4
    }
    fn bounds(&self) -> Vec<(f64, f64)> {
        vec![POS, POS, POS, (0.0, 1.0)]
    }
    fn modulus(&self, p: &[f64], omega_rad_s: f64) -> C64 {
        if short(p, 4, None) {
            return NAN;
        }
        match Self::z(p[2], p[3], omega_rad_s) {
            None => C64::new(p[0], 0.0),
            Some((z, _)) => p[0] + p[1] * z / (1.0 + z),
        }
    }
    fn jacobian(&self, p: &[f64], omega_rad_s: f64, out: &mut [C64]) {
        if short(p, 4, Some(out)) {
            return;
        }
        out[0] = C64::new(1.0, 0.0);
        match Self::z(p[2], p[3], omega_rad_s) {
            None => {
                out[1] = C64::new(0.0, 0.0);
                out[2] = C64::new(0.0, 0.0);
                out[3] = C64::new(0.0, 0.0);
            }
            Some((z, ln_s)) => {
                let one_z = 1.0 + z;
                // d/dz [z / (1 + z)] = 1 / (1 + z)^2; dz/dtau = alpha z / tau; dz/dalpha = z ln(j w tau).
                let dfz = p[1] / (one_z * one_z);
                out[1] = z / one_z;
                out[2] = dfz * (p[3] * z / p[2]);
                out[3] = dfz * (z * ln_s);
            }
        }
    }
}

/// Generalized Maxwell series (Prony series, Wiechert model) with n branches:
///
/// E*(w) = E_inf + sum_k j w eta_k E_k / (E_k + j w eta_k),
///
/// parameters [E_inf, E_1, eta_1, ..., E_n, eta_n] (Pa, then Pa and Pa s per branch); the
/// relaxation time of branch k is tau_k = eta_k / E_k. With n = 1 it is Model 3.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GeneralizedMaxwell {
    /// Number of Maxwell branches (>= 1).
    pub n_branches: usize,
}

impl GeneralizedMaxwell {
    pub fn new(n_branches: usize) -> Self {
        GeneralizedMaxwell { n_branches }
    }
}

impl ConstitutiveModel for GeneralizedMaxwell {
    fn name(&self) -> &str {
        "generalized_maxwell"
    }
    fn description(&self) -> String {
        format!(
            "Generalized Maxwell, {} branches: E* = E_inf + sum_k j w eta_k E_k / (E_k + j w eta_k)",
            self.n_branches
        )
    }
    fn param_names(&self) -> Vec<String> {
        let mut v = vec!["E_inf".to_string()];
        for k in 1..=self.n_branches {
            v.push(format!("E_{k}"));
            v.push(format!("eta_{k}"));
        }
        v
    }
    fn param_units(&self) -> Vec<String> {
        let mut v = vec!["Pa".to_string()];
        for _ in 0..self.n_branches {
            v.push("Pa".to_string());
            v.push("Pa s".to_string());
        }
        v
    }
    fn n_params(&self) -> usize {
        1 + 2 * self.n_branches
    }
    fn bounds(&self) -> Vec<(f64, f64)> {
        vec![POS; 1 + 2 * self.n_branches]
    }
    fn modulus(&self, p: &[f64], omega_rad_s: f64) -> C64 {
        if short(p, 1 + 2 * self.n_branches, None) {
            return NAN;
        }
        let mut e = C64::new(p[0], 0.0);
        for k in 0..self.n_branches {
            e += maxwell_branch(p[1 + 2 * k], p[2 + 2 * k], omega_rad_s);
        }
        e
    }
    fn jacobian(&self, p: &[f64], omega_rad_s: f64, out: &mut [C64]) {
        if short(p, 1 + 2 * self.n_branches, Some(out)) {
            return;
        }
        out[0] = C64::new(1.0, 0.0);
        for k in 0..self.n_branches {
            let (d_e, d_eta) = maxwell_branch_jacobian(p[1 + 2 * k], p[2 + 2 * k], omega_rad_s);
            out[1 + 2 * k] = d_e;
            out[2 + 2 * k] = d_eta;
        }
    }
}
