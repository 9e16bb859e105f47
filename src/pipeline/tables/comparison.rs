//! The tables of the model comparison ([`crate::bayes::compare`]). Tables (parquet):
//!
//! | table | columns (unit) |
//! |---|---|
//! | `evidence` | level, model, estimator (laplace / tmcmc / tmcmc_is (TMCMC's final importance reweighting) / nuts_is (importance sampling from a reference fitted to NUTS's draws) / stepping_stone), prior (declared / widened_10x), log_evidence, se (nats; NaN for Laplace), n_loglik, seconds (s; NaN for Laplace), inside_sd (1) |
//! | `model_comparison` | level, model, log_evidence_<estimator>, se_<estimator> (nats), estimator (the one the next columns use), log_bf_vs_best (nats), probability, log_bf_widened_10x, probability_widened_10x, max_estimator_gap (nats), elpd_loo, elpd_loo_se, p_loo, max_pareto_k, elpd_waic, elpd_waic_se, p_waic, n_draws, frac_<channel>_map, _median, _lo, _hi (95 %) |
//! | `ppc` | level, model, channel, line, freq_hz (Hz), residual_re, residual_im (standardised, 1), chi2, dof, p_value (per channel, repeated) |
//! | `predictive` | level, model, criterion (scc / acc), freq_hz (Hz), map, median, lo, hi (95 %) |
//! | `pointwise_loglik` | level, model, sampler, chain, draw (as in `draws`), line, freq_hz (Hz), log_lik (nats, summed over channels), elpd_loo_i, pareto_k, elpd_waic_i (per line, repeated) |
//!
//! Bayes factors and model probabilities use equal prior model probabilities over the models
//! of `[inference] models` at a level and one estimator for all of them: stepping-stone when it
//! ran for every model, else TMCMC, else Laplace.

use crate::bayes::PosteriorResult;
use crate::output::{Columns as Cols, Table};
use crate::stage::RunError;

/// Estimators in order of preference for the Bayes factors.
pub(crate) const PREFERENCE: [&str; 5] =
    ["stepping_stone", "tmcmc_is", "nuts_is", "tmcmc", "laplace"];

/// Estimators that a sampler's disagreement check compares.
const SAMPLED: [&str; 4] = ["tmcmc", "tmcmc_is", "nuts_is", "stepping_stone"];

pub(crate) fn evidence_of(p: &PosteriorResult, estimator: &str, prior: &str) -> Option<(f64, f64)> {
    p.compare
        .evidence
        .iter()
        .find(|e| e.estimator == estimator && e.prior == prior)
        .map(|e| (e.log_evidence, e.se))
}

/// Per model at one level: (log BF vs the best, probability) under `prior`, with the estimator.
pub(crate) fn model_probabilities(
    posts: &[&PosteriorResult],
    prior: &str,
) -> Option<(&'static str, Vec<(f64, f64)>)> {
    let est = PREFERENCE.iter().copied().find(|e| {
        posts
            .iter()
            .all(|p| evidence_of(p, e, prior).is_some_and(|v| v.0.is_finite()))
    })?;
    let z: Vec<f64> = posts
        .iter()
        .map(|p| evidence_of(p, est, prior).map_or(f64::NAN, |v| v.0))
        .collect();
    let best = z.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let sum: f64 = z.iter().map(|v| (v - best).exp()).sum();
    Some((
        est,
        z.iter()
            .map(|v| (v - best, (v - best).exp() / sum))
            .collect(),
    ))
}

/// Largest gap between the sampled estimators (TMCMC, stepping-stone) under the declared
/// priors (NaN with fewer than two).
pub(crate) fn estimator_gap(p: &PosteriorResult) -> f64 {
    let v: Vec<f64> = SAMPLED
        .iter()
        .filter_map(|e| evidence_of(p, e, "declared").map(|v| v.0))
        .collect();
    if v.len() < 2 {
        return f64::NAN;
    }
    let mx = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let mn = v.iter().copied().fold(f64::INFINITY, f64::min);
    mx - mn
}

pub(crate) fn levels_of<'a>(
    posts: &[&'a PosteriorResult],
) -> Vec<(String, Vec<&'a PosteriorResult>)> {
    let mut out: Vec<(String, Vec<&PosteriorResult>)> = Vec::new();
    for p in posts {
        match out.iter_mut().find(|(l, _)| *l == p.level) {
            Some((_, v)) => v.push(p),
            None => out.push((p.level.clone(), vec![p])),
        }
    }
    out
}

