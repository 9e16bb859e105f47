//! Material-level study files (`rfmlab material STUDY.toml`): measured E'(w) and E''(w) in a CSV
//! file, fitted without a structure by the loop of [`crate::material_fit`].
//!
//! ```toml
//! [study]
//! name = "dma_tensile"              # results/<name> unless output_dir is given
//! kind = "material"                 # optional; must be "material" when given
//! seed = 1
//!
//! [material_data]
//! file = "data/dma/tensile_master_Tref_25C.csv"   # relative to this file
//! frequency_column = "f_Hz"
//! storage_column = "E_stor_MPa"
//! loss_column = "E_loss_MPa"
//! frequency_unit = "Hz"             # "Hz" or "rad/s"
//! modulus_unit = "MPa"              # "Pa", "kPa", "MPa" or "GPa"
//! skip_rows = 0                     # rows after the header to skip (e.g. a units row)
//! band_hz = [1e-5, 1e18]            # optional: only points inside
//!
//! [material_fit]                    # optional, defaults shown
//! start = "model4"                  # "model4", "fractional_zener" or "generalized_maxwell"
//! start_branches = 1                # for generalized_maxwell
//! max_branches = 30
//! min_evidence_gain = 2.3           # nats
//! try_fractional = true
//! kk_per_decade = 6.0
//! kk_threshold = 3.0
//! causal_floor_ratio = 1.05
//! n_starts = 4
//! max_iters = 500
//! figures = true
//! ```
//!
//! The CSV has one header row naming the columns (a UTF-8 byte-order mark is ignored);
//! values are separated by commas. Every error names the file, the key and the fix.

use super::{resolve, StudyError};
use crate::material_fit::{LoopParams, MasterCurve, RelaxationLaw};
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// A material study as written (public so that the documentation's key list can be checked
/// against it; fields stay private).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawMaterialStudy {
    #[serde(default)]
    study: RawMeta,
    material_data: Option<RawData>,
    material_fit: Option<RawFit>,
}

#[derive(Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawMeta {
    name: Option<String>,
    description: Option<String>,
    kind: Option<String>,
    seed: Option<u64>,
    output_dir: Option<String>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawData {
    file: String,
    frequency_column: String,
    storage_column: String,
    loss_column: String,
    frequency_unit: Option<String>,
    modulus_unit: Option<String>,
    skip_rows: Option<usize>,
    band_hz: Option<[f64; 2]>,
}

#[derive(Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawFit {
    start: Option<String>,
    start_branches: Option<usize>,
    max_branches: Option<usize>,
    min_evidence_gain: Option<f64>,
    try_fractional: Option<bool>,
    kk_per_decade: Option<f64>,
    kk_threshold: Option<f64>,
    causal_floor_ratio: Option<f64>,
    n_starts: Option<usize>,
    max_iters: Option<u64>,
    figures: Option<bool>,
}

/// A validated material study.
#[derive(Clone, Debug)]
pub struct MaterialStudy {
    pub file: PathBuf,
    pub name: String,
    pub description: String,
    pub seed: u64,
    pub output_dir: PathBuf,
    pub data_file: PathBuf,
    pub curve: MasterCurve,
    pub params: LoopParams,
    pub figures: bool,
}

fn err(file: &Path, key: &str, message: impl Into<String>) -> StudyError {
    StudyError {
        file: file.display().to_string(),
        key: key.to_string(),
        message: message.into(),
    }
}

/// Whether a study file is a material study (`[material_data]` present or `kind = "material"`),
/// without validating it.
pub fn is_material_study(text: &str) -> bool {
    match toml::from_str::<toml::Table>(text) {
        Ok(t) => {
            t.contains_key("material_data")
                || t.get("study")
                    .and_then(|s| s.get("kind"))
                    .and_then(|k| k.as_str())
                    == Some("material")
        }
        Err(_) => false,
    }
}

/// Read and validate a material study file and its data.
pub fn load_material(path: &Path) -> Result<MaterialStudy, StudyError> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| err(path, "(file)", format!("cannot read the study file: {e}")))?;
    parse_material(path, &text)
}

