//! Loading the measured data of every level ([`LevelData`]): the FRF files (UFF58 or CSV) on
//! the study's band, converted to accelerance, with the excitation channel checked
//! ([`crate::data::check_level`]), the coherence and block count when the files carry them,
//! and the truth of simulated data.

use super::{input_error, LevelData, LevelTruth, RunError};
use crate::common::C64;
use crate::data::{DataError, FrfLevel, Quantity};
use crate::study::build::BuiltModel;
use crate::study::Measurements;
use std::path::{Path, PathBuf};

/// The truth of `level` in a sidecar written by `rfmlab simulate` (levels named by `"level"`),
/// or in the `truth.json` of an independent virtual experiment (studies/data/virtual: levels
/// numbered by `"id"` with their `"force_rms_N"`). A numbered level is the study's level when
/// its force RMS equals the study level's `force_rms_n` (to 1e-6), or, without a force RMS in
/// the study, when the study level is named `L<id>`.
fn read_truth(
    file: &Path,
    path: &Path,
    level: &crate::study::Level,
) -> Result<Option<LevelTruth>, RunError> {
    let name = level.name.as_str();
    let bad = |m: String| {
        input_error(
            file,
            "measurements.truth",
            format!("{}: {m}", path.display()),
        )
    };
    let text = std::fs::read_to_string(path).map_err(|e| bad(e.to_string()))?;
    let v: serde_json::Value = serde_json::from_str(&text).map_err(|e| bad(e.to_string()))?;
    let Some(levels) = v.get("levels").and_then(|l| l.as_array()) else {
        return Err(bad(
            "no \"levels\" array: give the .truth.json of `rfmlab simulate` or the truth.json of a virtual experiment".into(),
        ));
    };
    let numbered = |l: &serde_json::Value| {
        let Some(id) = l.get("id").and_then(|n| n.as_u64()) else {
            return false;
        };
        match (
            level.force_rms_n,
            l.get("force_rms_N").and_then(|f| f.as_f64()),
        ) {
            (Some(a), Some(b)) => (a - b).abs() <= 1e-6 * b.abs(),
            _ => name == format!("L{id}"),
        }
    };
    let Some(l) = levels
        .iter()
        .find(|l| l.get("level").and_then(|n| n.as_str()) == Some(name))
        .or_else(|| levels.iter().find(|l| numbered(l)))
    else {
        return Ok(None);
    };
    let law = l
        .get("law")
        .and_then(|x| x.as_str())
        .unwrap_or_default()
        .to_string();
    let m = crate::material::model_from_name(&law, None)
        .map_err(|e| bad(format!("level {name}: {e}")))?;
    let mut params = Vec::new();
    for p in m.param_names() {
        let x = l
            .get("params")
            .and_then(|ps| ps.get(&p))
            .and_then(|x| x.as_f64())
            .ok_or_else(|| bad(format!("level {name}: no parameter {p} of {law}")))?;
        params.push(x);
    }
    Ok(Some(LevelTruth {
        law,
        model: m.into(),
        params,
    }))
}

const TWO_PI: f64 = 2.0 * std::f64::consts::PI;

/// Convert an FRF value of `q` to accelerance at `freq_hz` (H' = -w^2 H = j w Y).
fn to_accelerance(h: C64, freq_hz: f64, q: Quantity) -> C64 {
    let w = TWO_PI * freq_hz;
    match q {
        Quantity::Accelerance => h,
        Quantity::Mobility => C64::new(0.0, w) * h,
        Quantity::Receptance => -w * w * h,
    }
}

