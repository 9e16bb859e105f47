//! Writing a virtual experiment: one UFF58 file per level (H1 and coherence, labelled as
//! simulated) and the `<stem>.truth.json` sidecar stating the truth.

use super::{failed, SimulateError, Simulated};
use crate::data::FrfSet;
use serde_json::json;
use std::path::{Path, PathBuf};

/// The files [`Simulated::write`] writes for `out` and levels named `levels`: one data file
/// per level, `<stem>_<level>.<ext>` beside `out` (`.uff` when `out` has no extension), and
/// the sidecar `<stem>.truth.json`.
pub fn planned_files(out: &Path, levels: &[&str]) -> (Vec<PathBuf>, PathBuf) {
    let stem = out
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "simulated".into());
    let ext = out
        .extension()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "uff".into());
    let dir = out.parent().map(|p| p.to_path_buf()).unwrap_or_default();
    let data = levels
        .iter()
        .map(|l| dir.join(format!("{stem}_{l}.{ext}")))
        .collect();
    (data, dir.join(format!("{stem}.truth.json")))
}

/// Whether `path` is a file `rfmlab simulate` wrote: a UFF58 file whose ID line says so, or a
/// truth sidecar with its note (the output contract replaces only these without `--force`).
pub fn is_simulated_file(path: &Path) -> bool {
    crate::output::contract::file_mentions(path, SIMULATED_MARK.as_bytes(), 4096, 0)
        || crate::output::contract::file_mentions(path, TRUTH_MARK.as_bytes(), 4096, 8192)
}

/// The start of ID line 2 of every dataset `rfmlab simulate` writes.
const SIMULATED_MARK: &str = "SIMULATED by rfmlab simulate";
/// The note of every truth sidecar (`super::simulate` writes it).
const TRUTH_MARK: &str = "written by rfmlab simulate";

impl Simulated {
    /// Write one UFF58 file per level, `<stem>_<level>.<ext>` beside `out`, and the sidecar
    /// `<stem>.truth.json` (written last, atomically). Returns the data files and the sidecar.
    pub fn write(&self, out: &Path) -> Result<(Vec<PathBuf>, PathBuf), SimulateError> {
        if let Some(dir) = out.parent() {
            if !dir.as_os_str().is_empty() {
                std::fs::create_dir_all(dir)
                    .map_err(|e| failed(&format!("creating {}", dir.display()), e))?;
            }
        }
        let names: Vec<&str> = self.set.levels.iter().map(|l| l.name.as_str()).collect();
        let (paths, sidecar) = planned_files(out, &names);
        let mut written = Vec::new();
        for (lv, p) in self.set.levels.iter().zip(paths) {
            let one = FrfSet {
                levels: vec![lv.clone()],
            };
            let mut datasets = crate::data::uff_frf::frf_set_datasets(&one);
            for d in &mut datasets {
                // ID line 2 says what these data are, so no reader mistakes them for a measurement.
                d.ids[1] = format!("{SIMULATED_MARK} ({}, seed {})", self.name, self.seed);
            }
            crate::data::uff58::write_uff(&p, &datasets, self.binary)
                .map_err(|e| failed("writing UFF58", e))?;
            written.push(p);
        }
        let mut doc = self.truth.clone();
        if let Some(o) = doc.as_object_mut() {
            o.insert(
                "files".into(),
                json!(written
                    .iter()
                    .map(|p| p.file_name().map(|f| f.to_string_lossy().into_owned()))
                    .collect::<Vec<_>>()),
            );
        }
        let bytes = serde_json::to_vec_pretty(&doc).map_err(|e| failed("truth sidecar", e))?;
        crate::output::write_atomic_bytes(&sidecar, &bytes)
            .map_err(|e| failed("writing the truth sidecar", e))?;
        Ok((written, sidecar))
    }
}
