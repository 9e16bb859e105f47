//! The loop's verdict per level: a status that cannot be wrong quietly.
//!
//! * `nothing_missing`: the final residual is consistent with noise and nothing was accepted.
//! * `explained`: effects were accepted and the final residual is consistent with noise.
//! * `unexplained`: the residual stays above what noise and the measurement model allow. The
//!   verdict says by how much (`chi2 / null mean`), where (the frequency bands and channels
//!   with the largest normalised chi-square), and which candidates came closest. Effects
//!   accepted on the way are tentative; each is kept only if its evidence stays decisive in
//!   the final model once the likelihood is widened to the residual actually left (the
//!   drop-one check below). The adhesive's parameters carry a warning.
//! * `confounded`: the residual is consistent with noise, but an effect cannot be separated
//!   from the adhesive's parameters: an accepted effect whose posterior multiple correlation
//!   with the law's parameters is at least `sqrt(confounded_r2)`, or a candidate the law
//!   absorbs (`R^2 >= confounded_r2`, [`super::confounding`]) whose score is significant after
//!   a Bonferroni correction over the round's candidates. The parameter combination and the
//!   correlation are named and the adhesive's parameters are given as a range over the
//!   effect's plausible sizes.
//!
//! "Consistent with noise": `chi2_after <= threshold` of the calibrated null level
//! ([`super::null`]), not a fixed chi-square.
//!
//! **Drop-one check.** With `kappa = max(1, chi2_after / null mean)` the residual is `kappa`
//! times the noise; a likelihood widened by `kappa` (variances times `kappa`) scales every
//! log-likelihood difference by `1 / kappa`. For each accepted effect the final model is
//! refitted without it; the effect is kept when `(logZ_final - logZ_without) / kappa` is at
//! least the evidence threshold, otherwise it is dropped and the final model refitted without
//! the dropped effects.
//!
//! **Ranges of a confounded level.** For a candidate the law absorbs with `a` (relative change
//! of each law parameter per unit effect, [`super::confounding::Confounding`]), data holding
//! the effect at size `e` make the fit without it read `p (1 + a e)`, so the parameters over
//! the plausible sizes `e in [e_lo, e_hi]` (the one-step size +- 2 sd within the prior, from 0
//! for a one-sided effect) are `p / (1 + a e)`. For an accepted effect the posterior
//! regression `p_i(e) = p_i + (S_ie / S_ee)(e - e_hat)` over `e_hat +- 2 sd_e` (within the
//! prior), joined with each parameter's own 95 % interval.

use super::{ClosedLoopResult, Fit};
use crate::inference::prior::Prior;

/// The status of one level.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Status {
    NothingMissing,
    Explained,
    Unexplained,
    Confounded,
}

impl Status {
    /// The machine-readable name.
    pub fn as_str(self) -> &'static str {
        match self {
            Status::NothingMissing => "nothing_missing",
            Status::Explained => "explained",
            Status::Unexplained => "unexplained",
            Status::Confounded => "confounded",
        }
    }
}

impl std::fmt::Display for Status {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Settings of the verdict.
#[derive(Clone, Debug, PartialEq)]
pub struct VerdictParams {
    /// Evidence (nats) an effect keeps in the drop-one check. Default 5 (the loop's).
    pub threshold_nats: f64,
    /// `R^2` from which an effect counts as confounded with the law. Default
    /// [`super::confounding::CONFOUNDED_R2`] (0.99).
    pub confounded_r2: f64,
    /// Significance of a confounded candidate's score before the Bonferroni correction over
    /// the round's candidates. Default 0.01.
    pub p_threshold: f64,
    /// Equal-width frequency bands over which the residual is located. Default 10.
    pub bands: usize,
}

impl Default for VerdictParams {
    fn default() -> Self {
        VerdictParams {
            threshold_nats: 5.0,
            confounded_r2: super::confounding::CONFOUNDED_R2,
            p_threshold: 0.01,
            bands: 10,
        }
    }
}

/// The residual in one frequency band.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Band {
    pub lo_hz: f64,
    pub hi_hz: f64,
    pub chi2_normalised: f64,
    /// Share of the total chi-square in this band.
    pub share: f64,
}