/// Load and check the measured data of every level; returns one [`LevelData`] per level.
pub fn load_levels(
    measurements: Option<&Measurements>,
    built: &BuiltModel,
    file: &Path,
) -> Result<Vec<LevelData>, RunError> {
    let meas = measurements.ok_or_else(|| {
        input_error(
            file,
            "measurements",
            "no [measurements] section: add [[measurements.levels]] with name and files",
        )
    })?;
    let exc_point = &built.model.points[built.excitation];
    let mut out = Vec::new();
    for (li, level) in meas.levels.iter().enumerate() {
        for (fi, f) in level.files.iter().enumerate() {
            if !f.is_file() {
                return Err(input_error(
                    file,
                    format!("measurements.levels[{li}].files[{fi}]"),
                    format!(
                        "data file {} does not exist; check the path (relative paths are relative to the study file's folder)",
                        f.display()
                    ),
                ));
            }
        }
        let files: Vec<(PathBuf, String)> = level
            .files
            .iter()
            .map(|f| (f.clone(), level.name.clone()))
            .collect();
        let set = crate::data::frf_set_from_uff(&files, &crate::data::UffImportOptions::default())?;
        let lvl: &FrfLevel = set
            .levels
            .iter()
            .find(|l| l.name == level.name)
            .ok_or_else(|| {
                input_error(
                    file,
                    format!("measurements.levels[{li}]"),
                    format!(
                        "the files of level {} hold no FRFs of that level",
                        level.name
                    ),
                )
            })?;
        crate::data::check_level(lvl, Some((exc_point.id, exc_point.direction)), meas.band_hz)
            .map_err(|e| {
                RunError::Data(DataError {
                    message: format!(
                        "{} (study {}: measurements.band_hz / structure.excitation)",
                        e.message,
                        file.display()
                    ),
                    ..e
                })
            })?;
        let (lo, hi) = meas.band_hz.unwrap_or((0.0, f64::INFINITY));
        let lines: Vec<usize> = (0..lvl.freq_hz.len())
            .filter(|&l| lvl.freq_hz[l] > 0.0 && lvl.freq_hz[l] >= lo && lvl.freq_hz[l] <= hi)
            .collect();
        if lines.is_empty() {
            return Err(input_error(
                file,
                "measurements.band_hz",
                format!(
                    "no positive frequency line of level {} in the band",
                    level.name
                ),
            ));
        }
        // Channels: reference = excitation point, response among the model's points.
        let mut outputs = Vec::new();
        let mut ids = Vec::new();
        let mut chans = Vec::new();
        for ch in &lvl.channels {
            if ch.reference_id != exc_point.id {
                continue;
            }
            if let Some(sel) = &meas.channels {
                if !sel.contains(&ch.response_id) {
                    continue;
                }
            }
            let Some(k) = built
                .model
                .points
                .iter()
                .position(|p| p.id == ch.response_id)
            else {
                continue;
            };
            if outputs.contains(&k) {
                continue;
            }
            // Sign: a channel measured in the opposite direction of the model's point flips.
            let sign = if ch.response_dir == built.model.points[k].direction {
                1.0
            } else {
                -1.0
            };
            outputs.push(k);
            ids.push(ch.response_id);
            chans.push((ch, sign));
        }
        if outputs.is_empty() {
            return Err(input_error(file, "measurements.channels", {
                let mut held: Vec<String> = lvl
                    .channels
                    .iter()
                    .map(|c| format!("{}->{}", c.reference_id, c.response_id))
                    .collect();
                held.dedup();
                let pts: Vec<u32> = built.model.points.iter().map(|p| p.id).collect();
                format!(
                        "level {}: no channel with reference point {} and a response at one of the structure's points {pts:?}; the files hold (reference->response) {}: match structure.points / structure.excitation to these ids",
                        level.name,
                        exc_point.id,
                        held.join(", ")
                    )
            }));
        }
        let n_out = outputs.len();
        let mut acc = vec![C64::new(0.0, 0.0); lines.len() * n_out];
        for (ll, &l) in lines.iter().enumerate() {
            for (k, (ch, sign)) in chans.iter().enumerate() {
                acc[ll * n_out + k] =
                    to_accelerance(ch.values[l], lvl.freq_hz[l], lvl.quantity) * *sign;
            }
        }
        let freq_hz: Vec<f64> = lines.iter().map(|&l| lvl.freq_hz[l]).collect();
        let coherence = if chans.iter().all(|(ch, _)| ch.coherence.is_some()) {
            let mut c = vec![0.0; lines.len() * n_out];
            for (ll, &l) in lines.iter().enumerate() {
                for (k, (ch, _)) in chans.iter().enumerate() {
                    c[ll * n_out + k] = ch.coherence.as_ref().map_or(f64::NAN, |v| v[l]);
                }
            }
            Some(c)
        } else {
            None
        };
        out.push(LevelData {
            coherence,
            n_averages: lvl.n_averages,
            measurement: None,
            name: level.name.clone(),
            column: crate::rfm::MeasuredColumn {
                omega_rad_s: freq_hz.iter().map(|f| TWO_PI * f).collect(),
                input: built.excitation,
                outputs,
                accelerance: acc,
            },
            freq_hz,
            response_ids: ids,
            reference_id: exc_point.id,
            truth: match &meas.truth {
                Some(p) => read_truth(file, p, level)?,
                None => None,
            },
        });
    }
    Ok(out)
}

/// Lines of the lowest clear peak of the summed magnitude (a local maximum above a tenth of
/// the largest), in Hz.
pub fn first_peak_hz(level: &LevelData) -> Option<f64> {
    let n_out = level.column.outputs.len().max(1);
    let mag: Vec<f64> = (0..level.freq_hz.len())
        .map(|l| {
            (0..n_out)
                .map(|k| level.column.accelerance[l * n_out + k].norm())
                .sum::<f64>()
        })
        .collect();
    let top = mag.iter().cloned().fold(0.0, f64::max);
    if !(top > 0.0) || mag.len() < 3 {
        return None;
    }
    (1..mag.len() - 1)
        .find(|&l| mag[l] >= mag[l - 1] && mag[l] > mag[l + 1] && mag[l] > 0.1 * top)
        .map(|l| level.freq_hz[l])
}

/// The band (Hz) of the levels' lines.
pub fn band_of(levels: &[LevelData]) -> (f64, f64) {
    let lo = levels
        .iter()
        .flat_map(|l| l.freq_hz.first().copied())
        .fold(f64::INFINITY, f64::min);
    let hi = levels
        .iter()
        .flat_map(|l| l.freq_hz.last().copied())
        .fold(0.0, f64::max);
    (lo, hi)
}
