//! Atomic file replacement: write a temporary file in the target's folder, flush and fsync it,
//! then rename it over the target (rename is atomic within one file system on POSIX and
//! Windows). Readers see either the old file or the complete new one, never a partial file.

use std::fs::{File, OpenOptions};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use super::OutputError;

static COUNTER: AtomicU64 = AtomicU64::new(0);

/// The temporary sibling used while `path` is being written: hidden, unique per process and
/// call, and keeping the target's extension (some encoders pick the format from it).
pub(crate) fn temp_sibling(path: &Path) -> Result<PathBuf, OutputError> {
    let file_name = path
        .file_name()
        .ok_or_else(|| OutputError::NotAFile {
            path: path.to_path_buf(),
        })?
        .to_string_lossy();
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    let ext = path
        .extension()
        .map(|e| format!(".{}", e.to_string_lossy()))
        .unwrap_or_default();
    let tmp = format!(".{file_name}.tmp-{}-{n}{ext}", std::process::id());
    Ok(path.with_file_name(tmp))
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
    let sync = File::open(tmp).and_then(|f| f.sync_all());
    if let Err(e) = sync {
        let _ = std::fs::remove_file(tmp);
        return Err(OutputError::io(path, "fsync temporary file for", e));
    }
    if let Err(e) = std::fs::rename(tmp, path) {
        let _ = std::fs::remove_file(tmp);
        return Err(OutputError::io(path, "rename temporary file onto", e));
    }
    sync_parent(path);
    Ok(())
}

/// Best effort: fsync the folder so the rename itself survives a crash (POSIX only).
fn sync_parent(path: &Path) {
    #[cfg(unix)]
    {
        let parent = match path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p,
            _ => Path::new("."),
        };
        if let Ok(d) = File::open(parent) {
            let _ = d.sync_all();
        }
    }
    #[cfg(not(unix))]
    let _ = path;
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
    let tmp = temp_sibling(path)?;
    let file = OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&tmp)
        .map_err(|e| OutputError::io(path, "create temporary file for", e))?;
    let mut w = BufWriter::new(file);
    let result = write(&mut w).and_then(|()| w.flush());
    drop(w);
    if let Err(e) = result {
        let _ = std::fs::remove_file(&tmp);
        return Err(OutputError::io(path, "write", e));
    }
    commit(&tmp, path)
}

/// Writes `bytes` to `path` atomically (see [`write_atomic`]).
pub fn write_atomic_bytes(path: impl AsRef<Path>, bytes: &[u8]) -> Result<(), OutputError> {
    write_atomic(path, |w| w.write_all(bytes))
}
