//! Material-level identification on measured complex-modulus data (a DMA master curve): the
//! observations are E'(w) and E''(w) themselves, no structure.
//!
//! * [`law`]: the relaxation laws the loop moves through (Model 4, fractional Zener, Maxwell
//!   branches) in one parametrisation with analytic Jacobians;
//! * [`posterior`]: the [`crate::inference::Posterior`] on log E' and log E'' with inferred
//!   relative noise scales;
//! * [`residual`]: runs test and successive-difference scatter (systematic or scatter?);
//! * [`kk`]: Kramers-Kronig consistency of the data through a non-negative spectrum ([`nnls`]);
//! * [`fit_loop`]: fit, analyse the residual, add relaxation content while the Laplace evidence
//!   improves, stop at the causal floor.

pub mod fit_loop;
pub mod kk;
pub mod law;
pub mod nnls;
pub mod posterior;
pub mod residual;

pub use fit_loop::{run_loop, Candidate, LoopParams, LoopResult, StopReason};
pub use kk::{kk_check, KkCheck};
pub use law::{ParamKind, RelaxationLaw};
pub use posterior::{MasterCurve, MaterialPosterior, PriorBox};
pub use residual::{residual_stats, ResidualStats};

/// Errors of the material-level fit.
#[derive(Debug, Clone, thiserror::Error)]
pub enum MaterialFitError {
    /// The data cannot be used (the message says why and what to do).
    #[error("{0}")]
    Data(String),
    /// The MAP search failed for a law.
    #[error("fitting {law}: {message}")]
    Fit { law: String, message: String },
}
