//! What the closed loop found: the summary per level ([`DiagnoseSummary`], also printed by
//! `rfmlab diagnose --json`), the loop's outcome as a stage of a run ([`LoopOutcome`]), and
//! the accepted effects and parameter changes read off a level's result.

use crate::closed_loop::ClosedLoopResult;
use std::path::PathBuf;

/// What `diagnose` found, per level.
#[derive(Clone, Debug, serde::Serialize)]
pub struct DiagnoseSummary {
    pub study: String,
    pub model: String,
    pub output_dir: PathBuf,
    pub levels: Vec<DiagnoseLevel>,
    pub seconds: f64,
    /// The term ROM's certificate and modulus box, when a candidate or a declared effect
    /// needed one (degraded bond, adherend damping; src/diagnose/terms.rs).
    pub term_rom: Option<(crate::rom::TermCertificate, crate::rom::ModulusRange)>,
}

/// What the loop found at one level.
#[derive(Clone, Debug, serde::Serialize)]
pub struct DiagnoseLevel {
    pub level: String,
    /// `nothing_missing`, `explained`, `unexplained` or `confounded`
    /// ([`crate::closed_loop::verdict`]).
    pub status: String,
    /// The verdict behind the status (null level, where the residual is, tentative effects).
    pub verdict: crate::closed_loop::verdict::Verdict,
    /// The calibrated null level of the normalised chi-square.
    pub null: crate::closed_loop::null::NullCalibration,
    pub conclusion: String,
    pub chi2_normalised_before: f64,
    pub chi2_normalised_after: f64,
    pub relative_norm_before: f64,
    pub relative_norm_after: f64,
    pub frac_before: Vec<f64>,
    pub frac_after: Vec<f64>,
    /// Wall time (s) of the loop at this level (MAP, score tests, refits, evidence).
    pub loop_seconds: f64,
    /// Accepted effects in order: name, type, size (SI) and posterior sd.
    pub accepted: Vec<(String, String, f64, f64)>,
    /// Score-test ranking of the first round: candidate names, best first.
    pub first_ranking: Vec<String>,
    /// The model's parameters (law, then accepted effects), before and after.
    pub parameters: Vec<ParameterChange>,
    /// Candidates the law's parameters absorb (not identifiable), a sentence each.
    pub confounded: Vec<String>,
    /// With a term ROM: the factor by which the law's modulus at the final MAP leaves the term
    /// ROM's certified box over the level's lines (1: inside).
    pub term_box_factor: Option<f64>,
}

/// One parameter before and after the loop (SI), with the truth when simulated.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ParameterChange {
    pub name: String,
    pub before: Option<f64>,
    pub before_sd: Option<f64>,
    pub after: f64,
    pub after_sd: f64,
    pub truth: Option<f64>,
}

/// The loop's outcome (nothing written): per level its result, the summary and the markdown.
#[derive(Clone, Debug)]
pub struct LoopOutcome {
    /// The summary (`output_dir` empty until written).
    pub summary: DiagnoseSummary,
    /// Per level: name, lines (Hz), response ids, the loop's result and the truth of the
    /// final law when simulated.
    pub levels: Vec<LevelResult>,
    /// The loop's section of the report (markdown, its own level-1 heading).
    pub markdown: String,
    /// The effects the term ROM carries (empty without one).
    pub term_names: Vec<String>,
    /// The discretisation candidate's comparison of two meshes, when it was tried.
    pub mesh: Option<super::mesh::MeshComparison>,
    /// Wall time (s) of the stage's steps in order: the term ROM, then per level the loop's
    /// steps ([`crate::closed_loop::ClosedLoopResult::timings`], named `L1: round 1: refits`);
    /// `rfmlab diagnose` adds each pass's engine and names the pass. The manifest lists them.
    pub timings: Vec<(String, f64)>,
}

impl LoopOutcome {
    /// Make the markdown from the levels and the summary (again, after a later pass changed a
    /// level's status or its accepted effects).
    pub(crate) fn remake_markdown(&mut self) {
        self.markdown = super::markdown::markdown(
            &self.summary.study,
            &self.summary.model,
            &self.levels,
            &self.summary.levels,
            self.summary
                .term_rom
                .as_ref()
                .map(|(c, _)| (self.term_names.as_slice(), c)),
        );
    }
}

/// One level of the loop: name, lines (Hz), response ids, result, truth of the final law.
pub type LevelResult = (
    String,
    Vec<f64>,
    Vec<u32>,
    ClosedLoopResult,
    Option<Vec<f64>>,
);

/// Accepted effects and laws in the order the loop accepted them: name, type, size and sd
/// (NaN for a law, which has no size).
pub(crate) fn accepted_in_order(res: &ClosedLoopResult) -> Vec<(String, String, f64, f64)> {
    let mut v: Vec<(usize, String, String, f64, f64)> = res
        .candidates
        .iter()
        .filter_map(|c| {
            let r = c.refit.as_ref().filter(|r| r.accepted)?;
            Some((
                c.round,
                c.effect.name(),
                c.effect.kind().to_string(),
                r.size,
                r.sd,
            ))
        })
        .chain(
            res.law_candidates
                .iter()
                .filter(|c| c.refit.accepted)
                .map(|c| {
                    (
                        c.round,
                        c.law.clone(),
                        crate::closed_loop::alternative::ALTERNATIVE_LAW.to_string(),
                        f64::NAN,
                        f64::NAN,
                    )
                }),
        )
        .collect();
    v.sort_by_key(|x| x.0);
    v.into_iter().map(|(_, n, k, a, b)| (n, k, a, b)).collect()
}

/// The parameters before and after: the final model's (matched by name to the starting
/// model's; when the law was replaced, the new law's parameters have no "before"), then, when
/// the law was replaced, the old law's parameters as `<law>.<name>` with no "after" (NaN).
/// `truth` is the final law's true parameters.
pub(crate) fn parameter_changes(
    res: &ClosedLoopResult,
    truth: Option<&[f64]>,
) -> Vec<ParameterChange> {
    let (b, a) = (&res.before, &res.after);
    let replaced = b.law != a.law;
    let mut v: Vec<ParameterChange> = a
        .names
        .iter()
        .enumerate()
        .map(|(i, n)| {
            let j = b
                .names
                .iter()
                .enumerate()
                .position(|(j, m)| m == n && !(replaced && (i < a.n_law || j < b.n_law)));
            ParameterChange {
                name: n.clone(),
                before: j.map(|j| b.values[j]),
                before_sd: j.map(|j| b.sd[j]),
                after: a.values[i],
                after_sd: a.sd[i],
                truth: truth.and_then(|t| t.get(i).copied()),
            }
        })
        .collect();
    if replaced {
        for j in 0..b.n_law {
            v.push(ParameterChange {
                name: format!("{}.{}", b.law, b.names[j]),
                before: Some(b.values[j]),
                before_sd: Some(b.sd[j]),
                after: f64::NAN,
                after_sd: f64::NAN,
                truth: None,
            });
        }
    }
    v
}
