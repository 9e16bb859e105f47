//! Inverse eigensensitivity method (IEM), paper eq. 12-20 as corrected in method.md.
//!
//! For the complex eigenproblem (K_b + E* S - lambda M) phi = 0 with phi^T M phi = 1 (no
//! conjugate), d lambda/dE' = phi^T S phi and d lambda/dE'' = j phi^T S phi, so lambda is a
//! holomorphic function of E* with derivative phi^T S phi, and per mode (eq. 20)
//!
//! ```text
//!   dE* = (lambda_X - lambda_A) / (phi^T S phi),    lambda_X = w_r^2 (1 + j eta_r),
//! ```
//!
//! iterated until |dE*|/|E*| < tol: Newton's method on lambda_A(E*) = lambda_X, hence
//! quadratically convergent. lambda_X comes from the circle fit (w_r = 2 pi f_r, eta_r the
//! modal loss factor). The analytical modes come from a [`ModeProvider`] (the FE modes of
//! `crate::modes`, a reduced model, or a test double); the mode used at each iteration is the
//! one nearest the experimental frequency (among y-dominant modes when
//! [`IemParams::y_dominant_only`] and any are flagged).

use crate::common::C64;
use std::f64::consts::PI;

/// An analytical mode as the IEM needs it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AnalyticalMode {
    /// Eigenvalue lambda (rad^2/s^2): Re = w^2, Im = w^2 eta.
    pub lambda: C64,
    /// phi^T S phi with phi^T M phi = 1 (unconjugated), = d lambda / dE' (1/(kg ... per Pa)).
    pub phi_s_phi: C64,
    /// Whether the mode is dominated by the measured direction (true when unknown).
    pub y_dominant: bool,
}

impl AnalyticalMode {
    /// A mode with unknown direction (treated as y-dominant).
    pub fn new(lambda: C64, phi_s_phi: C64) -> Self {
        AnalyticalMode {
            lambda,
            phi_s_phi,
            y_dominant: true,
        }
    }
    /// Natural frequency sqrt(Re lambda) / 2 pi (Hz).
    pub fn freq_hz(&self) -> f64 {
        self.lambda.re.max(0.0).sqrt() / (2.0 * PI)
    }
    /// Modal loss factor Im lambda / Re lambda.
    pub fn loss_factor(&self) -> f64 {
        self.lambda.im / self.lambda.re
    }
}

impl From<(C64, C64)> for AnalyticalMode {
    fn from((lambda, phi_s_phi): (C64, C64)) -> Self {
        AnalyticalMode::new(lambda, phi_s_phi)
    }
}

/// Why a [`ModeProvider`] has no modes at a modulus (the engine's or the eigensolver's error).
pub type ModesError = Box<dyn std::error::Error + Send + Sync>;

/// Gives the analytical modes at a modulus. Implemented for closures
/// `Fn(C64) -> Result<Vec<AnalyticalMode>, ModesError>`.
pub trait ModeProvider {
    /// Modes of (K_b + E* S, M) at modulus E* (Pa); the error says what failed.
    fn modes_at(&self, modulus_pa: C64) -> Result<Vec<AnalyticalMode>, ModesError>;
}

impl<F> ModeProvider for F
where
    F: Fn(C64) -> Result<Vec<AnalyticalMode>, ModesError>,
{
    fn modes_at(&self, modulus_pa: C64) -> Result<Vec<AnalyticalMode>, ModesError> {
        self(modulus_pa)
    }
}

/// An experimental mode (circle fit).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ExperimentalMode {
    pub freq_hz: f64,
    pub loss_factor: f64,
}

impl ExperimentalMode {
    /// lambda_X = w_r^2 (1 + j eta_r).
    pub fn lambda(&self) -> C64 {
        let w = 2.0 * PI * self.freq_hz;
        C64::new(w * w, w * w * self.loss_factor)
    }
}

/// Tuning knobs of the IEM iteration.
#[derive(Clone, Debug)]
pub struct IemParams {
    /// Stop when |dE*| / |E*| falls below this. Default 1e-12.
    pub tol_rel_change: f64,
    /// Maximum number of updates. Default 50.
    pub max_iterations: usize,
    /// Select only among modes flagged y-dominant (if any is). Default true.
    pub y_dominant_only: bool,
    /// Largest relative modulus change per update, |dE*| <= max_rel_step |E*| (the step is
    /// scaled down to it), a guard against jumping to another mode. Default 0.5.
    pub max_rel_step: f64,
}

