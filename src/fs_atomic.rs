//! Atomic file replacement, the one primitive every writer of the crate uses (result tables,
//! figures, manifests, sampler checkpoints, UFF58 files, cached ROMs, Matrix Market files).
//!
//! A file is written to a temporary sibling with a name unique to the process and the call
//! (`.<name>.tmp-<pid>-<counter><.ext>`), flushed and fsynced, then renamed over the target
//! (rename is atomic within one file system on POSIX and Windows); the folder is fsynced after
//! the rename (POSIX). Readers see either the old file or the complete new one, never a partial
//! file; when anything fails the temporary file is removed and the target is left as it was.
//!
//! This module imports nothing from the crate: numerical and data modules use it without
//! depending on `output`. Errors are plain [`std::io::Error`]s; each caller wraps them in its
//! own error type with the path it was writing.

use std::fs::{File, OpenOptions};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

static COUNTER: AtomicU64 = AtomicU64::new(0);

/// The marker between a target's name and the process id in a temporary sibling's name.
const TMP_MARK: &str = ".tmp-";

/// The temporary sibling used while `path` is being written: hidden, unique per process and
/// call, and keeping the target's extension (some encoders pick the format from it).
/// Fails when `path` has no file name.
pub fn temp_sibling(path: &Path) -> std::io::Result<PathBuf> {
    let file_name = path
        .file_name()
        .ok_or_else(|| {
            std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                format!("'{}' has no file name", path.display()),
            )
        })?
        .to_string_lossy();
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    let ext = path
        .extension()
        .map(|e| format!(".{}", e.to_string_lossy()))
        .unwrap_or_default();
    let tmp = format!(".{file_name}{TMP_MARK}{}-{n}{ext}", std::process::id());
    Ok(path.with_file_name(tmp))
}

/// Whether `name` is the name of a temporary sibling made by [`temp_sibling`].
pub fn is_temp_name(name: &str) -> bool {
    let Some(rest) = name.strip_prefix('.') else {
        return false;
    };
    let Some(i) = rest.rfind(TMP_MARK) else {
        return false;
    };
    let tail = &rest[i + TMP_MARK.len()..];
    let mut parts = tail.splitn(2, '-');
    let pid_ok = parts
        .next()
        .is_some_and(|p| !p.is_empty() && p.bytes().all(|b| b.is_ascii_digit()));
    let n_ok = parts.next().is_some_and(|r| {
        let digits = r.split('.').next().unwrap_or("");
        !digits.is_empty() && digits.bytes().all(|b| b.is_ascii_digit())
    });
    pid_ok && n_ok
}

/// Makes a finished temporary file durable (fsync) and renames it over `path`, then fsyncs
/// the folder. On failure the temporary file is removed and `path` is untouched.
pub fn commit(tmp: &Path, path: &Path) -> std::io::Result<()> {
    if let Err(e) = File::open(tmp).and_then(|f| f.sync_all()) {
        let _ = std::fs::remove_file(tmp);
        return Err(e);
    }
    if let Err(e) = std::fs::rename(tmp, path) {
        let _ = std::fs::remove_file(tmp);
        return Err(e);
    }
    sync_parent(path);
    Ok(())
}

