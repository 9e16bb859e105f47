//! Measured FRF data: the data model ([`frf`]), UFF dataset 58 ([`uff58`]) and CSV ([`csv`]).

pub mod checks;
pub mod csv;
pub mod frf;
pub mod inspect;
pub mod uff58;
pub mod uff_frf;

pub use checks::check_level;
pub use frf::{Channel, FrfLevel, FrfSet, Quantity};
pub use inspect::{inspect_file, InspectRow};
pub use uff58::{parse_uff, read_uff, write_uff, Uff58Dataset, UffFile};
pub use uff_frf::{frf_set_from_uff, frf_set_to_uff, UffImportOptions};

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

impl DataError {
    /// An error at `file`, optional dataset index (0-based) and line (1-based).
    pub fn at(
        file: impl Into<String>,
        dataset: Option<usize>,
        line: Option<usize>,
        message: impl Into<String>,
    ) -> Self {
        DataError {
            file: file.into(),
            dataset,
            line,
            message: message.into(),
        }
    }
}