/// The residual on one channel against its null level.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct ChannelExcess {
    pub id: u32,
    pub chi2_normalised: f64,
    pub null_mean: f64,
}

/// A candidate that came close (not accepted).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Closest {
    pub name: String,
    pub kind: String,
    /// Evidence gain of its refit (nats), or its profile gain when not refitted.
    pub gain: f64,
    pub size: f64,
    pub sd: f64,
    pub verdict: String,
}

/// The drop-one check of one accepted effect.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct DropOne {
    pub effect: String,
    /// `logZ_final - logZ_without` (nats).
    pub gain: f64,
    /// `gain / kappa`.
    pub scaled_gain: f64,
    pub kappa: f64,
    pub kept: bool,
}

/// An accepted effect left out of an `explained` level because the residual is consistent with
/// noise without it: the data need it for their evidence but not for their fit (a proxy for a
/// small difference the candidates do not describe, e.g. a beam factor of -0.01 % after a
/// sensor's mass whose x and z inertia the measured-direction mass leaves out).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct NotNeeded {
    pub effect: String,
    /// The size it had in the final fit, in its unit.
    pub size: f64,
    pub unit: String,
    /// Normalised chi-square of the final model refitted without it (at most the threshold).
    pub chi2_without: f64,
}

impl NotNeeded {
    /// `name = size unit`, as the conclusion and `verdict.parquet` name it.
    pub fn entry(&self) -> String {
        format!("{} = {:.4e} {}", self.effect, self.size, self.unit)
    }
}

/// An effect the data cannot separate from the law's parameters.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct ConfoundedEffect {
    pub effect: String,
    pub unit: String,
    /// Multiple correlation of the effect with the law's parameters (`sqrt(R^2)`).
    pub correlation: f64,
    /// The law's parameters and the relative change of each per unit of the effect (the
    /// combination that trades against it).
    pub combination: Vec<(String, f64)>,
    /// Plausible sizes of the effect.
    pub size_range: (f64, f64),
    /// The law's parameters (name, low, high) over those sizes.
    pub ranges: Vec<(String, f64, f64)>,
    /// The other accepted effects' sizes (name, low, high) over those sizes (an accepted
    /// effect's only): each one's 95 % interval widened by its regression on the effect, as
    /// the law's parameters are (a sensor's mass trades against base springs too).
    pub effects: Vec<(String, f64, f64)>,
    pub accepted: bool,
}

/// The verdict of one level.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Verdict {
    pub status: Status,
    pub chi2_before: f64,
    pub chi2_after: f64,
    pub null_mean: f64,
    pub null_sd: f64,
    pub threshold: f64,
    pub false_alarm: f64,
    /// `chi2_after / null_mean`.
    pub excess: f64,
    /// The bands with the largest normalised chi-square (at most 3, worst first).
    pub bands: Vec<Band>,
    /// Every channel, worst first.
    pub channels: Vec<ChannelExcess>,
    /// Candidates that came closest (at most 3).
    pub closest: Vec<Closest>,
    /// Accepted effects reported as tentative (an `unexplained` end).
    pub tentative: Vec<String>,
    pub drop_one: Vec<DropOne>,
    /// Accepted effects left out because the residual is consistent with noise without them.
    pub not_needed: Vec<NotNeeded>,
    pub confounded: Vec<ConfoundedEffect>,
    /// The warning the law's parameters carry (an `unexplained` level).
    pub warning: Option<String>,
    /// One line for the report.
    pub sentence: String,
}

/// Whether the final residual is consistent with noise.
pub fn consistent(res: &ClosedLoopResult, null: &super::null::NullCalibration) -> bool {
    res.after.residuals.chi2_normalised <= null.threshold
}

