//! The tables of the `[inference]` part of a run. Tables (parquet):
//!
//! | table | columns (unit) |
//! |---|---|
//! | `draws` | level, model, sampler, chain, draw, one column per parameter (SI: E0 in Pa, eta1 in Pa s, noise scales in 1), lp, log_lik, log_prior (nats), step_size, tree_depth, n_steps, diverging, energy (NUTS; NaN for TMCMC) |
//! | `summary` | level, model, sampler, parameter, unit, map_status (`converged` / `flagged`: the MAP's), map_status_reason, mean, sd, median, q2_5, q97_5, q5, q95, hdi_lower, hdi_upper (94 %), r_hat, ess_bulk, ess_tail, mcse_mean, mcse_sd, prior_sd, map, laplace_sd, truth |
//! | `starts` | level, model, start, kind (initial / design / rfm), objective (nats), iterations, stop_reason, start_<param>, end_<param> (SI) |
//! | `laplace` | level, model, parameter, unit, status (`converged` / `flagged`: the MAP's), status_reason, map, mode_x, sd, log_evidence (nats), log_likelihood, log_prior, positive_definite |
//! | `sampler_runs` | level, model, sampler, seconds, evaluations, ess_bulk_min, ess_per_1000_evals, ess_per_second, log_evidence, log_evidence_se |
//!
//! The draws table is what `scripts/to_arviz.py` turns into an ArviZ InferenceData.

use crate::bayes::PosteriorResult;
use crate::inference::diagnostics::{summarize_with_hdi, Summary, DEFAULT_HDI_PROB};
use crate::output::{Columns as Cols, Table};
use crate::stage::{LevelData, RunError};

/// The diagnostics of one sampler's draws (one Summary per parameter).
pub(crate) fn summaries(p: &PosteriorResult) -> Vec<(String, Vec<Summary>)> {
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

pub(crate) fn truth_of(level: &LevelData, p: &PosteriorResult, k: usize) -> f64 {
    level
        .truth
        .as_ref()
        .filter(|t| t.law.eq_ignore_ascii_case(&p.model))
        .and_then(|t| t.params.get(k).copied())
        .unwrap_or(f64::NAN)
}

/// All inference tables (empty when no level has posteriors).
pub(super) fn tables(
    levels: &[LevelData],
    posts: &[&PosteriorResult],
) -> Result<Vec<Table>, RunError> {
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
        let map_status = p.map_status();
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
                su.s("map_status", map_status.label().to_string());
                su.s("map_status_reason", map_status.reason_text());
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
            la.s("status", map_status.label().to_string());
            la.s("status_reason", map_status.reason_text());
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
