//! Result tables and report section of the `[inference]` part of a run. Tables (parquet):
//!
//! | table | columns (unit) |
//! |---|---|
//! | `draws` | level, model, sampler, chain, draw, one column per parameter (SI: E0 in Pa, eta1 in Pa s, noise scales in 1), lp, log_lik, log_prior (nats), step_size, tree_depth, n_steps, diverging, energy (NUTS; NaN for TMCMC) |
//! | `summary` | level, model, sampler, parameter, unit, mean, sd, median, q2_5, q97_5, q5, q95, hdi_lower, hdi_upper (94 %), r_hat, ess_bulk, ess_tail, mcse_mean, mcse_sd, prior_sd, map, laplace_sd, truth |
//! | `starts` | level, model, start, kind (initial / design / rfm), objective (nats), iterations, stop_reason, start_<param>, end_<param> (SI) |
//! | `laplace` | level, model, parameter, unit, map, mode_x, sd, log_evidence (nats), log_likelihood, log_prior, positive_definite |
//! | `sampler_runs` | level, model, sampler, seconds, evaluations, ess_bulk_min, ess_per_1000_evals, ess_per_second, log_evidence, log_evidence_se |
//!
//! The draws table is what `scripts/to_arviz.py` turns into an ArviZ InferenceData.

use super::{LevelData, RunError};
use crate::bayes::PosteriorResult;
use crate::inference::diagnostics::{summarize_with_hdi, Summary, DEFAULT_HDI_PROB};
use crate::inference::Sampler;
use crate::output::{Columns as Cols, Report, Table};

/// The diagnostics of one sampler's draws (one Summary per parameter).
pub fn summaries(p: &PosteriorResult) -> Vec<(String, Vec<Summary>)> {
    p.samplers
        .iter()
        .map(|s| {
            let by = s.draws.by_chain();
            (
                s.sampler.to_string(),
                summarize_with_hdi(&by, DEFAULT_HDI_PROB).unwrap_or_default(),
            )
        })
        .collect()
}

fn truth_of(level: &LevelData, p: &PosteriorResult, k: usize) -> f64 {
    level
        .truth
        .as_ref()
        .filter(|t| t.law.eq_ignore_ascii_case(&p.model))
        .and_then(|t| t.params.get(k).copied())
        .unwrap_or(f64::NAN)
}