/// The prior range of `e` (infinite when not uniform).
fn prior_range(e: &crate::forward::Effect) -> (f64, f64) {
    match e.default_prior() {
        Prior::Uniform { lo, hi } => (lo, hi),
        _ => (f64::NEG_INFINITY, f64::INFINITY),
    }
}

/// Normalised chi-square per band of `z` (`[line * n + k]`).
fn bands(z: &[crate::common::C64], freq_hz: &[f64], n: usize, nb: usize) -> Vec<Band> {
    let nl = freq_hz.len();
    if nl == 0 || n == 0 || nb == 0 {
        return Vec::new();
    }
    let (f0, f1) = (freq_hz[0], freq_hz[nl - 1]);
    let width = ((f1 - f0) / nb as f64).max(f64::MIN_POSITIVE);
    let total: f64 = z.iter().map(|z| z.norm_sqr()).sum();
    let mut acc = vec![(0.0, 0usize); nb];
    for (l, f) in freq_hz.iter().enumerate() {
        let b = (((f - f0) / width) as usize).min(nb - 1);
        for k in 0..n {
            acc[b].0 += z[l * n + k].norm_sqr();
        }
        acc[b].1 += 1;
    }
    let mut out: Vec<Band> = acc
        .iter()
        .enumerate()
        .filter(|(_, (_, m))| *m > 0)
        .map(|(b, (q, m))| Band {
            lo_hz: f0 + b as f64 * width,
            hi_hz: f0 + (b + 1) as f64 * width,
            chi2_normalised: q / (2 * m * n) as f64,
            share: if total > 0.0 { q / total } else { 0.0 },
        })
        .collect();
    out.sort_by(|a, b| b.chi2_normalised.total_cmp(&a.chi2_normalised));
    out.truncate(3);
    out
}

/// Posterior multiple correlation `R^2` of parameter `e` with parameters `0..n_law` from the
/// covariance `cov` (`d x d`), and the regression coefficients `S_ie / S_ee` per law
/// parameter. `None` when the covariance is not usable.
fn posterior_confounding(cov: &[f64], d: usize, n_law: usize, e: usize) -> Option<(f64, Vec<f64>)> {
    if cov.len() != d * d || e >= d || n_law == 0 {
        return None;
    }
    let see = cov[e * d + e];
    if !(see > 0.0) {
        return None;
    }
    let sll: Vec<f64> = (0..n_law * n_law)
        .map(|k| cov[(k / n_law) * d + k % n_law])
        .collect();
    let sle: Vec<f64> = (0..n_law).map(|i| cov[i * d + e]).collect();
    let l = super::cholesky(&sll, n_law)?;
    let b = super::chol_solve(&l, n_law, &sle);
    let r2 = (b.iter().zip(&sle).map(|(a, c)| a * c).sum::<f64>() / see).clamp(0.0, 1.0);
    Some((r2, sle.iter().map(|s| s / see).collect()))
}

/// The law's parameters of `fit` as (name, value, sd).
fn law_params(fit: &Fit) -> Vec<(String, f64, f64)> {
    (0..fit.n_law)
        .map(|i| (fit.names[i].clone(), fit.values[i], fit.sd[i]))
        .collect()
}

