//! Atomic file replacement for result files: [`crate::fs_atomic`] with errors that name the
//! file ([`OutputError`]). Readers see either the old file or the complete new one, never a
//! partial file.

use std::io::Write;
use std::path::{Path, PathBuf};

use super::OutputError;

/// The temporary sibling used while `path` is being written ([`crate::fs_atomic::temp_sibling`]).
pub(crate) fn temp_sibling(path: &Path) -> Result<PathBuf, OutputError> {
    crate::fs_atomic::temp_sibling(path).map_err(|_| OutputError::NotAFile {
        path: path.to_path_buf(),
    })
}

/// Checks that the folder of `path` exists.
pub(crate) fn check_parent(path: &Path) -> Result<(), OutputError> {
    if path.file_name().is_none() {
        return Err(OutputError::NotAFile {
            path: path.to_path_buf(),
        });
    }
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() && !p.is_dir() => Err(OutputError::MissingParent {
            path: path.to_path_buf(),
        }),
        _ => Ok(()),
    }
}

/// Makes a finished temporary file durable and moves it over `path`.
/// On failure the temporary file is removed and `path` is untouched.
pub(crate) fn commit(tmp: &Path, path: &Path) -> Result<(), OutputError> {
    crate::fs_atomic::commit(tmp, path)
        .map_err(|e| OutputError::io(path, "fsync and rename the temporary file onto", e))
}

/// Writes `path` atomically with the bytes produced by `write`.
///
/// `write` receives a buffered writer on a temporary file in the same folder. If it returns
/// an error (or anything else fails), the temporary file is deleted and an existing file at
/// `path` is left exactly as it was. Otherwise the temporary file is flushed, fsynced and
/// renamed onto `path`. The folder must exist.
pub fn write_atomic<F>(path: impl AsRef<Path>, write: F) -> Result<(), OutputError>
where
    F: FnOnce(&mut dyn Write) -> std::io::Result<()>,
{
    let path = path.as_ref();
    check_parent(path)?;
    crate::fs_atomic::write_atomic(path, write).map_err(|e| OutputError::io(path, "write", e))
}

/// Writes `bytes` to `path` atomically (see [`write_atomic`]).
pub fn write_atomic_bytes(path: impl AsRef<Path>, bytes: &[u8]) -> Result<(), OutputError> {
    write_atomic(path, |w| w.write_all(bytes))
}
