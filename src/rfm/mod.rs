//! Response function method (RFM) updating of the adhesive's complex modulus
//! (paper eq. 9-11 and 37; method.md, "RFM").
//!
//! # The update equation
//! With Z_X = Z_A + dE* S (the model differs from the structure only through the modulus),
//! H_X - H_A = -H_A dZ H_X; in accelerance (H' = -w^2 H), for response i and excitation j,
//!
//! ```text
//!   B_ij(w) = ( -w^2 H_A,ij - H'_X,ij ) / ( H_A,i^T S H'_X,j ),   dE*(w) = B_ij(w)   (eq. 9-11)
//! ```
//!
//! H'_X,j is the whole DOF column j; its unmeasured entries are filled with the analytical
//! accelerance -w^2 H_A,j (this is why the method iterates). With the measured set m and the
//! engine's outputs ([`crate::frf::Sweep`]), the denominator is
//!
//! ```text
//!   d_ij = H_A,i^T S H'_X,j = w^2 dH_ij/dE'  +  sum_m sh[m][i] (H'_X,mj + w^2 H_A,mj)
//! ```
//!
//! because H_A,i^T S H_A,j = -dH_ij/dE' and b_m^T S H_A b_i = `sh[m][i]`. The second term needs
//! `sh` with *i as an input*: the engine must be built with inputs = all measured points
//! (checked, [`RfmError::EngineInputs`]). The fill assumes a measured point is one DOF with
//! weight 1 (a node); for interpolated points it is the natural generalisation b_m (H'_X - H'_A).
//!
//! [`Denominator::Analytical`] replaces H'_X,j by the analytical column (drops the second term):
//! then B = (H'_A - H'_X) / (-dH'_A/dE*), a per-line Newton step on the FRF residual.
//!
//! # Three estimators
//! * [`rfm_per_line`]: E*(w) <- E*(w) + B at each line, per FRF and combined (the mean of B
//!   over FRFs, the least-squares solution of the stacked eq. 11); the paper's Fig. 13 and 18.
//! * [`rfm_band_constant`]: one constant E* over a band (Model 1 over a 10 Hz band around a
//!   resonance, case study 1): eq. 37 with dE*/dp = [1, j].
//! * [`rfm_global`]: a [`ConstitutiveModel`] over a band. Eq. 37, U dp = D, with U rows
//!   [Re dE*/dp ; Im dE*/dp](w_l) and D = [Re B_il ; Im B_il], stacked over lines l and FRFs i,
//!   with no weights (as in the paper: every row is a modulus error in Pa, so FRFs are already
//!   on one scale). Solved by a thin SVD (faer) in log-parameters q = ln p (U columns scaled by
//!   p), truncated at `rcond * s_max` ([`RfmParams::rcond`], default 1e-10; the rank is
//!   reported); p <- p exp(dq) keeps positive parameters positive, and the step is halved
//!   when it leaves a model's admissible range or makes Z singular.
//!
//! # What the fixed point is (Gauss-Newton equivalence)
//! At a fixed point dp = 0, so U^T D = 0, i.e. for every parameter k
//!
//! ```text
//!   Re sum_{l,i} conj(dE*/dp_k (w_l)) B_il(p) = 0,   B_il = r_il / d_il,   r_il = H'_A,ij(p) - H'_X,ij.
//! ```
//!
//! Let g_il = dH'_A,ij/dE* (= -w^2 dH_ij/dE'). Gauss-Newton on the weighted FRF residual
//! rho_il = r_il / |g_il| with the weights evaluated at the current iterate (iteratively
//! reweighted least squares) has the stationarity condition Re sum conj(g_il dE*/dp_k) r_il /
//! |g_il|^2 = 0. With [`Denominator::Analytical`], d_il = -g_il, and the two conditions are the
//! same equation: **the RFM fixed point is the Gauss-Newton (IRLS) solution of
//! min sum_{l,i} |H'_A,ij(p) - H'_X,ij|^2 / |dH'_A,ij/dE*|^2**, i.e. the FRF error measured in
//! modulus units. With the paper's [`Denominator::MeasuredColumn`],
//! d_il = -g_il + sum_m sh[m][i] (H'_X,mj - H'_A,mj), which differs from -g_il by a term of the
//! order of the residual, so the two fixed points differ by O(|r|^2): on noiseless data both
//! are the truth, on noisy data they agree to second order in the noise. tests/rfm_gauss_newton.rs
//! checks both statements with an independent Gauss-Newton.

mod dense;
mod global;
mod linearise;
mod per_line;
pub mod status;

pub use dense::DenseEngine;
pub use global::{
    rfm_band_constant, rfm_global, BandResult, ConstantModulus, IterationRecord, RfmResult,
    WeakDirection,
};
pub use linearise::{frac, rfm_linearise, Linearisation};
pub use per_line::{rfm_per_line, PerLineEstimate};
pub use status::{FitStatus, FlagReason};

use crate::common::C64;
use crate::frf::FrfError;

/// One measured accelerance column: excitation at observation point `input`, responses at
/// observation points `outputs` (indices into the engine's observation points).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MeasuredColumn {
    /// Frequency lines (rad/s), strictly positive.
    pub omega_rad_s: Vec<f64>,
    /// Excitation point (index into the engine's observation points).
    pub input: usize,
    /// Response points (indices into the engine's observation points), no duplicates.
    pub outputs: Vec<usize>,
    /// Measured accelerance (m/s^2/N), `[line][k]` flattened: entry `line * outputs.len() + k`.
    pub accelerance: Vec<C64>,
}

