//! Measured FRF data: the data model ([`frf`]), UFF dataset 58 ([`uff58`]) and CSV ([`csv`]).

pub mod frf;

pub use frf::{Channel, FrfLevel, FrfSet, Quantity};

/// An error reading or checking measured data: names the file, the dataset (0-based index)
/// and line where known, and what to do.
#[derive(Debug, thiserror::Error)]
#[error("{file}{}{}: {message}", dataset.map(|d| format!(": dataset {d}")).unwrap_or_default(), line.map(|l| format!(", line {l}")).unwrap_or_default())]
pub struct DataError {
    pub file: String,
    pub dataset: Option<usize>,
    pub line: Option<usize>,
    pub message: String,
}
