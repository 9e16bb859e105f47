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

/// The measured data of every level ([`load_levels`]) and what the pre-flight said of it:
/// channels whose sign was flipped, files whose force level does not match their level.
pub struct LoadedLevels {
    pub levels: Vec<LevelData>,
    /// Notices and warnings that bear on the results, one sentence each.
    pub warnings: Vec<String>,
}

/// Two force levels (N) differ beyond this ratio: a level's file whose header states another
/// force than the study's level is reported, and a level's files must agree within it.
pub const FORCE_RATIO_TOL: f64 = 1.1;

/// What one file of a level says of itself: its force level and its own level name, from
/// the header (UFF58 ID lines `force_rms_n=` and load case name; CSV `# level=... force_rms_n=`).
struct FileHeader {
    path: PathBuf,
    force_rms_n: Vec<f64>,
    level_name: Option<String>,
}

fn is_csv(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("csv"))
}

/// The FRFs of level `li` of the study read from its files (UFF58 or CSV, by extension), in
/// one [`FrfLevel`], with each file's header.
fn read_level_files(
    file: &Path,
    li: usize,
    level: &crate::study::Level,
) -> Result<(FrfLevel, Vec<FileHeader>), RunError> {
    let mut headers = Vec::new();
    let mut uff = Vec::new();
    let mut csv_levels = Vec::new();
    for (fi, f) in level.files.iter().enumerate() {
        let key = format!("measurements.levels[{li}].files[{fi}]");
        if f.is_dir() {
            return Err(input_error(
                file,
                key,
                format!(
                    "{} is a folder, not a data file: give the UFF58 or CSV file inside it (relative paths are relative to the study file's folder)",
                    f.display()
                ),
            ));
        }
        if !f.is_file() {
            return Err(input_error(
                file,
                key,
                format!(
                    "data file {} does not exist; check the path (relative paths are relative to the study file's folder)",
                    f.display()
                ),
            ));
        }
        if is_csv(f) {
            let set = crate::data::csv::read_csv(f, &crate::data::csv::CsvOptions::default())?;
            let names: Vec<&str> = set.levels.iter().map(|l| l.name.as_str()).collect();
            let pick = if set.levels.len() == 1 {
                0
            } else {
                set.levels
                    .iter()
                    .position(|l| l.name == level.name)
                    .ok_or_else(|| {
                        input_error(
                            file,
                            key.clone(),
                            format!(
                                "{} holds levels {names:?} but none named {}: give a file of one level, or name the study's level as in the file",
                                f.display(),
                                level.name
                            ),
                        )
                    })?
            };
            let mut l = set.levels.into_iter().nth(pick).expect("picked level");
            headers.push(FileHeader {
                path: f.clone(),
                force_rms_n: l.force_rms_n.into_iter().collect(),
                level_name: Some(l.name.clone()),
            });
            l.name = level.name.clone();
            csv_levels.push(l);
        } else {
            let u = crate::data::read_uff(f)?;
            let mut force: Vec<f64> = Vec::new();
            let mut own = None;
            for d in &u.datasets {
                for v in d
                    .ids
                    .iter()
                    .flat_map(|s| s.split_whitespace())
                    .filter_map(|t| {
                        t.strip_prefix("force_rms_n=")
                            .and_then(|v| v.parse::<f64>().ok())
                    })
                {
                    if v.is_finite() && v > 0.0 && !force.contains(&v) {
                        force.push(v);
                    }
                }
                let name = d.ids[3].trim();
                if own.is_none() && !name.is_empty() && name != "NONE" {
                    own = Some(name.to_string());
                }
            }
            headers.push(FileHeader {
                path: f.clone(),
                force_rms_n: force,
                level_name: own,
            });
            uff.push((u, level.name.clone()));
        }
    }
    let mut parts: Vec<FrfLevel> = Vec::new();
    if !uff.is_empty() {
        let set = crate::data::uff_frf::frf_set_from_uff_files(
            &uff,
            &crate::data::UffImportOptions::default(),
        )?;
        parts.extend(set.levels.into_iter().filter(|l| l.name == level.name));
    }
    parts.extend(csv_levels);
    let mut parts = parts.into_iter();
    let mut lvl = parts.next().ok_or_else(|| {
        input_error(
            file,
            format!("measurements.levels[{li}]"),
            format!(
                "the files of level {} hold no FRFs of that level",
                level.name
            ),
        )
    })?;
    for p in parts {
        // The tolerance the UFF58 import holds one level's datasets to.
        let rel = crate::data::UffImportOptions::default().grid_rel_tol;
        if !crate::data::uff_frf::grids_match(&p.freq_hz, &lvl.freq_hz, rel) {
            return Err(input_error(
                file,
                format!("measurements.levels[{li}].files"),
                format!(
                    "the files of level {} have different frequency lines ({} lines {}..{} Hz against {} lines {}..{} Hz): resample them to one grid or put them in separate levels",
                    level.name,
                    p.freq_hz.len(),
                    p.freq_hz.first().copied().unwrap_or(f64::NAN),
                    p.freq_hz.last().copied().unwrap_or(f64::NAN),
                    lvl.freq_hz.len(),
                    lvl.freq_hz.first().copied().unwrap_or(f64::NAN),
                    lvl.freq_hz.last().copied().unwrap_or(f64::NAN),
                ),
            ));
        }
        let p = p.convert(lvl.quantity);
        lvl.force_rms_n = lvl.force_rms_n.or(p.force_rms_n);
        lvl.n_averages = lvl.n_averages.or(p.n_averages);
        lvl.channels.extend(p.channels);
    }
    crate::data::check_level(&lvl, None, None)?;
    Ok((lvl, headers))
}

