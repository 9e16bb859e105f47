//! The run manifest (`manifest.json`): what produced a results folder.

use std::io::Read;
use std::path::{Path, PathBuf};
use std::time::{Instant, SystemTime, UNIX_EPOCH};

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use super::atomic::write_atomic_bytes;
use super::OutputError;

/// Wall time spent in one step of a run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StepTiming {
    pub step: String,
    pub seconds: f64,
}

/// One file of the results folder, with its SHA-256 (lowercase hex) when known.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FileEntry {
    /// Path relative to the results folder.
    pub name: String,
    pub sha256: Option<String>,
}

/// Provenance of a results folder, written as `manifest.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    /// rfmlab version (`CARGO_PKG_VERSION`).
    pub version: String,
    /// `git rev-parse HEAD` of the rfmlab source tree, `-dirty` appended when it has
    /// uncommitted changes; `None` when git or the source tree is not available.
    pub git_revision: Option<String>,
    /// The study file, as an absolute path (canonical when the file exists).
    pub study_file: String,
    /// SHA-256 of the study file's bytes (lowercase hex); `None` if it could not be read.
    pub study_sha256: Option<String>,
    /// Seed of the random number generators, if the run uses any.
    pub seed: Option<u64>,
    /// Start of the run, UTC, RFC 3339 (`2025-01-31T12:00:00Z`).
    pub started_utc: String,
    pub timings: Vec<StepTiming>,
    /// Counts of costly steps beside the timings (`rom builds`: ROMs built and certified by
    /// the run; `rom cache loads`: ROMs read from the cache instead).
    #[serde(default)]
    pub counters: std::collections::BTreeMap<String, u64>,
    pub files: Vec<FileEntry>,
    pub notes: Vec<String>,
}

impl Manifest {
    /// A manifest for a run of `study_file` started now. Never fails: an unreadable study
    /// file gives `study_sha256 = None` and a note, a missing git gives `git_revision = None`.
    pub fn new(study_file: impl AsRef<Path>, seed: Option<u64>) -> Manifest {
        let study_file = study_file.as_ref();
        let mut notes = Vec::new();
        let study_sha256 = match sha256_file(study_file) {
            Ok(h) => Some(h),
            Err(e) => {
                notes.push(format!("study file not hashed: {e}"));
                None
            }
        };
        Manifest {
            version: env!("CARGO_PKG_VERSION").to_string(),
            git_revision: git_revision(),
            study_file: std::fs::canonicalize(study_file)
                .or_else(|_| std::path::absolute(study_file))
                .unwrap_or_else(|_| study_file.to_path_buf())
                .display()
                .to_string(),
            study_sha256,
            seed,
            started_utc: utc_now_rfc3339(),
            timings: Vec::new(),
            counters: Default::default(),
            files: Vec::new(),
            notes,
        }
    }
    /// Records the wall time of a step.
    pub fn add_timing(&mut self, step: impl Into<String>, seconds: f64) {
        self.timings.push(StepTiming {
            step: step.into(),
            seconds,
        });
    }
    /// Runs `f`, records its wall time under `step` and returns its result.
    pub fn time<T>(&mut self, step: impl Into<String>, f: impl FnOnce() -> T) -> T {
        let t0 = Instant::now();
        let out = f();
        self.add_timing(step, t0.elapsed().as_secs_f64());
        out
    }
    /// Records a file (replacing an earlier entry of the same name).
    pub fn add_file(&mut self, name: impl Into<String>, sha256: Option<String>) {
        let name = name.into();
        self.files.retain(|f| f.name != name);
        self.files.push(FileEntry { name, sha256 });
    }
    /// Adds `n` to the counter `name`.
    pub fn add_count(&mut self, name: impl Into<String>, n: u64) {
        *self.counters.entry(name.into()).or_insert(0) += n;
    }
    pub fn add_note(&mut self, note: impl Into<String>) {
        self.notes.push(note.into());
    }
    /// Pretty JSON.
    pub fn to_json(&self) -> Result<String, OutputError> {
        serde_json::to_string_pretty(self).map_err(|source| OutputError::Json {
            path: PathBuf::from("manifest.json"),
            source,
        })
    }
    /// Writes the manifest as JSON to `path`, atomically.
    pub fn write(&self, path: impl AsRef<Path>) -> Result<(), OutputError> {
        let mut json = self.to_json()?;
        json.push('\n');
        write_atomic_bytes(path, json.as_bytes())
    }
    /// Reads a manifest written by [`Manifest::write`].
    pub fn read(path: impl AsRef<Path>) -> Result<Manifest, OutputError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|e| OutputError::io(path, "read", e))?;
        serde_json::from_str(&text).map_err(|source| OutputError::Json {
            path: path.to_path_buf(),
            source,
        })
    }
}

