//! report.md's model-comparison section, one table per level: log evidence per estimator,
//! Bayes factors against the best model and model probabilities (declared priors and priors
//! widened ten-fold), LOO and WAIC, FRAC over posterior draws, the estimators'
//! disagreements, and the posterior predictive check per channel at the MAP.

use crate::bayes::PosteriorResult;
use crate::output::Report;
use crate::pipeline::tables::comparison::{
    estimator_gap, evidence_of, levels_of, model_probabilities, PREFERENCE,
};

fn pm(z: f64, se: f64) -> String {
    if !z.is_finite() {
        return "-".into();
    }
    if se.is_finite() {
        format!("{z:.2} +- {se:.2}")
    } else {
        format!("{z:.2}")
    }
}

/// The report's model-comparison section: one table per level.
pub(super) fn section(rep: &mut Report, posts: &[&PosteriorResult]) {
    if posts.is_empty() {
        return;
    }
    rep.heading(2, "Model comparison");
    rep.paragraph("Log evidence (nats) per estimator, each with its own error bar (TMCMC: its delta-method error; stepping-stone: the spread of independent replicas; Laplace: none). Bayes factors against the level's best model and posterior model probabilities assume equal prior model probabilities and use one estimator for all models (stepping-stone when it ran for every model, else TMCMC, else Laplace). **Evidence depends on the priors** (Lindley): the columns \"widened 10x\" give the Bayes factor and probability when each law parameter's prior is ten times wider in its natural scale (log-uniform: ten times the log-width about the geometric centre), by importance reweighting of posterior draws (exact when the posterior lies well inside the declared support; `inside_sd` in `evidence.parquet`). For log-uniform priors this costs exactly ln 10 = 2.30 nats per parameter, so it penalises the models with more parameters. LOO and WAIC are the expected log predictive density of a left-out frequency line (all channels), PSIS-LOO with the largest Pareto k (above 0.7: unreliable). FRAC median [95 %] is over posterior draws; the MAP's value is in `model_comparison.parquet`.");
    for (level, group) in levels_of(posts) {
        rep.heading(3, &format!("Level {level}"));
        let declared = model_probabilities(&group, "declared");
        let widened = model_probabilities(&group, "widened_10x");
        let estimators: Vec<&str> = PREFERENCE
            .iter()
            .rev()
            .copied()
            .filter(|e| {
                group
                    .iter()
                    .any(|p| evidence_of(p, e, "declared").is_some())
            })
            .collect();
        let mut headers: Vec<String> = vec!["model".into()];
        for e in &estimators {
            headers.push(format!("log Z {e}"));
        }
        headers.extend([
            "log BF vs best".to_string(),
            "P(model)".into(),
            "log BF / P, priors widened 10x".into(),
            "elpd LOO +- se (p_loo, max k)".into(),
            "elpd WAIC +- se".into(),
            "FRAC median [95 %] per channel".into(),
        ]);
        let mut rows = Vec::new();
        let mut flags = Vec::new();
        for (i, p) in group.iter().enumerate() {
            let c = &p.compare;
            let mut row = vec![p.model.clone()];
            for e in &estimators {
                let (z, se) = evidence_of(p, e, "declared").unwrap_or((f64::NAN, f64::NAN));
                row.push(pm(z, se));
            }
            let (bf, prob) = declared.as_ref().map_or((f64::NAN, f64::NAN), |d| d.1[i]);
            row.push(format!("{bf:.2}"));
            row.push(format!("{prob:.3}"));
            let (bfw, probw) = widened.as_ref().map_or((f64::NAN, f64::NAN), |d| d.1[i]);
            row.push(format!("{bfw:.2} / {probw:.3}"));
            row.push(match &c.loo {
                Some(l) => format!(
                    "{:.1} +- {:.1} ({:.1}, {:.2})",
                    l.elpd,
                    l.se,
                    l.p_loo,
                    l.pareto_k.iter().copied().fold(f64::NEG_INFINITY, f64::max)
                ),
                None => "-".into(),
            });
            row.push(match &c.waic {
                Some(w) => format!("{:.1} +- {:.1}", w.elpd, w.se),
                None => "-".into(),
            });
            row.push(
                c.frac
                    .iter()
                    .map(|b| format!("{:.4} [{:.4}, {:.4}]", b.median, b.lo, b.hi))
                    .collect::<Vec<_>>()
                    .join("; "),
            );
            rows.push(row);
            let gap = estimator_gap(p);
            if gap > 0.5 {
                flags.push(format!(
                    "{}: the sampled estimators (TMCMC, its reweighting, stepping-stone) differ by up to {gap:.2} nats (> 0.5)",
                    p.model
                ));
            }
            if let (Some(l), Some(t)) = (
                evidence_of(p, "laplace", "declared"),
                evidence_of(p, "tmcmc", "declared"),
            ) {
                if (l.0 - t.0).abs() > 0.5 {
                    flags.push(format!(
                        "{}: Laplace and TMCMC differ by {:.2} nats (> 0.5; Laplace assumes a Gaussian posterior)",
                        p.model,
                        (l.0 - t.0).abs()
                    ));
                }
            }
        }
        rep.table(&headers, &rows);
        if let Some((est, v)) = &declared {
            let best = v
                .iter()
                .enumerate()
                .max_by(|a, b| a.1 .1.total_cmp(&b.1 .1))
                .map(|(i, _)| group[i].model.clone())
                .unwrap_or_default();
            rep.paragraph(&format!(
                "Highest posterior probability at level {level}: **{best}** (estimator {est})."
            ));
        }
        if flags.is_empty() {
            rep.paragraph("The evidence estimators agree within 0.5 nats for every model.");
        } else {
            rep.paragraph(&format!(
                "**Estimator disagreement:** {}.",
                flags.join("; ")
            ));
        }
        let mut ppc = Vec::new();
        for p in &group {
            for ch in &p.compare.ppc {
                ppc.push(vec![
                    p.model.clone(),
                    ch.response_id.to_string(),
                    format!("{:.1}", ch.chi2),
                    ch.dof.to_string(),
                    format!("{:.2}", ch.chi2 / ch.dof as f64),
                    format!("{:.3e}", ch.p_value),
                ]);
            }
            for n in &p.compare.notes {
                rep.paragraph(&format!("{}: {n}", p.model));
            }
        }
        rep.paragraph("Posterior predictive check at the MAP: standardised complex residuals per channel (`ppc.parquet`); chi-square = sum of squared standardised real and imaginary parts, on 2 x lines degrees of freedom. A small p-value says the residual is larger than the noise model allows (model error or a measurement effect the model lacks).");
        rep.table(
            &["model", "channel", "chi2", "dof", "chi2 / dof", "p-value"],
            &ppc,
        );
    }
}