/// Each level's files against the level: the force levels the files' headers state must
/// agree within a level (else an input error), and a warning when they differ from the
/// study's `force_rms_n` of the level, when a file names another level of the study, or when
/// two levels read the same file.
fn check_level_files(
    file: &Path,
    meas: &Measurements,
    headers: &[Vec<FileHeader>],
    warnings: &mut Vec<String>,
) -> Result<(), RunError> {
    let ratio = |a: f64, b: f64| a.max(b) / a.min(b);
    for (li, (level, files)) in meas.levels.iter().zip(headers).enumerate() {
        let stated: Vec<(&Path, f64)> = files
            .iter()
            .flat_map(|h| h.force_rms_n.iter().map(move |&f| (h.path.as_path(), f)))
            .collect();
        if let (Some(lo), Some(hi)) = (
            stated.iter().min_by(|a, b| a.1.total_cmp(&b.1)),
            stated.iter().max_by(|a, b| a.1.total_cmp(&b.1)),
        ) {
            if ratio(lo.1, hi.1) > FORCE_RATIO_TOL {
                let which = if lo.0 == hi.0 {
                    format!(
                        "{} states both force_rms_n={} and {} N",
                        lo.0.display(),
                        lo.1,
                        hi.1
                    )
                } else {
                    format!(
                        "{} states force_rms_n={} N and {} states {} N",
                        lo.0.display(),
                        lo.1,
                        hi.0.display(),
                        hi.1
                    )
                };
                return Err(input_error(
                    file,
                    format!("measurements.levels[{li}].files"),
                    format!(
                        "the files of level {} disagree on the excitation level ({which}, {:.1}x apart): one level's files must come from one force level; give each force level its own [[measurements.levels]]",
                        level.name,
                        ratio(lo.1, hi.1)
                    ),
                ));
            }
        }
        let others = || {
            meas.levels
                .iter()
                .enumerate()
                .filter(move |(lj, _)| *lj != li)
                .map(|(_, l)| l)
        };
        if let (Some(want), Some(&(path, got))) = (level.force_rms_n, stated.first()) {
            if want > 0.0 && ratio(want, got) > FORCE_RATIO_TOL {
                let like = others()
                    .find(|o| {
                        o.force_rms_n
                            .is_some_and(|f| f > 0.0 && ratio(f, got) <= FORCE_RATIO_TOL)
                    })
                    .map(|o| {
                        format!(
                            "; it looks like level {}'s data (force_rms_n = {} N)",
                            o.name,
                            o.force_rms_n.unwrap_or_default()
                        )
                    })
                    .unwrap_or_default();
                warnings.push(format!(
                    "measurements.levels[{li}]: level {} has force_rms_n = {want} N but its file {} states force_rms_n={got} N ({:.1}x apart){like}: check that the file belongs to this level",
                    level.name,
                    path.display(),
                    ratio(want, got)
                ));
            }
        }
        for h in files {
            if let Some(own) = &h.level_name {
                if *own != level.name && others().any(|o| o.name == *own) {
                    warnings.push(format!(
                        "measurements.levels[{li}]: the file {} names level {own} in its header but is given as level {}: check that it belongs to this level",
                        h.path.display(),
                        level.name
                    ));
                }
            }
            for (lj, o) in meas.levels.iter().enumerate().skip(li + 1) {
                if o.files.contains(&h.path) {
                    warnings.push(format!(
                        "measurements.levels[{li}] and [{lj}]: levels {} and {} read the same file {}",
                        level.name,
                        o.name,
                        h.path.display()
                    ));
                }
            }
        }
    }
    Ok(())
}

/// Load and check the measured data of every level; returns one [`LevelData`] per level.
/// [`load_checked`] with its warnings dropped, every point of the model required.
pub fn load_levels(
    measurements: Option<&Measurements>,
    built: &BuiltModel,
    file: &Path,
) -> Result<Vec<LevelData>, RunError> {
    load_checked(measurements, built, &[], file).map(|l| l.levels)
}

