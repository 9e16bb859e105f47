//! Checks on measured FRF data at load time: one grid per level with strictly increasing,
//! finite lines; finite values; one value (and coherence) per line; no duplicate channel;
//! the excitation channel present; the requested band covered. Every failure is a
//! [`DataError`] naming the file and dataset (from the channel's source) and what to do.

use crate::common::Direction;
use crate::data::uff58::{Ordinate, Uff58Dataset};
use crate::data::{DataError, FrfLevel};

/// A coherence may exceed 1 by rounding in the file by this much.
pub const COHERENCE_SLACK: f64 = 1e-6;

/// Check the header and values of one UFF58 dataset holding an FRF or a coherence (`file`
/// names the file): at least one point, a positive and finite line spacing on an even grid,
/// finite abscissa and values, a coherence within [0, 1]. Errors name the file, the dataset
/// and the line (record 7 for the header, the dataset's first line for values).
pub fn check_dataset(file: &str, d: &Uff58Dataset, coherence: bool) -> Result<(), DataError> {
    let record7 = d.line + 8;
    let err = |line: usize, m: String| Err(DataError::at(file, Some(d.index), Some(line), m));
    if d.num_pts == 0 {
        return err(
            record7,
            "record 7 says the dataset holds 0 points: give the number of frequency lines it holds, or remove the dataset".into(),
        );
    }
    if d.even && !(d.x0.is_finite() && d.dx.is_finite() && d.dx > 0.0) {
        return err(
            record7,
            format!(
                "record 7: the first line {} Hz and line spacing {} Hz must be finite numbers with a spacing above 0 (frequency lines increase); fix the header",
                d.x0, d.dx
            ),
        );
    }
    if d.even && d.x0 < 0.0 {
        return err(
            record7,
            format!(
                "record 7: the first line is at {} Hz, below 0 Hz: frequencies of an FRF are 0 Hz or above; fix the header's starting frequency",
                d.x0
            ),
        );
    }
    let at = |k: usize| {
        d.x.get(k)
            .map_or(String::new(), |f| format!(" (at {f} Hz)"))
    };
    // record 12, the values, starts 13 lines below the dataset's "-1"
    let values_line = d.line + 13;
    if let Some(k) = d.x.iter().position(|x| !x.is_finite()) {
        return err(
            values_line,
            format!(
                "abscissa value {} is {}: every frequency must be a finite number",
                k + 1,
                d.x[k]
            ),
        );
    }
    if let Some(k) = d.x.iter().position(|x| *x < 0.0) {
        return err(
            values_line,
            format!(
                "abscissa value {} is {} Hz, below 0 Hz: frequencies of an FRF are 0 Hz or above",
                k + 1,
                d.x[k]
            ),
        );
    }
    let bad = match &d.values {
        Ordinate::Real(v) => v.iter().position(|x| !x.is_finite()),
        Ordinate::Complex(v) => v
            .iter()
            .position(|z| !(z.re.is_finite() && z.im.is_finite())),
    };
    if let Some(k) = bad {
        return err(
            values_line,
            format!("value {} of the values starting at this line{} is not a finite number (NaN or Inf): fix or drop that frequency line", k + 1, at(k)),
        );
    }
    if coherence {
        let re: Vec<f64> = match &d.values {
            Ordinate::Real(v) => v.clone(),
            Ordinate::Complex(v) => v.iter().map(|z| z.re).collect(),
        };
        if let Some(k) = re
            .iter()
            .position(|g| !(-COHERENCE_SLACK..=1.0 + COHERENCE_SLACK).contains(g))
        {
            return err(
                values_line,
                format!("coherence value {} of the values starting at this line{} is {}: a coherence lies within [0, 1]; fix the file", k + 1, at(k), re[k]),
            );
        }
    }
    Ok(())
}

fn where_of(level: &FrfLevel, ch: Option<usize>) -> (String, Option<usize>) {
    let c = ch
        .and_then(|i| level.channels.get(i))
        .or(level.channels.first());
    match c.and_then(|c| c.source.clone()) {
        Some((f, d)) if ch.is_some() => (f, Some(d)),
        Some((f, _)) => (f, None),
        None => (format!("level {}", level.name), None),
    }
}

