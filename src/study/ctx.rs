//! Validation context: the study file being checked, and the error constructors every
//! section's validator uses (each error names the file and the key).

use super::StudyError;
use std::path::Path;

pub(super) struct Ctx<'a> {
    pub(super) file: &'a Path,
}

impl Ctx<'_> {
    pub(super) fn err(&self, key: impl Into<String>, message: impl Into<String>) -> StudyError {
        StudyError {
            file: self.file.display().to_string(),
            key: key.into(),
            message: message.into(),
        }
    }
    pub(super) fn positive(&self, key: &str, v: f64, unit: &str) -> Result<f64, StudyError> {
        if v.is_finite() && v > 0.0 {
            Ok(v)
        } else {
            Err(self.err(
                key,
                format!("must be a positive number in {unit}, got {v}: give the value in SI units ({unit})"),
            ))
        }
    }
    pub(super) fn non_negative(&self, key: &str, v: f64, unit: &str) -> Result<f64, StudyError> {
        if v.is_finite() && v >= 0.0 {
            Ok(v)
        } else {
            Err(self.err(key, format!("must be zero or positive ({unit}), got {v}")))
        }
    }
    pub(super) fn poisson(&self, key: &str, v: f64) -> Result<f64, StudyError> {
        if v.is_finite() && v > -1.0 && v < 0.5 {
            Ok(v)
        } else {
            Err(self.err(
                key,
                format!("Poisson's ratio must lie in (-1, 0.5), got {v} (0.5 is incompressible and not supported by displacement elements)"),
            ))
        }
    }
}
