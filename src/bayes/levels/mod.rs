//! Across excitation levels: the level-to-level change of E' and E'' with
//! credible intervals, and whether the law's parameters differ between levels at all.
//!
//! 1. **Change**: at the first two bending modes of the joint (from the lower level's MAP: the
//!    modal frequency `f_r` solves `(2 pi f_r)^2 = Re lambda_r(E*(2 pi f_r))`, a fixed point on
//!    the ROM's complex modes) and at chosen frequencies, `Delta E' = E'_high(f) - E'_low(f)`
//!    over pairs of posterior draws of the two levels (independent posteriors: draw `i` of one
//!    with draw `i` of the other is a draw of the pair), with its 50 % and 95 % intervals and
//!    `P(E'_high < E'_low)`, the probability that the adhesive is softer at the higher level.
//! 2. **Shared or separate** (evidence): a posterior whose law parameters are shared by both
//!    levels (likelihood = product of the levels' likelihoods, noise coordinates per level,
//!    [`crate::inference::joint::JointPosterior`]) against separate parameters per level
//!    (`log Z_low + log Z_high`). Laplace always (TMCMC when asked). `log B = log Z_separate -
//!    log Z_shared > 0` favours a level-dependent (amplitude-dependent) law.
//!
//! The change in [`change`], the evidence in [`shared`]. Checked by the unit tests of
//! [`change`]; the comparison runs in `studies/bayes_compare.toml` (the suite's `docs` test
//! checks its tables).

pub mod change;
pub mod shared;

pub use change::{change_stats, modal_frequencies, ChangeRow, ChangeStats, Quantiles};
pub use shared::SharedEvidence;

use super::{InferenceParams, PosteriorResult, RunContext};
use crate::frf::FrfEngine;
use crate::stage::{LevelData, RunError};
use crate::study::comparison::LevelSettings;
use crate::study::Measurements;

/// Modal frequencies used for one model.
#[derive(Clone, Debug)]
pub struct ModalPoint {
    pub model: String,
    pub freq_hz: Vec<f64>,
}

/// The comparison of two levels.
#[derive(Clone, Debug)]
pub struct LevelComparison {
    pub low: String,
    pub high: String,
    pub force_low_n: Option<f64>,
    pub force_high_n: Option<f64>,
    pub rows: Vec<ChangeRow>,
    pub evidence: Vec<SharedEvidence>,
    pub modes: Vec<ModalPoint>,
    /// Problems met (a model skipped and why).
    pub notes: Vec<String>,
}

/// The comparison of the first two levels of the inference stages `stages` that have
/// posteriors in `posteriors` (per level), ordered by the force RMS of `data` when it gives
/// them, or `None` with fewer than two such levels. `engine` gives the modes.
pub fn compare(
    run: &RunContext<'_>,
    stages: &[InferenceParams],
    settings: &LevelSettings,
    data: &Measurements,
    engine: &dyn FrfEngine,
    levels: &[LevelData],
    posteriors: &[(&str, &[PosteriorResult])],
) -> Result<Option<LevelComparison>, RunError> {
    let force = |name: &str| {
        data.levels
            .iter()
            .find(|l| l.name == name)
            .and_then(|l| l.force_rms_n)
    };
    let posts_at = |name: &str| posteriors.iter().find(|(l, _)| *l == name).map(|(_, p)| *p);
    let mut names: Vec<&str> = Vec::new();
    for s in stages {
        if !names.contains(&s.level.as_str()) {
            names.push(&s.level);
        }
    }
    names.retain(|n| posteriors.iter().any(|(l, p)| l == n && !p.is_empty()));
    if names.len() < 2 {
        return Ok(None);
    }
    names.sort_by(|a, b| {
        force(a)
            .unwrap_or(f64::NAN)
            .total_cmp(&force(b).unwrap_or(f64::NAN))
    });
    let (ln, hn) = (names[0], names[1]);
    let (Some(low), Some(high)) = (
        levels.iter().find(|l| l.name == ln),
        levels.iter().find(|l| l.name == hn),
    ) else {
        return Ok(None);
    };
    let (Some(rl), Some(rh)) = (posts_at(ln), posts_at(hn)) else {
        return Ok(None);
    };
    let band = (
        low.freq_hz.first().copied().unwrap_or(0.0),
        low.freq_hz.last().copied().unwrap_or(f64::INFINITY),
    );
    let mut out = LevelComparison {
        low: ln.to_string(),
        high: hn.to_string(),
        force_low_n: force(ln),
        force_high_n: force(hn),
        rows: Vec::new(),
        evidence: Vec::new(),
        modes: Vec::new(),
        notes: Vec::new(),
    };
    for (mi, pl) in rl.iter().enumerate() {
        let Some(ph) = rh.iter().find(|p| p.model == pl.model) else {
            continue;
        };
        let Some((_, law)) = run.model(&pl.model) else {
            continue;
        };
        let nl = law.n_params();
        let modes = modal_frequencies(engine, law, &pl.map.map_physical[..nl], band, 2);
        out.modes.push(ModalPoint {
            model: pl.model.clone(),
            freq_hz: modes.clone(),
        });
        let mut points: Vec<(String, f64)> = modes
            .iter()
            .enumerate()
            .map(|(r, f)| (format!("mode {}", r + 1), *f))
            .collect();
        points.extend(settings.freq_hz.iter().map(|f| ("chosen".to_string(), *f)));
        out.rows
            .extend(change::change_rows(law, (low, pl), (high, ph), &points));
        if settings.shared {
            let stage = stages.iter().find(|s| s.model == pl.model);
            match stage.map(|stage| {
                shared::shared_evidence(
                    run,
                    stage,
                    settings.tmcmc,
                    engine,
                    law,
                    (low, pl),
                    (high, ph),
                    mi,
                )
            }) {
                Some(Ok(ev)) => out.evidence.extend(ev),
                Some(Err(e)) => out.notes.push(format!(
                    "shared-parameter evidence of {} not computed: {e}",
                    pl.model
                )),
                None => {}
            }
        }
    }
    Ok(Some(out))
}
