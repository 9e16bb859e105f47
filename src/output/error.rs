//! The error type of the output module.

use std::path::PathBuf;

/// Everything that can go wrong while writing or reading result files.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    /// A file-system operation failed.
    #[error("cannot {action} '{}': {source}", path.display())]
    Io {
        path: PathBuf,
        /// What was being done ("create temporary file for", "write", "rename", ...).
        action: &'static str,
        #[source]
        source: std::io::Error,
    },
    /// The folder a file should go into does not exist.
    #[error("cannot write '{}': its folder does not exist (create it first, e.g. with ResultsDir::create)", path.display())]
    MissingParent { path: PathBuf },
    /// A path has no file name component.
    #[error("'{}' is not a file path (it has no file name)", path.display())]
    NotAFile { path: PathBuf },
    /// Polars failed to build, write or read a table.
    #[error("parquet error for table '{table}' ({}): {source}", path.display())]
    Polars {
        table: String,
        path: PathBuf,
        #[source]
        source: polars_core::error::PolarsError,
    },
    /// A table column was rejected when it was added.
    #[error("table '{table}', column '{column}': {reason}")]
    BadColumn {
        table: String,
        column: String,
        reason: String,
    },
    /// A parquet file holds a column this reader does not support.
    #[error("'{}': column '{column}' has type {dtype}, which rfmlab tables do not use (supported: f64, i64, u32, string, bool)", path.display())]
    UnsupportedColumn {
        path: PathBuf,
        column: String,
        dtype: String,
    },
    /// JSON serialisation or parsing failed.
    #[error("JSON error for '{}': {source}", path.display())]
    Json {
        path: PathBuf,
        #[source]
        source: serde_json::Error,
    },
    /// A name (study, file) cannot be used as a single path component.
    #[error("invalid {what} name '{name}': {reason}")]
    BadName {
        what: &'static str,
        name: String,
        reason: &'static str,
    },
    /// An output path holds something rfmlab may not replace (the output contract,
    /// [`crate::output::contract`]): nothing was written.
    #[error("refusing to write '{}': it is {found}; {fix}", path.display())]
    Refused {
        path: PathBuf,
        /// What is there, in words.
        found: String,
        /// What the user can do.
        fix: String,
    },
    /// An output path cannot be created.
    #[error("cannot write '{}': {reason}; choose a folder you can write to with -o/--output", path.display())]
    NotWritable { path: PathBuf, reason: String },
    /// The parts of a sharded table do not fit together.
    #[error("sharded table '{table}': {message}")]
    Shard { table: String, message: String },
}

impl OutputError {
    /// Whether the error is about the output path the user chose (a refused or unwritable
    /// output: exit code 2 on the command line) rather than a failure while writing.
    pub fn is_input(&self) -> bool {
        matches!(
            self,
            OutputError::Refused { .. } | OutputError::NotWritable { .. }
        )
    }
    pub(crate) fn io(
        path: impl Into<PathBuf>,
        action: &'static str,
        source: std::io::Error,
    ) -> Self {
        OutputError::Io {
            path: path.into(),
            action,
            source,
        }
    }
}