/// Lowercase hex SHA-256 of `bytes`.
pub fn sha256_hex(bytes: &[u8]) -> String {
    hex(&Sha256::digest(bytes))
}

/// Lowercase hex SHA-256 of a file's contents (streamed).
pub fn sha256_file(path: impl AsRef<Path>) -> Result<String, OutputError> {
    let path = path.as_ref();
    let mut f = std::fs::File::open(path).map_err(|e| OutputError::io(path, "open", e))?;
    let mut h = Sha256::new();
    let mut buf = vec![0u8; 1 << 16];
    loop {
        let n = f
            .read(&mut buf)
            .map_err(|e| OutputError::io(path, "read", e))?;
        if n == 0 {
            break;
        }
        h.update(&buf[..n]);
    }
    Ok(hex(&h.finalize()))
}

fn hex(bytes: &[u8]) -> String {
    use std::fmt::Write;
    let mut s = String::with_capacity(2 * bytes.len());
    for b in bytes {
        let _ = write!(s, "{b:02x}");
    }
    s
}

/// The git revision of the rfmlab source tree this binary was built from
/// (`git -C <crate root> rev-parse HEAD`, `-dirty` appended if tracked files changed), or
/// `None` when git or the source tree is unavailable. Never fails.
pub fn git_revision() -> Option<String> {
    let root = env!("CARGO_MANIFEST_DIR");
    let out = std::process::Command::new("git")
        .args(["-C", root, "rev-parse", "HEAD"])
        .stderr(std::process::Stdio::null())
        .output()
        .ok()?;
    if !out.status.success() {
        return None;
    }
    let rev = String::from_utf8(out.stdout).ok()?.trim().to_string();
    if rev.is_empty() {
        return None;
    }
    let dirty = std::process::Command::new("git")
        .args(["-C", root, "status", "--porcelain", "--untracked-files=no"])
        .stderr(std::process::Stdio::null())
        .output()
        .ok()
        .filter(|o| o.status.success())
        .is_some_and(|o| !o.stdout.is_empty());
    Some(if dirty { format!("{rev}-dirty") } else { rev })
}

/// The current UTC time as RFC 3339 with second resolution.
pub fn utc_now_rfc3339() -> String {
    let secs = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    format_utc(secs)
}

/// Formats seconds since the Unix epoch as `YYYY-MM-DDThh:mm:ssZ` (proleptic Gregorian
/// calendar; days-to-civil conversion by era arithmetic).
pub(crate) fn format_utc(secs: u64) -> String {
    let days = (secs / 86_400) as i64;
    let rem = secs % 86_400;
    let (h, mi, s) = (rem / 3600, (rem % 3600) / 60, rem % 60);
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!("{y:04}-{m:02}-{d:02}T{h:02}:{mi:02}:{s:02}Z")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn utc_formatting_matches_known_dates() {
        assert_eq!(format_utc(0), "1970-01-01T00:00:00Z");
        assert_eq!(format_utc(951_782_400), "2000-02-29T00:00:00Z");
        assert_eq!(format_utc(1_700_000_000), "2023-11-14T22:13:20Z");
        assert_eq!(format_utc(4_107_542_399), "2100-02-28T23:59:59Z");
    }

    #[test]
    fn the_study_path_is_recorded_absolute() {
        let m = Manifest::new("studies/default.toml", None);
        assert!(Path::new(&m.study_file).is_absolute(), "{}", m.study_file);
        assert!(m.study_file.ends_with("default.toml"), "{}", m.study_file);
        let m = Manifest::new("no/such/study.toml", None);
        assert!(Path::new(&m.study_file).is_absolute(), "{}", m.study_file);
    }

    #[test]
    fn sha256_of_abc() {
        assert_eq!(
            sha256_hex(b"abc"),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
    }
}