/// Check one level. `excitation` is the (point, direction) the level must contain as a
/// reference (directions compared by axis); `band_hz` the band the data must cover (relative
/// tolerance 1e-9 of the band edge).
pub fn check_level(
    level: &FrfLevel,
    excitation: Option<(u32, Direction)>,
    band_hz: Option<(f64, f64)>,
) -> Result<(), DataError> {
    let fail = |ch: Option<usize>, m: String| {
        let (f, d) = where_of(level, ch);
        Err(DataError::at(
            f,
            d,
            None,
            format!("level {}: {m}", level.name),
        ))
    };
    let f = &level.freq_hz;
    if f.is_empty() {
        return fail(None, "no frequency lines; the data set is empty".into());
    }
    if level.channels.is_empty() {
        return fail(
            None,
            "no FRF channels; check that the files hold FRFs (function type 4)".into(),
        );
    }
    if let Some(k) = f.iter().position(|x| !x.is_finite()) {
        return fail(None, format!("frequency line {k} is {}; remove it", f[k]));
    }
    if let Some(k) = f.windows(2).position(|w| w[1] <= w[0]) {
        return fail(
            None,
            format!("frequency lines are not strictly increasing at line {} ({} Hz then {} Hz); sort the data and remove repeats", k + 1, f[k], f[k + 1]),
        );
    }
    for (i, c) in level.channels.iter().enumerate() {
        let name = format!(
            "channel {}{}/{}{}",
            c.response_id, c.response_dir, c.reference_id, c.reference_dir
        );
        if c.values.len() != f.len() {
            return fail(
                Some(i),
                format!(
                    "{name} has {} values for {} frequency lines (one grid per level); resample it",
                    c.values.len(),
                    f.len()
                ),
            );
        }
        if let Some(k) = c
            .values
            .iter()
            .position(|h| !(h.re.is_finite() && h.im.is_finite()))
        {
            return fail(Some(i), format!("{name} has a non-finite value at {} Hz; drop that line (e.g. 0 Hz) or fix the data", f[k]));
        }
        if let Some(coh) = &c.coherence {
            if coh.len() != f.len() {
                return fail(
                    Some(i),
                    format!(
                        "{name}: coherence has {} values for {} lines",
                        coh.len(),
                        f.len()
                    ),
                );
            }
            if let Some(k) = coh.iter().position(|g| !g.is_finite()) {
                return fail(
                    Some(i),
                    format!("{name}: coherence is not finite at {} Hz", f[k]),
                );
            }
            if let Some(k) = coh
                .iter()
                .position(|g| !(-COHERENCE_SLACK..=1.0 + COHERENCE_SLACK).contains(g))
            {
                return fail(
                    Some(i),
                    format!(
                        "{name}: coherence is {} at {} Hz; a coherence lies within [0, 1]: fix the data",
                        coh[k], f[k]
                    ),
                );
            }
        }
        for o in level.channels.iter().take(i) {
            if o.response_id == c.response_id
                && o.response_dir.axis == c.response_dir.axis
                && o.reference_id == c.reference_id
                && o.reference_dir.axis == c.reference_dir.axis
            {
                let other = o
                    .source
                    .as_ref()
                    .map(|(f, d)| format!(" (also in {f} dataset {d})"))
                    .unwrap_or_default();
                return fail(
                    Some(i),
                    format!("duplicate {name}{other}; keep one of them"),
                );
            }
        }
    }
    if let Some((p, d)) = excitation {
        if !level
            .channels
            .iter()
            .any(|c| c.reference_id == p && c.reference_dir.axis == d.axis)
        {
            return fail(None, format!("no channel has the excitation point {p}{d} as reference; check the study's excitation point or the files' reference DOF"));
        }
    }
    if let Some((lo, hi)) = band_hz {
        let (f0, f1) = (f[0], f[f.len() - 1]);
        let tol = 1e-9 * hi.abs().max(1.0);
        if f0 > lo + tol || f1 < hi - tol {
            return fail(None, format!("the data covers {f0}..{f1} Hz but the band {lo}..{hi} Hz is requested; narrow the band or supply wider data"));
        }
    }
    Ok(())
}
