//! The `[inference.across_levels]` and `[inference.basins]` sub-sections: the comparison across
//! excitation levels and the initial-value (basin) study.
//!
//! ```toml
//! [inference.across_levels]
//! freq_hz = [10.0, 100.0, 300.0]   # chosen frequencies of the level change (besides the first two modes)
//! shared = true                    # evidence of law parameters shared by both levels (Laplace); default true
//! tmcmc = false                    # also TMCMC on the shared posterior (costs one more TMCMC run per model)
//!
//! [inference.basins]               # off unless given
//! starts = 200                     # space-filling starts over the prior box (plus the initial values)
//! rfm = true                       # the deterministic RFM from the same starts too
//! tolerance_sd = 0.1               # end points closer than this many Laplace sd (every coordinate) share a basin
//! ```

use super::validate::Ctx;
use super::StudyError;
use serde::Deserialize;

#[derive(Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct RawLevels {
    pub freq_hz: Option<Vec<f64>>,
    pub shared: Option<bool>,
    pub tmcmc: Option<bool>,
}

#[derive(Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct RawBasins {
    pub starts: Option<usize>,
    pub rfm: Option<bool>,
    pub tolerance_sd: Option<f64>,
}

/// The comparison across levels.
#[derive(Clone, Debug, PartialEq)]
pub struct LevelSettings {
    /// Frequencies (Hz) at which the level change is reported besides the modes.
    pub freq_hz: Vec<f64>,
    /// Compare shared against separate law parameters by evidence.
    pub shared: bool,
    /// TMCMC on the shared posterior as well as Laplace.
    pub tmcmc: bool,
}

impl Default for LevelSettings {
    fn default() -> Self {
        LevelSettings {
            freq_hz: vec![10.0, 100.0, 300.0],
            shared: true,
            tmcmc: false,
        }
    }
}

/// The basin study.
#[derive(Clone, Debug, PartialEq)]
pub struct BasinSettings {
    pub starts: usize,
    pub rfm: bool,
    pub tolerance_sd: f64,
}

pub(super) fn levels(ctx: &Ctx, r: Option<&RawLevels>) -> Result<LevelSettings, StudyError> {
    let mut s = LevelSettings::default();
    let Some(r) = r else { return Ok(s) };
    if let Some(f) = &r.freq_hz {
        for (i, v) in f.iter().enumerate() {
            ctx.positive(&format!("inference.across_levels.freq_hz[{i}]"), *v, "Hz")?;
        }
        s.freq_hz = f.clone();
    }
    s.shared = r.shared.unwrap_or(s.shared);
    s.tmcmc = r.tmcmc.unwrap_or(s.tmcmc);
    if s.tmcmc && !s.shared {
        return Err(ctx.err(
            "inference.across_levels.tmcmc",
            "TMCMC of the shared posterior needs `shared = true`",
        ));
    }
    Ok(s)
}

pub(super) fn basins(
    ctx: &Ctx,
    r: Option<&RawBasins>,
) -> Result<Option<BasinSettings>, StudyError> {
    let Some(r) = r else { return Ok(None) };
    let starts = r.starts.unwrap_or(200);
    if starts < 2 {
        return Err(ctx.err(
            "inference.basins.starts",
            format!("{starts} is too small: give at least 2 (200 for a basin study)"),
        ));
    }
    let tol = r.tolerance_sd.unwrap_or(0.1);
    ctx.positive("inference.basins.tolerance_sd", tol, "posterior sd")?;
    Ok(Some(BasinSettings {
        starts,
        rfm: r.rfm.unwrap_or(true),
        tolerance_sd: tol,
    }))
}