impl Default for IemParams {
    fn default() -> Self {
        IemParams {
            tol_rel_change: 1e-12,
            max_iterations: 50,
            y_dominant_only: true,
            max_rel_step: 0.5,
        }
    }
}

/// Result of [`iem_mode`].
#[derive(Clone, Debug, PartialEq)]
pub struct IemResult {
    /// Identified modulus (Pa).
    pub modulus: C64,
    /// Updates made.
    pub iterations: usize,
    /// Frequency (Hz) and loss factor of the selected analytical mode at the final modulus.
    pub freq_hz: f64,
    pub loss_factor: f64,
    pub converged: bool,
    /// The modulus after each update (the initial one first).
    pub history: Vec<C64>,
}

/// Errors of the IEM.
#[derive(Clone, Debug, thiserror::Error)]
pub enum IemError {
    #[error("mode computation failed at E* = {modulus} Pa: {message}")]
    Modes { modulus: C64, message: String },
    #[error("no analytical mode available at E* = {modulus} Pa (is the mode count large enough?)")]
    NoMode { modulus: C64 },
    #[error("phi^T S phi of the mode at {freq_hz} Hz is zero: this mode does not involve the adhesive, so the IEM cannot update the modulus from it")]
    Insensitive { freq_hz: f64 },
    #[error("bad input: {0}")]
    Input(String),
}

/// Select the analytical mode nearest the target frequency.
pub fn nearest_mode(
    modes: &[AnalyticalMode],
    target_hz: f64,
    y_dominant_only: bool,
) -> Option<AnalyticalMode> {
    let any_y = modes.iter().any(|m| m.y_dominant);
    modes
        .iter()
        .filter(|m| !(y_dominant_only && any_y) || m.y_dominant)
        .filter(|m| m.lambda.re.is_finite() && m.lambda.im.is_finite())
        .min_by(|a, b| {
            (a.freq_hz() - target_hz)
                .abs()
                .total_cmp(&(b.freq_hz() - target_hz).abs())
        })
        .copied()
}

/// Identify E* from one experimental mode by eq. 20, starting from `e0` (Pa).
pub fn iem_mode(
    provider: &dyn ModeProvider,
    target: ExperimentalMode,
    e0: C64,
    params: &IemParams,
) -> Result<IemResult, IemError> {
    if !(target.freq_hz.is_finite() && target.freq_hz > 0.0 && target.loss_factor.is_finite()) {
        return Err(IemError::Input(format!(
            "experimental mode {} Hz, loss factor {}: frequency must be positive and both finite",
            target.freq_hz, target.loss_factor
        )));
    }
    if !(e0.re.is_finite() && e0.im.is_finite() && e0.norm() > 0.0) {
        return Err(IemError::Input(format!(
            "initial modulus {e0} Pa must be finite and non-zero"
        )));
    }
    let lambda_x = target.lambda();
    let select = |e: C64| -> Result<AnalyticalMode, IemError> {
        let modes = provider.modes_at(e).map_err(|err| IemError::Modes {
            modulus: e,
            message: err.to_string(),
        })?;
        nearest_mode(&modes, target.freq_hz, params.y_dominant_only)
            .ok_or(IemError::NoMode { modulus: e })
    };
    let mut e = e0;
    let mut mode = select(e)?;
    let mut history = vec![e];
    let mut converged = false;
    let mut iterations = 0;
    for _ in 0..params.max_iterations {
        if mode.phi_s_phi.norm() == 0.0 {
            return Err(IemError::Insensitive {
                freq_hz: mode.freq_hz(),
            });
        }
        let mut de = (lambda_x - mode.lambda) / mode.phi_s_phi;
        let limit = params.max_rel_step * e.norm();
        if de.norm() > limit {
            de *= limit / de.norm();
        }
        e += de;
        iterations += 1;
        history.push(e);
        mode = select(e)?;
        if de.norm() <= params.tol_rel_change * e.norm() {
            converged = true;
            break;
        }
    }
    Ok(IemResult {
        modulus: e,
        iterations,
        freq_hz: mode.freq_hz(),
        loss_factor: mode.loss_factor(),
        converged,
        history,
    })
}