/// Confounding of each accepted effect in the final fit (posterior correlation), and of the
/// last round's candidates the law absorbs whose score is significant (Bonferroni).
fn confounded_effects(res: &ClosedLoopResult, params: &VerdictParams) -> Vec<ConfoundedEffect> {
    let a = &res.after;
    let d = a.names.len();
    let mut out = Vec::new();
    for (e, size, sd) in &res.accepted {
        if super::is_law_effect(e) {
            continue;
        }
        let Some(i) = a.names.iter().position(|n| *n == e.name()) else {
            continue;
        };
        let Some((r2, reg)) = posterior_confounding(&a.cov, d, a.n_law, i) else {
            continue;
        };
        if r2 < params.confounded_r2 {
            continue;
        }
        let (lo, hi) = prior_range(e);
        let (e_lo, e_hi) = ((size - 2.0 * sd).max(lo), (size + 2.0 * sd).min(hi));
        // A parameter of value p, sd s and regression b on the effect, over its sizes.
        let over = |p: f64, s: f64, b: f64| {
            let ends = [p + b * (e_lo - size), p + b * (e_hi - size)];
            (
                ends[0].min(ends[1]).min(p - 1.96 * s),
                ends[0].max(ends[1]).max(p + 1.96 * s),
            )
        };
        let ranges = law_params(a)
            .into_iter()
            .zip(&reg)
            .map(|((n, p, s), b)| {
                let (lo, hi) = over(p, s, *b);
                (n, lo, hi)
            })
            .collect();
        let see = a.cov[i * d + i];
        let effects = res
            .accepted
            .iter()
            .filter(|(o, _, _)| o != e)
            .filter_map(|(o, _, _)| {
                let j = a.names.iter().position(|n| *n == o.name())?;
                let (lo, hi) = over(a.values[j], a.sd[j], a.cov[j * d + i] / see);
                Some((o.name(), lo, hi))
            })
            .collect();
        out.push(ConfoundedEffect {
            effect: e.name(),
            unit: e.unit().into(),
            correlation: r2.sqrt(),
            combination: law_params(a)
                .into_iter()
                .zip(&reg)
                .map(|((n, p, _), b)| (n, if p != 0.0 { b / p } else { *b }))
                .collect(),
            size_range: (e_lo, e_hi),
            ranges,
            effects,
            accepted: true,
        });
    }
    let last = res.candidates.iter().map(|c| c.round).max().unwrap_or(0);
    let in_round = res
        .candidates
        .iter()
        .filter(|c| c.round == last)
        .count()
        .max(1);
    for c in res.candidates.iter().filter(|c| {
        c.round == last
            && !super::is_law_effect(&c.effect)
            && c.confounding.r2 >= params.confounded_r2
            && c.p_value < params.p_threshold / in_round as f64
            && !c.refit.as_ref().is_some_and(|r| r.accepted)
    }) {
        let (lo, hi) = prior_range(&c.effect);
        let (mut e_lo, e_hi) = (
            (c.one_step - 2.0 * c.one_step_sd).max(lo),
            (c.one_step + 2.0 * c.one_step_sd).min(hi),
        );
        if c.effect.one_sided() {
            e_lo = e_lo.max(0.0);
        }
        let ranges = law_params(a)
            .into_iter()
            .map(|(n, p, s)| {
                let rel = c
                    .confounding
                    .absorbed
                    .iter()
                    .find(|(m, _)| *m == n)
                    .map_or(0.0, |(_, r)| *r);
                let ends = [p / (1.0 + rel * e_lo), p / (1.0 + rel * e_hi)];
                let lo = ends[0].min(ends[1]).min(p - 1.96 * s);
                let hi = ends[0].max(ends[1]).max(p + 1.96 * s);
                (n, lo, hi)
            })
            .collect();
        out.push(ConfoundedEffect {
            effect: c.effect.name(),
            unit: c.effect.unit().into(),
            correlation: c.confounding.r2.sqrt(),
            combination: c.confounding.absorbed.clone(),
            size_range: (e_lo, e_hi),
            ranges,
            effects: Vec::new(),
            accepted: false,
        });
    }
    out
}