/// The comparison tables (empty when nothing was inferred).
pub(super) fn tables(posts: &[&PosteriorResult]) -> Result<Vec<Table>, RunError> {
    if posts.is_empty() {
        return Ok(Vec::new());
    }
    let (mut ev, mut mc, mut pp, mut pr, mut pw) = (
        Cols::default(),
        Cols::default(),
        Cols::default(),
        Cols::default(),
        Cols::default(),
    );
    // Every estimator that any model has, for fixed columns.
    let estimators: Vec<&str> = PREFERENCE
        .iter()
        .rev()
        .copied()
        .filter(|e| {
            posts
                .iter()
                .any(|p| evidence_of(p, e, "declared").is_some())
        })
        .collect();
    let channels: Vec<u32> = posts
        .iter()
        .find(|p| !p.compare.ppc.is_empty())
        .map(|p| p.compare.ppc.iter().map(|c| c.response_id).collect())
        .unwrap_or_default();
    for (level, group) in levels_of(posts) {
        let declared = model_probabilities(&group, "declared");
        let widened = model_probabilities(&group, "widened_10x");
        for (i, p) in group.iter().enumerate() {
            let c = &p.compare;
            for e in &c.evidence {
                ev.s("level", level.clone());
                ev.s("model", p.model.clone());
                ev.s("estimator", e.estimator.clone());
                ev.s("prior", e.prior.clone());
                ev.f("log_evidence", "nats", e.log_evidence);
                ev.f("se", "nats", e.se);
                ev.i("n_loglik", e.n_loglik as i64);
                ev.f("seconds", "s", e.seconds);
                ev.f("inside_sd", "1", c.inside_sd);
            }
            mc.s("level", level.clone());
            mc.s("model", p.model.clone());
            for e in &estimators {
                let (z, se) = evidence_of(p, e, "declared").unwrap_or((f64::NAN, f64::NAN));
                mc.f(&format!("log_evidence_{e}"), "nats", z);
                mc.f(&format!("se_{e}"), "nats", se);
            }
            let (est, bf, prob) = declared
                .as_ref()
                .map_or(("", f64::NAN, f64::NAN), |(e, v)| (*e, v[i].0, v[i].1));
            mc.s("estimator", est.to_string());
            mc.f("log_bf_vs_best", "nats", bf);
            mc.f("probability", "1", prob);
            let (bfw, probw) = widened.as_ref().map_or((f64::NAN, f64::NAN), |(_, v)| v[i]);
            mc.f("log_bf_widened_10x", "nats", bfw);
            mc.f("probability_widened_10x", "1", probw);
            mc.f("max_estimator_gap", "nats", estimator_gap(p));
            let l = c.loo.as_ref();
            mc.f("elpd_loo", "nats", l.map_or(f64::NAN, |l| l.elpd));
            mc.f("elpd_loo_se", "nats", l.map_or(f64::NAN, |l| l.se));
            mc.f("p_loo", "1", l.map_or(f64::NAN, |l| l.p_loo));
            mc.f(
                "max_pareto_k",
                "1",
                l.map_or(f64::NAN, |l| {
                    l.pareto_k.iter().copied().fold(f64::NEG_INFINITY, f64::max)
                }),
            );
            let w = c.waic.as_ref();
            mc.f("elpd_waic", "nats", w.map_or(f64::NAN, |w| w.elpd));
            mc.f("elpd_waic_se", "nats", w.map_or(f64::NAN, |w| w.se));
            mc.f("p_waic", "1", w.map_or(f64::NAN, |w| w.p_waic));
            mc.i("n_draws", c.pointwise.len() as i64);
            for (k, id) in channels.iter().enumerate() {
                let b = c.frac.get(k);
                for (suffix, v) in [
                    ("map", b.map_or(f64::NAN, |b| b.map)),
                    ("median", b.map_or(f64::NAN, |b| b.median)),
                    ("lo", b.map_or(f64::NAN, |b| b.lo)),
                    ("hi", b.map_or(f64::NAN, |b| b.hi)),
                ] {
                    mc.f(&format!("frac_{id}_{suffix}"), "1", v);
                }
            }
            let freq = &c.freq_hz;
            for ch in &c.ppc {
                for (l, r) in ch.residuals.iter().enumerate() {
                    pp.s("level", level.clone());
                    pp.s("model", p.model.clone());
                    pp.i("channel", ch.response_id as i64);
                    pp.i("line", l as i64);
                    pp.f("freq_hz", "Hz", freq.get(l).copied().unwrap_or(f64::NAN));
                    pp.f("residual_re", "1", r.re);
                    pp.f("residual_im", "1", r.im);
                    pp.f("chi2", "1", ch.chi2);
                    pp.i("dof", ch.dof as i64);
                    pp.f("p_value", "1", ch.p_value);
                }
            }
            for (name, bands) in [("scc", &c.scc), ("acc", &c.acc)] {
                for (l, b) in bands.iter().enumerate() {
                    pr.s("level", level.clone());
                    pr.s("model", p.model.clone());
                    pr.s("criterion", name.to_string());
                    pr.f("freq_hz", "Hz", freq.get(l).copied().unwrap_or(f64::NAN));
                    pr.f("map", "1", b.map);
                    pr.f("median", "1", b.median);
                    pr.f("lo", "1", b.lo);
                    pr.f("hi", "1", b.hi);
                }
            }
            for ((ch, dr), row) in c.draw_index.iter().zip(&c.pointwise) {
                for (l, v) in row.iter().enumerate() {
                    pw.s("level", level.clone());
                    pw.s("model", p.model.clone());
                    pw.s(
                        "sampler",
                        c.draws_from.map(|s| s.to_string()).unwrap_or_default(),
                    );
                    pw.i("chain", *ch as i64);
                    pw.i("draw", *dr as i64);
                    pw.i("line", l as i64);
                    pw.f("freq_hz", "Hz", freq.get(l).copied().unwrap_or(f64::NAN));
                    pw.f("log_lik", "nats", *v);
                    pw.f(
                        "elpd_loo_i",
                        "nats",
                        l_at(c.loo.as_ref().map(|x| x.pointwise.as_slice()), l),
                    );
                    pw.f(
                        "pareto_k",
                        "1",
                        l_at(c.loo.as_ref().map(|x| x.pareto_k.as_slice()), l),
                    );
                    pw.f(
                        "elpd_waic_i",
                        "nats",
                        l_at(c.waic.as_ref().map(|x| x.pointwise.as_slice()), l),
                    );
                }
            }
        }
    }
    Ok(vec![
        ev.table("evidence")?,
        mc.table("model_comparison")?,
        pp.table("ppc")?,
        pr.table("predictive")?,
        pw.table("pointwise_loglik")?,
    ])
}

fn l_at(v: Option<&[f64]>, l: usize) -> f64 {
    v.and_then(|v| v.get(l)).copied().unwrap_or(f64::NAN)
}