/// Best effort: fsync the folder of `path` so that a rename in it survives a crash (POSIX).
pub fn sync_parent(path: &Path) {
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

/// Writes `path` atomically with the bytes `write` produces on a buffered writer.
///
/// If `write` returns an error (or anything else fails) the temporary file is deleted and an
/// existing file at `path` is left exactly as it was. The folder must exist.
pub fn write_atomic<F>(path: &Path, write: F) -> std::io::Result<()>
where
    F: FnOnce(&mut dyn Write) -> std::io::Result<()>,
{
    let tmp = temp_sibling(path)?;
    let file = OpenOptions::new().write(true).create_new(true).open(&tmp)?;
    let mut w = BufWriter::new(file);
    let result = write(&mut w).and_then(|()| w.flush());
    drop(w);
    if let Err(e) = result {
        let _ = std::fs::remove_file(&tmp);
        return Err(e);
    }
    commit(&tmp, path)
}

/// Writes `bytes` to `path` atomically (see [`write_atomic`]).
pub fn write_atomic_bytes(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    write_atomic(path, |w| w.write_all(bytes))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeSet;

    fn names(dir: &Path) -> BTreeSet<String> {
        std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect()
    }

    #[test]
    fn temporary_names_are_unique_across_threads_and_recognised() {
        let target = Path::new("some/folder/table.parquet");
        let all: Vec<PathBuf> = std::thread::scope(|s| {
            let hs: Vec<_> = (0..8)
                .map(|_| {
                    s.spawn(|| {
                        (0..200)
                            .map(|_| temp_sibling(target).unwrap())
                            .collect::<Vec<PathBuf>>()
                    })
                })
                .collect();
            hs.into_iter().flat_map(|h| h.join().unwrap()).collect()
        });
        let unique: BTreeSet<&PathBuf> = all.iter().collect();
        assert_eq!(unique.len(), all.len(), "temporary names collide");
        for p in &all {
            assert_eq!(p.parent(), target.parent());
            assert_eq!(p.extension().unwrap(), "parquet");
            assert!(is_temp_name(&p.file_name().unwrap().to_string_lossy()));
        }
        for n in ["table.parquet", ".hidden", "a.tmp-x", ".a.tmp-12", "M.tmp~"] {
            assert!(!is_temp_name(n), "{n}");
        }
    }

    #[test]
    fn concurrent_writers_of_one_file_leave_one_complete_version_and_no_temporaries() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("shared.json");
        std::thread::scope(|s| {
            for t in 0..8u8 {
                let target = &target;
                s.spawn(move || {
                    for _ in 0..25 {
                        write_atomic_bytes(target, &[t; 4096]).unwrap();
                    }
                });
            }
        });
        let bytes = std::fs::read(&target).unwrap();
        assert_eq!(bytes.len(), 4096);
        assert!(bytes.iter().all(|&b| b == bytes[0]), "a torn write");
        assert_eq!(
            names(dir.path()),
            BTreeSet::from(["shared.json".to_string()])
        );
    }

    #[test]
    fn a_failed_write_leaves_the_target_untouched() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("a.txt");
        std::fs::write(&target, "old").unwrap();
        let err = write_atomic(&target, |w| {
            w.write_all(b"half of the new")?;
            Err(std::io::Error::other("the encoder failed"))
        })
        .unwrap_err();
        assert_eq!(err.to_string(), "the encoder failed");
        assert_eq!(std::fs::read_to_string(&target).unwrap(), "old");
        assert_eq!(names(dir.path()), BTreeSet::from(["a.txt".to_string()]));
        // A missing folder: an error, nothing created.
        let missing = dir.path().join("no/such/b.txt");
        assert!(write_atomic_bytes(&missing, b"x").is_err());
        assert!(!dir.path().join("no").exists());
        // A success goes through the fsync and the rename.
        write_atomic_bytes(&target, b"new").unwrap();
        assert_eq!(std::fs::read_to_string(&target).unwrap(), "new");
        assert_eq!(names(dir.path()), BTreeSet::from(["a.txt".to_string()]));
    }

    #[test]
    fn a_commit_onto_a_folder_fails_and_removes_the_temporary_file() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("sub");
        std::fs::create_dir(&target).unwrap();
        std::fs::write(target.join("keep"), "user").unwrap();
        assert!(write_atomic_bytes(&target, b"x").is_err());
        assert_eq!(
            std::fs::read_to_string(target.join("keep")).unwrap(),
            "user"
        );
        assert_eq!(names(dir.path()), BTreeSet::from(["sub".to_string()]));
    }
}