/// Candidates that came closest: refitted or profiled but not accepted, by gain.
fn closest(res: &ClosedLoopResult) -> Vec<Closest> {
    let mut v: Vec<Closest> = res
        .candidates
        .iter()
        .filter(|c| !c.refit.as_ref().is_some_and(|r| r.accepted))
        .filter_map(|c| {
            let (gain, size, sd, verdict) = match (&c.refit, c.profile_gain) {
                (Some(r), _) => (r.evidence_gain, r.size, r.sd, r.verdict.to_string()),
                (None, Some(g)) => (g, f64::NAN, f64::NAN, "profile only".to_string()),
                _ => return None,
            };
            Some(Closest {
                name: c.effect.name(),
                kind: c.effect.kind().into(),
                gain,
                size,
                sd,
                verdict,
            })
        })
        .chain(
            res.law_candidates
                .iter()
                .filter(|c| !c.refit.accepted)
                .map(|c| Closest {
                    name: c.law.clone(),
                    kind: super::alternative::ALTERNATIVE_LAW.into(),
                    gain: c.refit.evidence_gain,
                    size: f64::NAN,
                    sd: f64::NAN,
                    verdict: c.refit.verdict.to_string(),
                }),
        )
        .filter(|c| c.gain.is_finite())
        .collect();
    v.sort_by(|a, b| b.gain.total_cmp(&a.gain));
    v.truncate(3);
    v
}