/// All inference tables (empty when no level has posteriors).
pub fn tables(levels: &[LevelData], posts: &[&PosteriorResult]) -> Result<Vec<Table>, RunError> {
    if posts.is_empty() {
        return Ok(Vec::new());
    }
    let mut all_names: Vec<String> = Vec::new();
    for p in posts {
        for n in &p.names {
            if !all_names.contains(n) {
                all_names.push(n.clone());
            }
        }
    }
    let unit_of = |n: &str| -> String {
        posts
            .iter()
            .find_map(|p| {
                p.names
                    .iter()
                    .position(|m| m == n)
                    .map(|k| p.units[k].clone())
            })
            .unwrap_or_default()
    };
    let (mut dr, mut su, mut st, mut la, mut runs) = (
        Cols::default(),
        Cols::default(),
        Cols::default(),
        Cols::default(),
        Cols::default(),
    );
    for p in posts {
        let level = levels.iter().find(|l| l.name == p.level);
        let sums = summaries(p);
        for (s, (_, summ)) in p.samplers.iter().zip(&sums) {
            let d = &s.draws;
            for r in 0..d.chain.len() {
                dr.s("level", p.level.clone());
                dr.s("model", p.model.clone());
                dr.s("sampler", s.sampler.to_string());
                dr.i("chain", d.chain[r] as i64);
                dr.i("draw", d.draw[r] as i64);
                for n in &all_names {
                    let v = p
                        .names
                        .iter()
                        .position(|m| m == n)
                        .map_or(f64::NAN, |k| d.values[k][r]);
                    dr.f(&n.to_ascii_lowercase(), &unit_of(n), v);
                }
                dr.f("lp", "nats", d.lp[r]);
                dr.f("log_lik", "nats", d.log_lik[r]);
                dr.f("log_prior", "nats", d.log_prior[r]);
                for name in ["step_size", "tree_depth", "n_steps", "diverging", "energy"] {
                    let v = d
                        .stats
                        .iter()
                        .find(|(n, _)| n == name)
                        .map_or(f64::NAN, |(_, v)| v[r]);
                    dr.f(name, "", v);
                }
            }
            let lap_sd = p.map.laplace.sd_physical();
            for (k, sm) in summ.iter().enumerate() {
                su.s("level", p.level.clone());
                su.s("model", p.model.clone());
                su.s("sampler", s.sampler.to_string());
                su.s("parameter", p.names[k].clone());
                su.s("unit", p.units[k].clone());
                // The unit varies by row (the parameter's, in `unit`).
                let u = "SI (see unit)";
                for (c, v) in [
                    ("mean", sm.mean),
                    ("sd", sm.sd),
                    ("median", sm.median),
                    ("q2_5", sm.q2_5),
                    ("q97_5", sm.q97_5),
                    ("q5", sm.q5),
                    ("q95", sm.q95),
                    ("hdi_lower", sm.hdi_lower),
                    ("hdi_upper", sm.hdi_upper),
                    ("mcse_mean", sm.mcse_mean),
                    ("mcse_sd", sm.mcse_sd),
                    ("prior_sd", p.priors[k].sd_physical()),
                    ("map", p.map.map_physical[k]),
                    ("laplace_sd", lap_sd[k]),
                    ("truth", level.map_or(f64::NAN, |l| truth_of(l, p, k))),
                ] {
                    su.f(c, u, v);
                }
                su.f("r_hat", "1", sm.r_hat);
                su.f("ess_bulk", "1", sm.ess_bulk);
                su.f("ess_tail", "1", sm.ess_tail);
            }
            let ess_min = summ
                .iter()
                .map(|s| s.ess_bulk.min(s.ess_tail))
                .fold(f64::INFINITY, f64::min);
            runs.s("level", p.level.clone());
            runs.s("model", p.model.clone());
            runs.s("sampler", s.sampler.to_string());
            runs.f("seconds", "s", s.seconds);
            runs.i("evaluations", s.evaluations as i64);
            runs.f("ess_min", "1", ess_min);
            runs.f(
                "ess_per_1000_evals",
                "1",
                1000.0 * ess_min / s.evaluations.max(1) as f64,
            );
            runs.f("ess_per_second", "1/s", ess_min / s.seconds.max(1e-9));
            let (lz, se) = s.log_evidence.unwrap_or((f64::NAN, f64::NAN));
            runs.f("log_evidence", "nats", lz);
            runs.f("log_evidence_se", "nats", se);
        }
        for s in &p.map.starts {
            st.s("level", p.level.clone());
            st.s("model", p.model.clone());
            st.i("start", s.index as i64);
            st.s("kind", s.kind.to_string());
            st.f("objective", "nats", s.objective);
            st.i("iterations", s.iterations as i64);
            st.s("stop_reason", s.stop_reason.clone());
            let sp = phys(p, &s.start_x);
            let ep = phys(p, &s.end_x);
            for n in &all_names {
                let k = p.names.iter().position(|m| m == n);
                let key = n.to_ascii_lowercase();
                st.f(
                    &format!("start_{key}"),
                    &unit_of(n),
                    k.map_or(f64::NAN, |k| sp[k]),
                );
                st.f(
                    &format!("end_{key}"),
                    &unit_of(n),
                    k.map_or(f64::NAN, |k| ep[k]),
                );
            }
        }
        let lp = &p.map.laplace;
        let sd = lp.sd_physical();
        for k in 0..p.names.len() {
            la.s("level", p.level.clone());
            la.s("model", p.model.clone());
            la.s("parameter", p.names[k].clone());
            la.s("unit", p.units[k].clone());
            // The unit varies by row (the parameter's, in `unit`).
            la.f("map", "SI (see unit)", p.map.map_physical[k]);
            la.f("mode_x", "SI (see unit)", lp.physical[k]);
            la.f("sd", "SI (see unit)", sd[k]);
            la.f("log_evidence", "nats", lp.log_evidence);
            la.f("log_likelihood", "nats", lp.log_likelihood);
            la.f("log_prior", "nats", lp.log_prior);
            la.i("positive_definite", lp.positive_definite as i64);
        }
    }
    Ok(vec![
        dr.table("draws")?,
        su.table("summary")?,
        st.table("starts")?,
        la.table("laplace")?,
        runs.table("sampler_runs")?,
    ])
}

/// Physical values of unconstrained coordinates through the posterior's priors.
fn phys(p: &PosteriorResult, x: &[f64]) -> Vec<f64> {
    x.iter()
        .zip(&p.priors)
        .map(|(x, pr)| pr.to_physical(*x))
        .collect()
}

