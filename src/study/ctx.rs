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
                if unit == "-" || unit.is_empty() {
                    format!("must be a positive number (a plain ratio without unit), got {v}: give a number above 0 (docs/study-files.md gives its default)")
                } else {
                    format!("must be a positive number in {unit}, got {v}: give the value in SI units ({unit})")
                },
            ))
        }
    }
    pub(super) fn non_negative(&self, key: &str, v: f64, unit: &str) -> Result<f64, StudyError> {
        if v.is_finite() && v >= 0.0 {
            Ok(v)
        } else {
            Err(self.err(
                key,
                if unit == "-" || unit.is_empty() {
                    format!("must be zero or a positive number (a plain ratio without unit), got {v}")
                } else {
                    format!("must be zero or a positive number in {unit}, got {v}: give the value in SI units ({unit})")
                },
            ))
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
