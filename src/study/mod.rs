//! Study files: the TOML as written (serde, unknown keys denied) and the validated, typed study.

/// An error in a study file: names the file, the key and the fix.
#[derive(Debug, thiserror::Error)]
#[error("{file}: {key}: {message}")]
pub struct StudyError {
    pub file: String,
    pub key: String,
    pub message: String,
}
