//! Writing a virtual experiment: one UFF58 file per level (H1 and coherence, labelled as
//! simulated) and the `<stem>.truth.json` sidecar stating the truth.

use super::{failed, SimulateError, Simulated};
use crate::data::FrfSet;
use serde_json::json;
use std::path::{Path, PathBuf};

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
        let stem = out
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "simulated".into());
        let ext = out
            .extension()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "uff".into());
        let dir = out.parent().map(|p| p.to_path_buf()).unwrap_or_default();
        let mut written = Vec::new();
        for lv in &self.set.levels {
            let p = dir.join(format!("{stem}_{}.{ext}", lv.name));
            let one = FrfSet {
                levels: vec![lv.clone()],
            };
            let mut datasets = crate::data::uff_frf::frf_set_datasets(&one);
            for d in &mut datasets {
                // ID line 2 says what these data are, so no reader mistakes them for a measurement.
                d.ids[1] = format!(
                    "SIMULATED by rfmlab simulate ({}, seed {})",
                    self.name, self.seed
                );
            }
            crate::data::uff58::write_uff(&p, &datasets, self.binary)
                .map_err(|e| failed("writing UFF58", e))?;
            written.push(p);
        }
        let sidecar = dir.join(format!("{stem}.truth.json"));
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
