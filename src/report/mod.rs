//! Writing a run's [`Results`] to a folder: every table as parquet (units in the file
//! metadata, see [`crate::output`]), the figures when the plan asks for them, `report.md` and
//! `manifest.json` (written last, with every file's SHA-256, the timings and counters).
//!
//! The folder is replaced as a whole ([`crate::output::replace_dir`]): everything is written
//! into a temporary sibling `<dir>.tmp-<pid>` that is then swapped with `dir`. A failed or
//! killed write leaves the previous results intact; a temporary folder left by a killed run is
//! deleted by the next write to the same folder.

use crate::pipeline::{Event, Results, RunError};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// What [`write`] wrote.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Written {
    /// The results folder.
    pub dir: PathBuf,
    /// Files written, relative to `dir` (`manifest.json` last).
    pub files: Vec<String>,
    /// Seconds spent writing.
    pub seconds: f64,
}

/// Write `results` into `dir`, replacing its previous contents atomically (module doc).
pub fn write(results: &Results, dir: impl AsRef<Path>) -> Result<Written, RunError> {
    write_with(results, dir, &|_| {})
}

/// [`write`] with a progress callback.
pub fn write_with(
    results: &Results,
    dir: impl AsRef<Path>,
    progress: &(dyn Fn(Event) + Sync),
) -> Result<Written, RunError> {
    let dir = dir.as_ref();
    let t0 = Instant::now();
    let files = crate::output::replace_dir(dir, |tmp| {
        crate::runner::write::fill(tmp, results, t0, progress)
    })?;
    Ok(Written {
        dir: dir.to_path_buf(),
        files,
        seconds: t0.elapsed().as_secs_f64(),
    })
}
