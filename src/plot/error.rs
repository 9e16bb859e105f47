//! The error type of the plot module.

use std::path::PathBuf;

use crate::output::OutputError;

/// Everything that can go wrong while drawing a figure.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    #[error("figure '{figure}': no curves were given (pass at least one curve per panel)")]
    NoCurves { figure: String },
    #[error("curve '{label}' is empty (it has no points)")]
    EmptyCurve { label: String },
    #[error("curve '{label}' has {x_len} x values but {y_len} y values (they must match)")]
    LengthMismatch {
        label: String,
        x_len: usize,
        y_len: usize,
    },
    #[error("panel '{panel}' has no finite point to draw (all values NaN/inf{})", if *.log_axis { " or not positive on a log axis" } else { "" })]
    NoFiniteData { panel: String, log_axis: bool },
    #[error("figure '{figure}': {reason}")]
    InvalidInput { figure: String, reason: String },
    #[error("cannot load the embedded font: {0}")]
    Font(String),
    #[error("cannot render '{}': {message}", path.display())]
    Render { path: PathBuf, message: String },
    #[error(transparent)]
    Output(#[from] OutputError),
}

/// A drawing backend's failure while rendering, with its message; the caller attaches the
/// figure's path ([`PlotError::Render`]).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{0}")]
pub struct DrawError(pub String);