/// Scale of a unit for the report.
fn scale(unit: &str) -> (f64, &'static str) {
    match unit {
        "Pa" => (1e-6, "MPa"),
        "Pa s" => (1e-3, "kPa s"),
        _ => (1.0, ""),
    }
}

/// The report's posterior section.
pub fn report(
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
        if let Some((n, sd, lme)) = p.linearisation_check {
            rep.paragraph(&format!(
                "The samplers saw the H1 measurement model's bias linearised at the MAP (`[inference] measurement = \"linearised\"`). On {n} posterior draws the exact operator's log likelihood minus the linearised one has sd {sd:.2e} nats and log mean exp {lme:+.3e} nats; the latter is added to the evidence estimates (importance sampling from the linearised posterior). {}",
                if sd > 0.3 {
                    "WARNING: the sd exceeds 0.3 nats, so this posterior's shape is not the exact one's. It happens when the model misfits the data by far more than the noise (the residual multiplies the linearisation's second-order error); for such a model the comparison is decided by the evidence gap, but for its exact posterior rerun with `measurement = \"exact\"`."
                } else {
                    "The posterior's shape is the exact operator's."
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

/// Posterior figures: per level and model the NUTS trace plot and the pair plot (MAP and the
/// Laplace 95 % ellipse), and per model the posterior bands of E'(f) and E''(f) of every level
/// on one figure. Returns (PNG file name, alt text).
pub fn figures(
    dir: &std::path::Path,
    posts: &[&PosteriorResult],
) -> Result<Vec<(String, String)>, RunError> {
    use crate::plot::posterior::{pair_figure, posterior_bands_figure, trace_figure, BandGroup};
    let mut out = Vec::new();
    for p in posts {
        let Some(s) = p.figure_sampler() else {
            continue;
        };
        let by = s.draws.by_chain();
        let name = format!("fig_trace_{}_{}.png", p.level, p.model);
        trace_figure(
            &dir.join(&name),
            &p.names,
            &by,
            &format!("{} at {}: {} draws", p.model, p.level, s.sampler),
        )?;
        out.push((name, format!("trace plot of {} at {}", p.model, p.level)));
        let name = format!("fig_pair_{}_{}.png", p.level, p.model);
        let lap = &p.map.laplace;
        pair_figure(
            &dir.join(&name),
            &p.names,
            &s.draws.values,
            Some(&p.map.map_physical),
            lap.positive_definite.then_some(lap.cov_physical.as_slice()),
            &format!(
                "{} at {}: posterior, MAP and Laplace 95 % ellipse",
                p.model, p.level
            ),
        )?;
        out.push((name, format!("pair plot of {} at {}", p.model, p.level)));
    }
    // Bands of E*(f) per model, levels together.
    let mut models: Vec<&str> = posts.iter().map(|p| p.model.as_str()).collect();
    models.dedup();
    for m in models {
        let Ok(law) = crate::material::model_from_name(m, None) else {
            continue;
        };
        let freq: Vec<f64> = (0..=100).map(|k| 1.0 + 4.99 * k as f64).collect();
        let mut groups = Vec::new();
        for p in posts.iter().filter(|p| p.model == m) {
            let Some(s) = p.figure_sampler() else {
                continue;
            };
            let n = s.draws.chain.len();
            let step = (n / 400).max(1);
            let nl = law.n_params();
            let mut storage = Vec::new();
            let mut loss = Vec::new();
            for r in (0..n).step_by(step) {
                let par: Vec<f64> = (0..nl).map(|k| s.draws.values[k][r]).collect();
                let e: Vec<crate::common::C64> = freq
                    .iter()
                    .map(|f| law.modulus(&par, std::f64::consts::TAU * f))
                    .collect();
                storage.push(e.iter().map(|z| z.re).collect());
                loss.push(e.iter().map(|z| z.im).collect());
            }
            groups.push(BandGroup {
                label: format!("level {}", p.level),
                freq_hz: freq.clone(),
                storage,
                loss,
            });
        }
        if groups.is_empty() {
            continue;
        }
        let name = format!("fig_posterior_modulus_{m}.png");
        posterior_bands_figure(
            &dir.join(&name),
            &groups,
            &[],
            &format!("{m}: posterior E'(f) and E''(f), median, 50 % and 95 % bands"),
        )?;
        out.push((name, format!("posterior bands of E* of {m}")));
    }
    Ok(out)
}
