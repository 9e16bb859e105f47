//! The results folder `results/<study>/` and the files written into it.

use std::io::Write;
use std::path::{Path, PathBuf};

use super::atomic::write_atomic;
use super::manifest::{sha256_file, Manifest};
use super::{OutputError, Report, Table};

/// A study's results folder. Every write is atomic; the names and SHA-256 of the files written
/// through it are collected for the manifest ([`ResultsDir::write_manifest`]).
#[derive(Debug)]
pub struct ResultsDir {
    root: PathBuf,
    written: Vec<String>,
}

fn check_component(what: &'static str, name: &str) -> Result<(), OutputError> {
    let bad = |reason| {
        Err(OutputError::BadName {
            what,
            name: name.to_string(),
            reason,
        })
    };
    if name.is_empty() {
        return bad("it is empty");
    }
    if name == "." || name == ".." {
        return bad("'.' and '..' are not allowed");
    }
    if name.contains(['/', '\\']) || name.contains('\0') {
        return bad("it must be a single path component (no '/' or '\\')");
    }
    Ok(())
}

impl ResultsDir {
    /// Creates (if needed) `<results_root>/<study>/` and returns it; `results_root` is
    /// normally `results`. Existing files in it are kept until they are replaced.
    pub fn create(results_root: impl AsRef<Path>, study: &str) -> Result<ResultsDir, OutputError> {
        check_component("study", study)?;
        let root = results_root.as_ref().join(study);
        std::fs::create_dir_all(&root)
            .map_err(|e| OutputError::io(&root, "create results folder", e))?;
        Ok(ResultsDir {
            root,
            written: Vec::new(),
        })
    }
    /// The folder.
    pub fn path(&self) -> &Path {
        &self.root
    }
    /// `<folder>/<name>` (no file is created).
    pub fn file_path(&self, name: &str) -> PathBuf {
        self.root.join(name)
    }
    /// Names (relative to the folder) of the files written through this value, in order.
    pub fn written(&self) -> &[String] {
        &self.written
    }
    /// Records a file written into the folder by other means (e.g. figures from
    /// [`crate::plot`]), so that the manifest lists it. `path` may be absolute or relative to
    /// the folder.
    pub fn record(&mut self, path: impl AsRef<Path>) {
        let path = path.as_ref();
        let rel = path.strip_prefix(&self.root).unwrap_or(path);
        let name = rel.to_string_lossy().into_owned();
        if !self.written.contains(&name) {
            self.written.push(name);
        }
    }
    /// Writes `<folder>/<name>` atomically with what `write` produces.
    pub fn write_with<F>(&mut self, name: &str, write: F) -> Result<PathBuf, OutputError>
    where
        F: FnOnce(&mut dyn Write) -> std::io::Result<()>,
    {
        check_component("file", name)?;
        let path = self.file_path(name);
        write_atomic(&path, write)?;
        self.record(name);
        Ok(path)
    }
    /// Writes `<folder>/<name>` atomically.
    pub fn write_bytes(&mut self, name: &str, bytes: &[u8]) -> Result<PathBuf, OutputError> {
        self.write_with(name, |w| w.write_all(bytes))
    }
    /// Writes a serialisable value as pretty JSON to `<folder>/<name>`.
    pub fn write_json<T: serde::Serialize>(
        &mut self,
        name: &str,
        value: &T,
    ) -> Result<PathBuf, OutputError> {
        let mut json = serde_json::to_string_pretty(value).map_err(|source| OutputError::Json {
            path: self.file_path(name),
            source,
        })?;
        json.push('\n');
        self.write_bytes(name, json.as_bytes())
    }
    /// Writes `<folder>/<table name>.parquet`.
    pub fn write_table(&mut self, table: &Table) -> Result<PathBuf, OutputError> {
        let name = format!("{}.parquet", table.name());
        check_component("table", &name)?;
        let path = self.file_path(&name);
        table.write_parquet(&path)?;
        self.record(&name);
        Ok(path)
    }
    /// Writes `<folder>/report.md`.
    pub fn write_report(&mut self, report: &Report) -> Result<PathBuf, OutputError> {
        let text = report.to_markdown();
        self.write_bytes("report.md", text.as_bytes())
    }
    /// Adds every file written so far (with its SHA-256) to `manifest` and writes it as
    /// `<folder>/manifest.json`. Call it last: the manifest does not list itself.
    pub fn write_manifest(&mut self, manifest: &mut Manifest) -> Result<PathBuf, OutputError> {
        for name in &self.written {
            let hash = sha256_file(self.root.join(name)).ok();
            manifest.add_file(name.clone(), hash);
        }
        let path = self.file_path("manifest.json");
        manifest.write(&path)?;
        Ok(path)
    }
}