/// The verdict of `res` (after any drop-one check, whose outcome is `drop_one`) against the
/// null level `null`, on lines `freq_hz` and channels `ids`.
pub fn assess(
    res: &ClosedLoopResult,
    null: &super::null::NullCalibration,
    freq_hz: &[f64],
    ids: &[u32],
    drop_one: Vec<DropOne>,
    not_needed: Vec<NotNeeded>,
    params: &VerdictParams,
) -> Verdict {
    let a = &res.after.residuals;
    let chi2_after = a.chi2_normalised;
    let ok = chi2_after <= null.threshold;
    let n = ids.len();
    let excess = chi2_after / null.mean;
    let mut channels: Vec<ChannelExcess> = ids
        .iter()
        .enumerate()
        .map(|(k, id)| ChannelExcess {
            id: *id,
            chi2_normalised: a.channels.get(k).map_or(f64::NAN, |c| c.chi2_normalised),
            null_mean: null.channel_mean.get(k).copied().unwrap_or(null.mean),
        })
        .collect();
    channels.sort_by(|x, y| {
        (y.chi2_normalised / y.null_mean).total_cmp(&(x.chi2_normalised / x.null_mean))
    });
    let accepted_names: Vec<String> = res
        .accepted
        .iter()
        .map(|(e, v, s)| super::accepted_entry(e, *v, *s))
        .chain(
            res.law_candidates
                .iter()
                .filter(|c| c.refit.accepted)
                .map(|c| format!("law {}", c.law)),
        )
        .collect();
    let confounded = if ok {
        confounded_effects(res, params)
    } else {
        Vec::new()
    };
    let status = if !ok {
        Status::Unexplained
    } else if !confounded.is_empty() {
        Status::Confounded
    } else if accepted_names.is_empty() {
        Status::NothingMissing
    } else {
        Status::Explained
    };
    let level = format!(
        "normalised chi-square {:.3} -> {chi2_after:.3} against a null level of {:.3} +- {:.3} (threshold {:.3} at a false-alarm rate of {} %)",
        res.before.residuals.chi2_normalised,
        null.mean,
        null.sd,
        null.threshold,
        100.0 * null.false_alarm
    );
    let close = closest(res);
    let worst = bands(&a.z, freq_hz, n, params.bands);
    let (tentative, warning, sentence) = match status {
        Status::NothingMissing => (
            Vec::new(),
            None,
            format!(
                "nothing_missing: no effect needed; {level}{}",
                left_out(&not_needed)
            ),
        ),
        Status::Explained => (
            Vec::new(),
            None,
            format!(
                "explained: {}; {level}{}",
                accepted_names.join("; "),
                left_out(&not_needed)
            ),
        ),
        Status::Confounded => {
            let c = &confounded[0];
            // "name in [lo, hi], ..."
            let in_ranges = |r: &[(String, f64, f64)]| {
                r.iter()
                    .map(|(n, lo, hi)| format!("{n} in [{lo:.4e}, {hi:.4e}]"))
                    .collect::<Vec<_>>()
                    .join(", ")
            };
            let ranges = in_ranges(&c.ranges);
            let others = if c.effects.is_empty() {
                String::new()
            } else {
                format!(", and the other effects {}", in_ranges(&c.effects))
            };
            let comb = c
                .combination
                .iter()
                .map(|(n, r)| format!("{n} {r:+.3e}"))
                .collect::<Vec<_>>()
                .join(", ");
            (
                Vec::new(),
                None,
                format!(
                    "confounded: {} ({}) cannot be separated from the adhesive's parameters (multiple correlation {:.4}; relative change per unit: {comb}); over its plausible sizes [{:.3e}, {:.3e}] {} the adhesive's parameters range {ranges}{others}; {level}",
                    c.effect,
                    if c.accepted { "accepted" } else { "not accepted" },
                    c.correlation,
                    c.size_range.0,
                    c.size_range.1,
                    c.unit
                ),
            )
        }
        Status::Unexplained => {
            let where_f = worst
                .iter()
                .map(|b| {
                    format!(
                        "{:.0}-{:.0} Hz ({:.2}, {:.0} % of the total)",
                        b.lo_hz,
                        b.hi_hz,
                        b.chi2_normalised,
                        100.0 * b.share
                    )
                })
                .collect::<Vec<_>>()
                .join(", ");
            let where_c = channels
                .iter()
                .take(2)
                .map(|c| {
                    format!(
                        "ch{} ({:.2}, null {:.2})",
                        c.id, c.chi2_normalised, c.null_mean
                    )
                })
                .collect::<Vec<_>>()
                .join(", ");
            let near = if close.is_empty() {
                "none refitted".to_string()
            } else {
                close
                    .iter()
                    .map(|c| format!("{} ({:.1} nats, {})", c.name, c.gain, c.verdict))
                    .collect::<Vec<_>>()
                    .join("; ")
            };
            let tent = if accepted_names.is_empty() {
                String::new()
            } else {
                format!(
                    "; tentative (accepted on the way, kept by the drop-one check): {}",
                    accepted_names.join("; ")
                )
            };
            let dropped: Vec<String> = drop_one
                .iter()
                .filter(|d| !d.kept)
                .map(|d| {
                    format!(
                        "{} ({:.1} nats / {:.2} = {:.1})",
                        d.effect, d.gain, d.kappa, d.scaled_gain
                    )
                })
                .collect();
            let dropped = if dropped.is_empty() {
                String::new()
            } else {
                format!(
                    "; dropped (evidence not decisive under the residual left): {}",
                    dropped.join(", ")
                )
            };
            (
                accepted_names.clone(),
                Some(format!(
                    "unexplained residual ({excess:.2} times the null level): the value is conditional on a model that does not fit these data and its interval understates the error"
                )),
                format!(
                    "unexplained: the residual is {excess:.2} times the null level; {level}; largest in {where_f}; channels {where_c}; closest candidates: {near}{tent}{dropped}"
                ),
            )
        }
    };
    Verdict {
        status,
        chi2_before: res.before.residuals.chi2_normalised,
        chi2_after,
        null_mean: null.mean,
        null_sd: null.sd,
        threshold: null.threshold,
        false_alarm: null.false_alarm,
        excess,
        bands: worst,
        channels,
        closest: close,
        tentative,
        drop_one,
        not_needed,
        confounded,
        warning,
        sentence,
    }
}

/// The sentence's note on the effects left out as not needed (empty without any).
fn left_out(not_needed: &[NotNeeded]) -> String {
    if not_needed.is_empty() {
        return String::new();
    }
    let each: Vec<String> = not_needed
        .iter()
        .map(|d| {
            format!(
                "{} ({:.4e} {}; chi-square {:.3} without it)",
                d.effect, d.size, d.unit, d.chi2_without
            )
        })
        .collect();
    format!(
        "; left out, not needed for a residual consistent with noise (accepted for their evidence, likely proxies for a difference the candidates do not describe): {}",
        each.join(", ")
    )
}