/// Load and check the measured data of every level against the study (the data part of the
/// pre-flight, [`crate::stage::preflight`]): each level's files against the level (force
/// level, level name), the direction of every channel against its point (the same axis with
/// the opposite sign is flipped, with a notice; another axis is an input error), and every
/// point of the model measured unless `points` marks it optional.
pub fn load_checked(
    measurements: Option<&Measurements>,
    built: &BuiltModel,
    points: &[crate::study::Point],
    file: &Path,
) -> Result<LoadedLevels, RunError> {
    let meas = measurements.ok_or_else(|| {
        input_error(
            file,
            "measurements",
            "no [measurements] section: add [[measurements.levels]] with name and files",
        )
    })?;
    let exc_point = &built.model.points[built.excitation];
    let optional = |id: u32, axis: crate::common::Axis| {
        points
            .iter()
            .any(|p| p.id == id && p.direction.axis == axis && p.optional)
    };
    let point_key = |id: u32, axis: crate::common::Axis| {
        points
            .iter()
            .position(|p| p.id == id && p.direction.axis == axis)
            .map(|i| format!("structure.points[{i}].direction"))
            .unwrap_or_else(|| "structure.points".into())
    };
    let mut warnings = Vec::new();
    let mut read = Vec::new();
    let mut headers = Vec::new();
    for (li, level) in meas.levels.iter().enumerate() {
        let (lvl, h) = read_level_files(file, li, level)?;
        read.push(lvl);
        headers.push(h);
    }
    check_level_files(file, meas, &headers, &mut warnings)?;
    let mut out = Vec::new();
    for (level, lvl) in meas.levels.iter().zip(&read) {
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
        // A channel as the messages name it: "3+x/2+y (FILE dataset N)".
        let label = |ch: &crate::data::Channel| {
            let source = ch
                .source
                .as_ref()
                .map(|(f, d)| format!("{f} dataset {d}"))
                .unwrap_or_else(|| "its file".into());
            format!(
                "{}{}/{}{} ({source})",
                ch.response_id, ch.response_dir, ch.reference_id, ch.reference_dir
            )
        };
        // Channels: reference = the excitation point along its axis (a reference along
        // another axis is another column of the FRF matrix), response = one of the model's
        // points along its axis.
        let mut outputs = Vec::new();
        let mut ids = Vec::new();
        let mut chans = Vec::new();
        let mut other_axis = Vec::new();
        for ch in &lvl.channels {
            if ch.reference_id != exc_point.id || ch.reference_dir.axis != exc_point.direction.axis
            {
                continue;
            }
            if let Some(sel) = &meas.channels {
                if !sel.contains(&ch.response_id) {
                    continue;
                }
            }
            let Some(k) =
                built.model.points.iter().position(|p| {
                    p.id == ch.response_id && p.direction.axis == ch.response_dir.axis
                })
            else {
                other_axis.push(ch);
                continue;
            };
            if outputs.contains(&k) {
                continue;
            }
            // Sign: a response (or force) measured opposite to the model's direction flips.
            let point = &built.model.points[k];
            let sign = f64::from(ch.response_dir.sign * point.direction.sign)
                * f64::from(ch.reference_dir.sign * exc_point.direction.sign);
            if sign < 0.0 {
                warnings.push(format!(
                    "level {}: channel {} is measured opposite to point {}{} / excitation {}{} of the study: its sign is flipped",
                    level.name,
                    label(ch),
                    point.id,
                    point.direction,
                    exc_point.id,
                    exc_point.direction
                ));
            }
            outputs.push(k);
            ids.push(ch.response_id);
            chans.push((ch, sign));
        }
        // Every point of the model measured (unless optional or left out by
        // measurements.channels); a channel along another axis cannot stand for it.
        let mut missing = Vec::new();
        for (k, p) in built.model.points.iter().enumerate() {
            if outputs.contains(&k)
                || optional(p.id, p.direction.axis)
                || meas.channels.as_ref().is_some_and(|s| !s.contains(&p.id))
            {
                continue;
            }
            if let Some(ch) = other_axis.iter().find(|c| c.response_id == p.id) {
                return Err(input_error(
                    file,
                    point_key(p.id, p.direction.axis),
                    format!(
                        "level {}: channel {} is measured along {} but point {} is declared {} (with no channel along that axis): a response along another axis cannot stand for it. Set the point's direction to the measured one (direction = \"{}\"), give the data measured along {}, or mark the point optional = true",
                        level.name,
                        label(ch),
                        ch.response_dir,
                        p.id,
                        p.direction,
                        ch.response_dir,
                        p.direction
                    ),
                ));
            }
            missing.push(p.id);
        }
        if !missing.is_empty() && !outputs.is_empty() {
            let files: Vec<String> = level
                .files
                .iter()
                .map(|f| f.display().to_string())
                .collect();
            return Err(input_error(
                file,
                "structure.points",
                format!(
                    "level {}: point(s) {missing:?} have no channel in the level's files ({}), which hold responses {ids:?} to the excitation at point {}: give their data, remove the points, or mark them optional = true in [[structure.points]]",
                    level.name,
                    files.join(", "),
                    exc_point.id
                ),
            ));
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
    Ok(LoadedLevels {
        levels: out,
        warnings,
    })
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
