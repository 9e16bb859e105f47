//! report.md's posterior section (`[inference]`): the likelihood and priors, then per level
//! and model the MAP search, the Laplace evidence, per sampler and parameter the MAP, mean,
//! sd, 95 % interval, Laplace sd, R-hat and ESS (moduli in MPa, viscosities in kPa s), the
//! samplers' costs, diagnostics warnings and the posterior figures.

use crate::bayes::PosteriorResult;
use crate::inference::Sampler;
use crate::output::Report;
use crate::pipeline::tables::posterior::{summaries, truth_of};
use crate::stage::LevelData;

/// Scale of a unit for the report.
fn scale(unit: &str) -> (f64, &'static str) {
    match unit {
        "Pa" => (1e-6, "MPa"),
        "Pa s" => (1e-3, "kPa s"),
        _ => (1.0, ""),
    }
}

/// The report's posterior section.
pub(super) fn section(
    rep: &mut Report,
    levels: &[LevelData],
    posts: &[&PosteriorResult],
    figures: &[(String, String)],
) {
    if posts.is_empty() {
        return;
    }
    rep.heading(2, "Posteriors (Bayesian inference)");
    let p0 = posts[0];
    let noise = match &p0.noise.scale {
        crate::inference::likelihood::Scale::Coherence { n_averages, floor } => format!(
            "complex Gaussian with the H1 random error from the coherence (n_d = {n_averages:.1} equivalent averages, floor {floor:.0e} on 1 - g^2)"
        ),
        crate::inference::likelihood::Scale::Inferred { bands_hz } => format!(
            "one inferred relative noise level per channel{}",
            if bands_hz.is_empty() { String::new() } else { format!(" and band {bands_hz:?} Hz") }
        ),
        crate::inference::likelihood::Scale::Fixed { .. } => "given variances".into(),
    };
    let errs = match &p0.noise.errors {
        crate::inference::likelihood::ErrorLaw::Gaussian => "Gaussian errors".to_string(),
        crate::inference::likelihood::ErrorLaw::StudentT { nu: Some(nu) } => {
            format!("Student-t errors (nu = {nu})")
        }
        crate::inference::likelihood::ErrorLaw::StudentT { nu: None } => {
            "Student-t errors (nu inferred)".to_string()
        }
    };
    rep.paragraph(&format!(
        "Likelihood: {noise}, {errs}{}; the prediction is the forward model's expected H1 (with the declared measurement model). Priors per parameter are in the `summary` table's prior_sd and in the study file; the default is log-uniform over a decade either side of the initial value. Posterior draws: `draws.parquet` (`python scripts/to_arviz.py DIR` makes an ArviZ InferenceData).",
        if p0.noise.model_error > 0.0 {
            format!(", model-error floor {} relative", p0.noise.model_error)
        } else {
            String::new()
        }
    ));
    for p in posts {
        rep.heading(3, &format!("{} at level {}", p.model, p.level));
        let level = levels.iter().find(|l| l.name == p.level);
        let sums = summaries(p);
        let lap_sd = p.map.laplace.sd_physical();
        let best = &p.map.starts[p.map.best];
        let reached = p
            .map
            .starts
            .iter()
            .filter(|s| {
                (s.objective - best.objective).abs() <= 1e-6 * best.objective.abs().max(1.0)
            })
            .count();
        rep.paragraph(&format!(
            "MAP by {} L-BFGS starts ({} reached the best objective within 1e-6; best from a{} {} start), {:.1} s; Laplace log evidence {:.2} nats{}.",
            p.map.starts.len(),
            reached,
            if best.kind.starts_with(['a', 'e', 'i', 'o', 'u']) { "n" } else { "" },
            best.kind,
            p.map_seconds,
            p.map.laplace.log_evidence,
            if p.map.laplace.positive_definite { "" } else { " (Hessian not positive definite: not usable)" }
        ));
        for note in &p.notes {
            rep.paragraph(note);
        }
        if let Some(c) = p.linearisation_check {
            let (n, sd, lme, se, k) = (c.draws, c.sd, c.shift, c.shift_se, c.pareto_k);
            rep.paragraph(&format!(
                "The samplers saw the H1 measurement model's bias linearised at the MAP (`[inference] measurement = \"linearised\"`). On {n} posterior draws the exact operator's log likelihood minus the linearised one has sd {sd:.2e} nats and log mean exp {lme:+.3e} +- {se:.1e} nats (Pareto k {k:.2}); the latter is added to the evidence estimates (importance sampling from the linearised posterior) and its standard error joins theirs. {}{}",
                if sd > 0.3 {
                    "WARNING: the sd exceeds 0.3 nats, so this posterior's shape is not the exact one's. It happens when the model misfits the data by far more than the noise (the residual multiplies the linearisation's second-order error); for such a model the comparison is decided by the evidence gap, but for its exact posterior rerun with `measurement = \"exact\"`."
                } else {
                    "The posterior's shape is the exact operator's."
                },
                if c.reliable() {
                    ""
                } else {
                    " WARNING: the importance weights' Pareto k exceeds 0.7, so the correction (and every evidence of this model) is uncertain by more than its standard error says."
                }
            ));
        }
        let has_truth = level.is_some_and(|l| {
            l.truth
                .as_ref()
                .is_some_and(|t| t.law.eq_ignore_ascii_case(&p.model))
        });
        let mut headers = vec![
            "sampler".to_string(),
            "parameter".into(),
            "MAP".into(),
            "mean".into(),
            "sd".into(),
            "95 % interval".into(),
            "Laplace sd".into(),
            "R-hat".into(),
            "ESS bulk / tail".into(),
        ];
        if has_truth {
            headers.push("truth".into());
        }
        let mut rows = Vec::new();
        let mut warnings = Vec::new();
        for (s, (_, summ)) in p.samplers.iter().zip(&sums) {
            for (k, sm) in summ.iter().enumerate() {
                let (f, u) = scale(&p.units[k]);
                let unit = if u.is_empty() {
                    String::new()
                } else {
                    format!(" {u}")
                };
                let mut row = vec![
                    s.sampler.to_string(),
                    format!(
                        "{}{}",
                        p.names[k],
                        if unit.is_empty() {
                            String::new()
                        } else {
                            format!(" ({})", u)
                        }
                    ),
                    format!("{:.4}", p.map.map_physical[k] * f),
                    format!("{:.4}", sm.mean * f),
                    format!("{:.4}", sm.sd * f),
                    format!("[{:.4}, {:.4}]", sm.q2_5 * f, sm.q97_5 * f),
                    format!("{:.4}", lap_sd[k] * f),
                    format!("{:.4}", sm.r_hat),
                    format!("{:.0} / {:.0}", sm.ess_bulk, sm.ess_tail),
                ];
                if has_truth {
                    let t = level.map_or(f64::NAN, |l| truth_of(l, p, k));
                    row.push(format!("{:.4}", t * f));
                }
                rows.push(row);
                let _ = unit;
                if s.sampler == Sampler::Nuts {
                    if sm.r_hat > 1.01 {
                        warnings.push(format!("R-hat of {} is {:.3} > 1.01", p.names[k], sm.r_hat));
                    }
                    if sm.ess_bulk < 400.0 || sm.ess_tail < 400.0 {
                        warnings.push(format!(
                            "ESS of {} is {:.0} (bulk) / {:.0} (tail) < 400",
                            p.names[k], sm.ess_bulk, sm.ess_tail
                        ));
                    }
                }
            }
        }
        rep.table(&headers, &rows);
        for s in &p.samplers {
            let ev = match s.log_evidence {
                Some((z, se)) => format!("; log evidence {z:.2} +- {se:.2} nats"),
                None => String::new(),
            };
            rep.paragraph(&format!(
                "{}: {:.1} s, {} likelihood evaluations{ev}; {}",
                s.sampler,
                s.seconds,
                s.evaluations,
                s.notes.first().cloned().unwrap_or_default()
            ));
        }
        if warnings.is_empty() {
            rep.paragraph("Diagnostics: R-hat <= 1.01 and bulk and tail ESS >= 400 for every parameter (NUTS).");
        } else {
            rep.paragraph(&format!("**Warning:** {}.", warnings.join("; ")));
        }
        for (file, alt) in figures {
            if file.contains(&format!("_{}_{}.", p.level, p.model)) {
                rep.image(file, alt);
            }
        }
    }
    for (file, alt) in figures {
        if file.starts_with("fig_posterior_modulus_") {
            rep.image(file, alt);
        }
    }
}
