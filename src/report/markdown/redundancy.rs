//! report.md's sections on parameter redundancy (SVD of the scaled sensitivity at the MAP,
//! posterior sd over prior sd, the strongest posterior correlation) and initial-value
//! sensitivity (where the MAP search and the global RFM end from space-filling starts: basins,
//! iterations, stop reasons).

use crate::bayes::PosteriorResult;
use crate::output::Report;
use crate::pipeline::LevelResults;

/// The parameter redundancy section (when a posterior has its redundancy analysis).
pub(super) fn redundancy(rep: &mut Report, results: &[LevelResults], figures: &[(String, String)]) {
    let posts: Vec<&PosteriorResult> = results.iter().flat_map(|r| r.posteriors.iter()).collect();
    let img = |rep: &mut Report, prefix: &str| {
        for (f, alt) in figures {
            if f.starts_with(prefix) {
                rep.image(f, alt);
            }
        }
    };
    if posts.iter().any(|p| p.redundancy.is_ok()) {
        rep.heading(2, "Parameter redundancy");
        rep.paragraph("SVD of the scaled sensitivity at the MAP, S = d r / d ln p with r the whitened residual (real and imaginary parts over the noise model's sd): dimensionless, S^T S is the Fisher information in ln p, and the data determine the combination v_i of relative changes to about 1 / s_i. Identifiability: posterior sd over prior sd in the sampler's unconstrained coordinates (1: the data taught nothing).");
        let mut rows = Vec::new();
        for p in &posts {
            let Ok(r) = &p.redundancy else { continue };
            let smin = r.svd.singular_values.last().copied().unwrap_or(f64::NAN);
            let ratio = r.ratio();
            let d = r.names.len();
            // The strongest posterior correlation.
            let mut best = (0, 0, 0.0f64);
            for i in 0..d {
                for j in 0..i {
                    let c = r.correlation[i * d + j];
                    if c.abs() > best.2.abs() {
                        best = (i, j, c);
                    }
                }
            }
            rows.push(vec![
                p.level.clone(),
                p.model.clone(),
                r.svd
                    .singular_values
                    .iter()
                    .map(|s| format!("{s:.3e}"))
                    .collect::<Vec<_>>()
                    .join(", "),
                format!("{:.1}", r.svd.condition_number),
                format!(
                    "{} (s = {:.3e}: sd of this combination about {:.2e})",
                    r.weakest_text,
                    smin,
                    1.0 / smin
                ),
                if d > 1 {
                    format!("{}-{}: {:+.3}", r.names[best.0], r.names[best.1], best.2)
                } else {
                    "-".into()
                },
                r.names
                    .iter()
                    .zip(&ratio)
                    .map(|(n, x)| format!("{n} {x:.2e}"))
                    .collect::<Vec<_>>()
                    .join(", "),
            ]);
        }
        rep.table(
            &[
                "level",
                "model",
                "singular values",
                "condition number",
                "weakest direction",
                "strongest posterior correlation",
                "posterior sd / prior sd",
            ],
            &rows,
        );
        if let Some(p) = posts
            .iter()
            .find(|p| p.model.eq_ignore_ascii_case("model5") && p.redundancy.is_ok())
        {
            if let Ok(r) = &p.redundancy {
                let d = r.names.len();
                let e0 = r.names.iter().position(|n| n == "eta0");
                let txt = match e0 {
                    Some(k) => {
                        let empty = Vec::new();
                        let (_, v) = r.svd.weakest().unwrap_or((&0.0, &empty));
                        let corr: Vec<String> = (0..d)
                            .filter(|j| *j != k)
                            .map(|j| format!("{} {:+.3}", r.names[j], r.correlation[k * d + j]))
                            .collect();
                        format!(
                            "Model 5 at {}: eta0 carries {:.2} of the weakest direction ({}); its posterior correlations: {}; its posterior sd is {:.2e} of its prior sd. The series dashpot eta0 and the Maxwell branch (E1, eta1) both add loss at low frequency, and the data separate them least.",
                            p.level,
                            v.get(k).copied().unwrap_or(f64::NAN).abs(),
                            r.weakest_text,
                            corr.join(", "),
                            r.ratio()[k]
                        )
                    }
                    None => String::new(),
                };
                if !txt.is_empty() {
                    rep.paragraph(&txt);
                }
            }
        }
        img(rep, "fig_identifiability");
    }
}