impl MeasuredColumn {
    /// Number of frequency lines.
    pub fn n_lines(&self) -> usize {
        self.omega_rad_s.len()
    }
    /// Measured value at (line, k).
    #[inline]
    pub fn at(&self, line: usize, k: usize) -> C64 {
        self.accelerance[line * self.outputs.len() + k]
    }
    /// The lines with frequency in [lo_hz, hi_hz] (inclusive), as a new column.
    pub fn restrict_to_band(&self, lo_hz: f64, hi_hz: f64) -> MeasuredColumn {
        let n_out = self.outputs.len();
        let mut out = MeasuredColumn {
            omega_rad_s: Vec::new(),
            input: self.input,
            outputs: self.outputs.clone(),
            accelerance: Vec::new(),
        };
        for (l, &w) in self.omega_rad_s.iter().enumerate() {
            let f = w / (2.0 * std::f64::consts::PI);
            if f >= lo_hz && f <= hi_hz {
                out.omega_rad_s.push(w);
                out.accelerance
                    .extend_from_slice(&self.accelerance[l * n_out..(l + 1) * n_out]);
            }
        }
        out
    }
}

/// Which column enters the RFM denominator H_A,i^T S H'_X,j.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Denominator {
    /// The paper's eq. 9: the measured column, unmeasured entries filled analytically.
    #[default]
    MeasuredColumn,
    /// The analytical column -w^2 H_A,j: B becomes a Newton step on the FRF residual and the
    /// fixed point is exactly the Gauss-Newton solution described in the module doc.
    Analytical,
}

/// Tuning knobs of the RFM iterations.
#[derive(Clone, Debug, PartialEq)]
pub struct RfmParams {
    /// Stop when the largest relative parameter (or modulus) change falls below this. Default 1e-8.
    pub tol_rel_change: f64,
    /// Maximum number of updates. Default 50.
    pub max_iterations: usize,
    /// SVD truncation: singular values below `rcond * s_max` are dropped. Default 1e-10.
    pub rcond: f64,
    /// Right singular vectors with s < `weak_ratio * s_max` are reported as poorly determined
    /// combinations (the smallest one is always reported). Default 1e-3.
    pub weak_ratio: f64,
    /// Largest log-parameter change per update (the step is scaled down to it). Default 1.0
    /// (a factor e).
    pub max_log_step: f64,
    /// Per-line estimates: largest modulus change per update relative to |E*|, |dE*| <=
    /// max_rel_modulus_step |E*| (a damped Newton step where the FRF is insensitive). Default 0.5.
    pub max_rel_modulus_step: f64,
    /// Step halvings tried when an update leaves the admissible range or makes Z singular
    /// before the run is declared diverged. Default 20.
    pub max_step_halvings: usize,
    /// Declared diverged when the modulus residual norm exceeds this multiple of the initial
    /// one. Default 1e6.
    pub divergence_factor: f64,
    /// Which column enters the denominator. Default: the paper's measured column.
    pub denominator: Denominator,
}

impl Default for RfmParams {
    fn default() -> Self {
        RfmParams {
            tol_rel_change: 1e-8,
            max_iterations: 50,
            rcond: 1e-10,
            weak_ratio: 1e-3,
            max_log_step: 1.0,
            max_rel_modulus_step: 0.5,
            max_step_halvings: 20,
            divergence_factor: 1e6,
            denominator: Denominator::MeasuredColumn,
        }
    }
}

/// Why an RFM iteration stopped.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum StopReason {
    /// Relative change below tolerance with full numerical rank.
    Converged,
    /// Relative change below tolerance, but U had numerical rank < number of parameters: the
    /// truncated (minimum-norm) steps converged in a subspace; see the weak directions.
    RankDeficient,
    /// The iteration budget ran out.
    MaxIterations,
    /// The residual grew beyond `divergence_factor`, became non-finite, or no step halving
    /// gave an admissible, non-singular update.
    Diverged,
}

impl std::fmt::Display for StopReason {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let s = match self {
            StopReason::Converged => "converged",
            StopReason::RankDeficient => "rank deficient",
            StopReason::MaxIterations => "max iterations",
            StopReason::Diverged => "diverged",
        };
        f.write_str(s)
    }
}

/// Errors of RFM updating.
#[derive(Debug, thiserror::Error)]
pub enum RfmError {
    #[error("measured data: {0}")]
    Data(String),
    #[error("observation point {point} (the {role}) is not an input of the FRF engine; build the engine with inputs = all measured observation points (the RFM needs S H_A,i for every response i)")]
    EngineInputs { point: usize, role: &'static str },
    #[error(
        "observation point {point} is out of range: the engine has {n_out} observation points"
    )]
    PointOutOfRange { point: usize, n_out: usize },
    #[error("initial value {name} = {value} is outside the admissible range ({lo}, {hi}); choose an initial value inside it")]
    InadmissibleInitial {
        name: String,
        value: f64,
        lo: f64,
        hi: f64,
    },
    #[error("expected {expected} initial parameter values for model {model}, got {got}")]
    ParamCount {
        model: String,
        expected: usize,
        got: usize,
    },
    #[error("the initial values make the system singular ({params}); choose different initial values: {source}")]
    SingularInitial { params: String, source: FrfError },
    #[error("no frequency line in the band {lo_hz}..{hi_hz} Hz")]
    EmptyBand { lo_hz: f64, hi_hz: f64 },
    #[error("the RFM denominator H_A,i^T S H'_X,j vanishes at line {line} ({freq_hz} Hz), output {output}: the FRF there is insensitive to the modulus; exclude this line")]
    ZeroDenominator {
        line: usize,
        freq_hz: f64,
        output: usize,
    },
    #[error("SVD of the RFM system failed: {0}")]
    Svd(String),
    #[error(transparent)]
    Frf(#[from] FrfError),
}