/// Validate the text of a material study file (`path` names it in errors and anchors relative
/// paths) and read its data.
pub fn parse_material(path: &Path, text: &str) -> Result<MaterialStudy, StudyError> {
    let raw: RawMaterialStudy =
        toml::from_str(text).map_err(|e| super::toml_error(path, text, &e))?;
    if let Some(k) = &raw.study.kind {
        if k != "material" {
            return Err(err(path, "study.kind", format!("'{k}': a material study has kind = \"material\" (structural studies run with `rfmlab run`)")));
        }
    }
    let name = raw.study.name.clone().unwrap_or_else(|| {
        path.file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "material".into())
    });
    if name.is_empty() || name.contains(['/', '\\']) {
        return Err(err(
            path,
            "study.name",
            format!("'{name}': give a non-empty name without '/'"),
        ));
    }
    let output_dir = raw
        .study
        .output_dir
        .as_ref()
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new("results").join(&name));
    let data = raw.material_data.ok_or_else(|| {
        err(path, "material_data", "missing: add a [material_data] section with file, frequency_column, storage_column and loss_column")
    })?;
    let f_scale = match data.frequency_unit.as_deref().unwrap_or("Hz") {
        "Hz" => 1.0,
        "rad/s" => 1.0 / std::f64::consts::TAU,
        u => {
            return Err(err(
                path,
                "material_data.frequency_unit",
                format!("'{u}': use \"Hz\" or \"rad/s\""),
            ))
        }
    };
    let m_scale = match data.modulus_unit.as_deref().unwrap_or("Pa") {
        "Pa" => 1.0,
        "kPa" => 1e3,
        "MPa" => 1e6,
        "GPa" => 1e9,
        u => {
            return Err(err(
                path,
                "material_data.modulus_unit",
                format!("'{u}': use \"Pa\", \"kPa\", \"MPa\" or \"GPa\""),
            ))
        }
    };
    let data_file = resolve(path, &data.file);
    let key_file = "material_data.file";
    let csv = std::fs::read_to_string(&data_file).map_err(|e| {
        err(
            path,
            key_file,
            format!("cannot read '{}': {e}", data_file.display()),
        )
    })?;
    let mut lines = csv.lines().filter(|l| !l.trim().is_empty());
    let header = lines.next().ok_or_else(|| {
        err(
            path,
            key_file,
            format!("'{}' is empty", data_file.display()),
        )
    })?;
    let cols: Vec<String> = header
        .trim_start_matches('\u{feff}')
        .split(',')
        .map(|s| s.trim().trim_matches('"').to_string())
        .collect();
    let find = |key: &str, want: &str| -> Result<usize, StudyError> {
        cols.iter().position(|c| c == want).ok_or_else(|| {
            err(
                path,
                &format!("material_data.{key}"),
                format!(
                    "column '{want}' is not in '{}'; its columns are: {}",
                    data_file.display(),
                    cols.join(", ")
                ),
            )
        })
    };
    let jf = find("frequency_column", &data.frequency_column)?;
    let js = find("storage_column", &data.storage_column)?;
    let jl = find("loss_column", &data.loss_column)?;
    let (mut f, mut s, mut l) = (Vec::new(), Vec::new(), Vec::new());
    let band = data.band_hz;
    if let Some([lo, hi]) = band {
        if !(lo >= 0.0 && hi > lo) {
            return Err(err(
                path,
                "material_data.band_hz",
                format!("[{lo}, {hi}]: give [low, high] in Hz with 0 <= low < high"),
            ));
        }
    }
    for (row, line) in lines.skip(data.skip_rows.unwrap_or(0)).enumerate() {
        let v: Vec<&str> = line.split(',').map(str::trim).collect();
        let get = |j: usize, key: &str, scale: f64| -> Result<f64, StudyError> {
            let t = v.get(j).copied().unwrap_or("");
            let x: f64 = t.parse().map_err(|_| {
                err(
                    path,
                    &format!("material_data.{key}"),
                    format!(
                        "'{}' data row {}: '{t}' is not a number (set skip_rows for a units row)",
                        data_file.display(),
                        row + 1
                    ),
                )
            })?;
            if !(x.is_finite() && x > 0.0) {
                return Err(err(
                    path,
                    &format!("material_data.{key}"),
                    format!(
                        "'{}' data row {}: {x} is not positive; moduli and frequencies must be positive (the fit is on their logarithms): remove or correct the row",
                        data_file.display(),
                        row + 1
                    ),
                ));
            }
            Ok(x * scale)
        };
        let fr = get(jf, "frequency_column", f_scale)?;
        let st = get(js, "storage_column", m_scale)?;
        let lo = get(jl, "loss_column", m_scale)?;
        if let Some([a, b]) = band {
            if fr < a || fr > b {
                continue;
            }
        }
        f.push(fr);
        s.push(st);
        l.push(lo);
    }
    let curve = MasterCurve::new(f, s, l)
        .map_err(|e| err(path, key_file, format!("'{}': {e}", data_file.display())))?;
    let fit = raw.material_fit.unwrap_or_default();
    let mut params = LoopParams::default();
    let nb = fit.start_branches;
    params.start = match fit.start.as_deref().unwrap_or("model4") {
        "model4" => RelaxationLaw::model4(),
        "fractional_zener" => RelaxationLaw::fractional_zener(),
        "generalized_maxwell" => RelaxationLaw::generalized_maxwell(nb.unwrap_or(1)),
        s => {
            return Err(err(
                path,
                "material_fit.start",
                format!("'{s}': use \"model4\", \"fractional_zener\" or \"generalized_maxwell\""),
            ))
        }
    };
    if nb.is_some() && fit.start.as_deref() != Some("generalized_maxwell") {
        return Err(err(
            path,
            "material_fit.start_branches",
            "only start = \"generalized_maxwell\" takes a number of branches; remove the key",
        ));
    }
    if nb == Some(0) {
        return Err(err(
            path,
            "material_fit.start_branches",
            "0: use at least 1",
        ));
    }
    if let Some(v) = fit.max_branches {
        if v < params.start.n_branches || v > 200 {
            return Err(err(
                path,
                "material_fit.max_branches",
                format!(
                    "{v}: use a number between the start law's branches ({}) and 200",
                    params.start.n_branches
                ),
            ));
        }
        params.max_branches = v;
    }
    let pos = |key: &str, v: Option<f64>, lo: f64, hi: f64| -> Result<Option<f64>, StudyError> {
        match v {
            Some(x) if !(x >= lo && x <= hi) => Err(err(
                path,
                &format!("material_fit.{key}"),
                format!("{x}: use a value in [{lo}, {hi}]"),
            )),
            other => Ok(other),
        }
    };
    if let Some(v) = pos("min_evidence_gain", fit.min_evidence_gain, 0.0, 1e6)? {
        params.min_evidence_gain = v;
    }
    if let Some(v) = pos("kk_per_decade", fit.kk_per_decade, 0.5, 10.0)? {
        params.kk_per_decade = v;
    }
    if let Some(v) = pos("kk_threshold", fit.kk_threshold, 1.0, 100.0)? {
        params.kk_threshold = v;
    }
    if let Some(v) = pos("causal_floor_ratio", fit.causal_floor_ratio, 1.0, 10.0)? {
        params.causal_floor_ratio = v;
    }
    if let Some(v) = fit.try_fractional {
        params.try_fractional = v;
    }
    if let Some(v) = fit.n_starts {
        if v > 1000 {
            return Err(err(
                path,
                "material_fit.n_starts",
                format!("{v}: use at most 1000"),
            ));
        }
        params.map.n_starts = v;
    }
    if let Some(v) = fit.max_iters {
        if v == 0 {
            return Err(err(path, "material_fit.max_iters", "0: use at least 1"));
        }
        params.map.max_iters = v;
    }
    let seed = raw.study.seed.unwrap_or(0);
    params.map.seed = seed;
    Ok(MaterialStudy {
        file: path.to_path_buf(),
        name,
        description: raw.study.description.unwrap_or_default(),
        seed,
        output_dir,
        data_file,
        curve,
        params,
        figures: fit.figures.unwrap_or(true),
    })
}