/// The initial-value sensitivity section (when a posterior has its basins).
pub(super) fn basins(rep: &mut Report, results: &[LevelResults], figures: &[(String, String)]) {
    let posts: Vec<&PosteriorResult> = results.iter().flat_map(|r| r.posteriors.iter()).collect();
    let img = |rep: &mut Report, prefix: &str| {
        for (f, alt) in figures {
            if f.starts_with(prefix) {
                rep.image(f, alt);
            }
        }
    };
    if posts.iter().any(|p| p.basins.is_some()) {
        rep.heading(2, "Initial-value sensitivity (basins)");
        let tol = posts
            .iter()
            .find_map(|p| p.basins.as_ref().map(|b| b.tolerance_sd))
            .unwrap_or(0.1);
        rep.paragraph(&format!(
            "The MAP search (argmin L-BFGS on -log posterior) and the deterministic global RFM from the same space-filling starts over the prior box (Latin hypercube in prior quantiles) plus the study's initial values (the paper's Table 4). End points within {tol} Laplace posterior sd of a basin's best point (every unconstrained coordinate) share the basin; basin 0 is the best end point (the global MAP for the search; the lowest FRF residual for the RFM). The RFM runs one pass on the measured column (without the leakage-corrected second pass)."
        ));
        let mut rows = Vec::new();
        let mut sentences = Vec::new();
        for p in &posts {
            let Some(b) = &p.basins else { continue };
            for m in &b.methods {
                let it: Vec<u64> = m
                    .starts
                    .iter()
                    .filter(|s| s.basin.is_some())
                    .map(|s| s.iterations)
                    .collect();
                let mut its = it.clone();
                its.sort();
                let med = its.get(its.len() / 2).copied().unwrap_or(0);
                let maxit = its.last().copied().unwrap_or(0);
                rows.push(vec![
                    p.level.clone(),
                    p.model.clone(),
                    m.method.to_string(),
                    m.starts.len().to_string(),
                    m.basins.len().to_string(),
                    format!("{:.1} %", 100.0 * m.fraction_at_map(tol)),
                    format!("{:.1} %", 100.0 * m.fraction_best()),
                    format!("{med} / {maxit}"),
                    m.stop_reasons()
                        .iter()
                        .map(|(r, n)| format!("{r}: {n}"))
                        .collect::<Vec<_>>()
                        .join("; "),
                    format!("{:.1}", m.seconds),
                ]);
                if let Some(s) = m.starts.iter().find(|s| s.kind == "initial") {
                    sentences.push(match s.basin {
                        Some(k) => format!(
                            "{} at {} ({}): the paper's initial values end in basin {k} of {} ({}; {} of {} starts end there, {:.1} sd from the MAP).",
                            p.model,
                            p.level,
                            m.method,
                            m.basins.len(),
                            if m.distance_to_map_sd[k] <= tol { "the MAP's basin".to_string() } else { "NOT the MAP's basin".to_string() },
                            m.basins[k].count,
                            m.starts.len(),
                            m.distance_to_map_sd[k]
                        ),
                        None => format!("{} at {} ({}): the search from the paper's initial values failed ({}).", p.model, p.level, m.method, s.stop_reason),
                    });
                }
            }
        }
        rep.table(
            &[
                "level",
                "model",
                "method",
                "starts",
                "basins",
                "reaching the MAP",
                "in basin 0",
                "iterations median / max",
                "stop reasons",
                "seconds",
            ],
            &rows,
        );
        for s in sentences {
            rep.paragraph(&s);
        }
        img(rep, "fig_basins_");
    }
}
