//! Tables, figures and report sections of the comparison across levels, parameter redundancy
//! and initial-value sensitivity. Tables (parquet):
//!
//! | table | columns (unit) |
//! |---|---|
//! | `level_change` | model, level_low, level_high, quantity (storage = E', loss = E''), point (mode 1, mode 2, chosen), freq_hz (Hz), low_median, low_q2_5, low_q97_5, high_median, high_q2_5, high_q97_5, change_median, change_q2_5, change_q25, change_q75, change_q97_5 (Pa; change = high - low), rel_change_median, rel_change_q2_5, rel_change_q97_5 (1), p_lower (1; P(high < low), for E' the probability that the adhesive is softer at the higher level), truth_low, truth_high, truth_change (Pa; NaN without a truth), truth_in_95 (1/0), n_pairs |
//! | `level_evidence` | model, level_low, level_high, method (laplace / tmcmc), log_z_shared, se_shared, log_z_separate, se_separate, log_bayes_factor (nats; separate minus shared), seconds, shared_<param> (SI, the shared posterior's MAP) |
//! | `redundancy` | level, model, kind (svd / parameter), index, parameter, singular_value (1), condition_number (1), direction (text), v_<param> (right singular vector, d ln p), posterior_sd_x, prior_sd_x, sd_ratio (1; unconstrained coordinates), corr_<param> (posterior correlation, unconstrained coordinates) |
//! | `basins` | level, model, method (map / rfm), start, kind (initial / design), basin (-1: failed), objective (map: -log posterior up to log Z, nats; rfm: relative FRF residual), iterations, stop_reason, basin_distance_sd (the basin's distance from the MAP in Laplace sd), start_<param>, end_<param> (SI) |

use super::{LevelResults, RunError};
use crate::bayes::levels::LevelComparison;
use crate::bayes::PosteriorResult;
use crate::output::{Columns as Cols, Report, Table};

fn union_names<'a>(names: impl Iterator<Item = &'a [String]>) -> Vec<String> {
    let mut all: Vec<String> = Vec::new();
    for ns in names {
        for n in ns {
            if !all.contains(n) {
                all.push(n.clone());
            }
        }
    }
    all
}

fn comparisons(results: &[LevelResults]) -> Vec<&LevelComparison> {
    results
        .iter()
        .filter_map(|r| r.across_levels.as_ref())
        .collect()
}

/// The tables (only those with rows).
pub fn tables(results: &[LevelResults]) -> Result<Vec<Table>, RunError> {
    let mut out = Vec::new();
    let cmps = comparisons(results);
    let (mut ch, mut ev) = (Cols::default(), Cols::default());
    let (mut n_ch, mut n_ev) = (0, 0);
    let ev_names = union_names(
        cmps.iter()
            .flat_map(|c| c.evidence.iter().map(|e| e.names.as_slice())),
    );
    for c in &cmps {
        for r in &c.rows {
            n_ch += 1;
            ch.s("model", r.model.clone());
            ch.s("level_low", c.low.clone());
            ch.s("level_high", c.high.clone());
            ch.s("quantity", r.quantity.to_string());
            ch.s("point", r.point.clone());
            ch.f("freq_hz", "Hz", r.freq_hz);
            let s = &r.stats;
            for (n, v) in [
                ("low_median", s.low.median),
                ("low_q2_5", s.low.q2_5),
                ("low_q97_5", s.low.q97_5),
                ("high_median", s.high.median),
                ("high_q2_5", s.high.q2_5),
                ("high_q97_5", s.high.q97_5),
                ("change_median", s.change.median),
                ("change_q2_5", s.change.q2_5),
                ("change_q25", s.change.q25),
                ("change_q75", s.change.q75),
                ("change_q97_5", s.change.q97_5),
            ] {
                ch.f(n, "Pa", v);
            }
            ch.f("rel_change_median", "1", s.rel_change.median);
            ch.f("rel_change_q2_5", "1", s.rel_change.q2_5);
            ch.f("rel_change_q97_5", "1", s.rel_change.q97_5);
            ch.f("p_lower", "1", s.p_lower);
            ch.f("truth_low", "Pa", r.truth_low);
            ch.f("truth_high", "Pa", r.truth_high);
            let tc = r.truth_high - r.truth_low;
            ch.f("truth_change", "Pa", tc);
            ch.i(
                "truth_in_95",
                (tc.is_finite() && s.change.contains95(tc)) as i64,
            );
            ch.i("n_pairs", s.n_pairs as i64);
        }
        for e in &c.evidence {
            n_ev += 1;
            ev.s("model", e.model.clone());
            ev.s("level_low", c.low.clone());
            ev.s("level_high", c.high.clone());
            ev.s("method", e.method.to_string());
            ev.f("log_z_shared", "nats", e.log_z_shared);
            ev.f("se_shared", "nats", e.se_shared);
            ev.f("log_z_separate", "nats", e.log_z_separate);
            ev.f("se_separate", "nats", e.se_separate);
            ev.f("log_bayes_factor", "nats", e.log_bayes_factor());
            ev.f("seconds", "s", e.seconds);
            for n in &ev_names {
                let v = e
                    .names
                    .iter()
                    .position(|m| m == n)
                    .map_or(f64::NAN, |k| e.shared_map[k]);
                ev.f(&format!("shared_{}", n.to_ascii_lowercase()), "", v);
            }
        }
    }
    if n_ch > 0 {
        out.push(ch.table("level_change")?);
    }
    if n_ev > 0 {
        out.push(ev.table("level_evidence")?);
    }
    let posts: Vec<&PosteriorResult> = results.iter().flat_map(|r| r.posteriors.iter()).collect();
    let names = union_names(posts.iter().map(|p| p.names.as_slice()));
    let mut rd = Cols::default();
    let mut n_rd = 0;
    for p in &posts {
        let Ok(r) = &p.redundancy else { continue };
        let mut row = |rd: &mut Cols, kind: &str, idx: usize| {
            n_rd += 1;
            rd.s("level", p.level.clone());
            rd.s("model", p.model.clone());
            rd.s("kind", kind.to_string());
            rd.i("index", idx as i64);
        };
        for (i, sv) in r.svd.singular_values.iter().enumerate() {
            row(&mut rd, "svd", i);
            rd.s("parameter", String::new());
            rd.f("singular_value", "1", *sv);
            rd.f("condition_number", "1", r.svd.condition_number);
            rd.s(
                "direction",
                crate::inference::identifiability::combination_text(
                    &r.law_names,
                    &r.svd.right_vectors[i],
                ),
            );
            for n in &names {
                let v = r
                    .law_names
                    .iter()
                    .position(|m| m == n)
                    .map_or(f64::NAN, |k| r.svd.right_vectors[i][k]);
                rd.f(&format!("v_{}", n.to_ascii_lowercase()), "1", v);
            }
            for (c, v) in [
                ("posterior_sd_x", f64::NAN),
                ("prior_sd_x", f64::NAN),
                ("sd_ratio", f64::NAN),
            ] {
                rd.f(c, "1", v);
            }
            for n in &names {
                rd.f(&format!("corr_{}", n.to_ascii_lowercase()), "1", f64::NAN);
            }
        }
        let d = r.names.len();
        let ratio = r.ratio();
        for (k, name) in r.names.iter().enumerate() {
            row(&mut rd, "parameter", k);
            rd.s("parameter", name.clone());
            rd.f("singular_value", "1", f64::NAN);
            rd.f("condition_number", "1", f64::NAN);
            rd.s("direction", String::new());
            for n in &names {
                rd.f(&format!("v_{}", n.to_ascii_lowercase()), "1", f64::NAN);
            }
            rd.f("posterior_sd_x", "1", r.posterior_sd_x[k]);
            rd.f("prior_sd_x", "1", r.prior_sd_x[k]);
            rd.f("sd_ratio", "1", ratio[k]);
            for n in &names {
                let v = r
                    .names
                    .iter()
                    .position(|m| m == n)
                    .map_or(f64::NAN, |j| r.correlation[k * d + j]);
                rd.f(&format!("corr_{}", n.to_ascii_lowercase()), "1", v);
            }
        }
    }
    if n_rd > 0 {
        out.push(rd.table("redundancy")?);
    }
    let mut ba = Cols::default();
    let mut n_ba = 0;
    for p in &posts {
        let Some(b) = &p.basins else { continue };
        for m in &b.methods {
            for s in &m.starts {
                n_ba += 1;
                ba.s("level", p.level.clone());
                ba.s("model", p.model.clone());
                ba.s("method", m.method.to_string());
                ba.i("start", s.index as i64);
                ba.s("kind", s.kind.to_string());
                ba.i("basin", s.basin.map_or(-1, |b| b as i64));
                ba.f("objective", "", s.objective);
                ba.i("iterations", s.iterations as i64);
                ba.s("stop_reason", s.stop_reason.clone());
                ba.f(
                    "basin_distance_sd",
                    "1",
                    s.basin.map_or(f64::NAN, |k| m.distance_to_map_sd[k]),
                );
                for n in &names {
                    let k = b.names.iter().position(|m| m == n);
                    // The parameter's unit from any posterior that has it (a column's unit
                    // is set by its first row, which may be a model without the parameter).
                    let unit = posts
                        .iter()
                        .find_map(|q| {
                            let bq = q.basins.as_ref()?;
                            bq.names
                                .iter()
                                .position(|m| m == n)
                                .map(|k| q.units[k].clone())
                        })
                        .unwrap_or_default();
                    ba.f(
                        &format!("start_{}", n.to_ascii_lowercase()),
                        &unit,
                        k.map_or(f64::NAN, |k| s.start.get(k).copied().unwrap_or(f64::NAN)),
                    );
                    ba.f(
                        &format!("end_{}", n.to_ascii_lowercase()),
                        &unit,
                        k.and_then(|k| s.end.as_ref().and_then(|e| e.get(k).copied()))
                            .unwrap_or(f64::NAN),
                    );
                }
            }
        }
    }
    if n_ba > 0 {
        out.push(ba.table("basins")?);
    }
    Ok(out)
}

/// The two parameters of a basin map: the largest entries of the weakest direction.
fn map_pair(p: &PosteriorResult, nl: usize) -> (usize, usize) {
    let Ok(r) = &p.redundancy else {
        return (0, 1.min(nl - 1));
    };
    let Some((_, v)) = r.svd.weakest() else {
        return (0, 1.min(nl - 1));
    };
    let mut idx: Vec<usize> = (0..v.len()).collect();
    idx.sort_by(|a, b| v[*b].abs().total_cmp(&v[*a].abs()));
    let (a, b) = (idx[0], idx.get(1).copied().unwrap_or(idx[0]));
    (a.min(b), a.max(b))
}

/// Figures: posterior bands of E' and E'' of every model and level on one figure; the
/// identifiability figure; basin maps per level, model and method.
pub fn figures(
    dir: &std::path::Path,
    results: &[LevelResults],
) -> Result<Vec<(String, String)>, RunError> {
    use crate::plot::posterior::{posterior_bands_figure, BandGroup};
    use crate::plot::{line_figure, Curve};
    let posts: Vec<&PosteriorResult> = results.iter().flat_map(|r| r.posteriors.iter()).collect();
    let mut out = Vec::new();
    if comparisons(results).is_empty()
        && posts
            .iter()
            .all(|p| p.basins.is_none() && p.redundancy.is_err())
    {
        return Ok(out);
    }
    // 1. E*(f) bands of every model and level.
    let freq: Vec<f64> = (0..=100).map(|k| 1.0 + 4.99 * k as f64).collect();
    let mut groups = Vec::new();
    for p in &posts {
        let (Ok(law), Some(s)) = (
            crate::material::model_from_name(&p.model, None),
            p.figure_sampler(),
        ) else {
            continue;
        };
        let n = s.draws.chain.len();
        let step = (n / 300).max(1);
        let nl = law.n_params();
        let (mut st, mut lo) = (Vec::new(), Vec::new());
        for r in (0..n).step_by(step) {
            let par: Vec<f64> = (0..nl).map(|k| s.draws.values[k][r]).collect();
            let e: Vec<crate::common::C64> = freq
                .iter()
                .map(|f| law.modulus(&par, std::f64::consts::TAU * f))
                .collect();
            st.push(e.iter().map(|z| z.re).collect());
            lo.push(e.iter().map(|z| z.im).collect());
        }
        groups.push(BandGroup {
            label: format!("{} {}", p.model, p.level),
            freq_hz: freq.clone(),
            storage: st,
            loss: lo,
        });
    }
    if groups.len() > 1 && !comparisons(results).is_empty() {
        let name = "fig_levels_modulus.png".to_string();
        posterior_bands_figure(
            &dir.join(&name),
            &groups,
            &[],
            "E'(f) and E''(f) of every model and level: median, 50 % and 95 % bands",
        )?;
        out.push((
            name,
            "posterior bands of E* of every model and level".to_string(),
        ));
    }
    // 2. Identifiability.
    let names = union_names(posts.iter().map(|p| p.names.as_slice()));
    let mut curves = Vec::new();
    for p in &posts {
        let Ok(r) = &p.redundancy else { continue };
        let ratio = r.ratio();
        let x: Vec<f64> = r
            .names
            .iter()
            .map(|n| names.iter().position(|m| m == n).unwrap_or(0) as f64 + 1.0)
            .collect();
        curves.push(Curve::points(format!("{} {}", p.model, p.level), x, ratio));
    }
    if !curves.is_empty() {
        let name = "fig_identifiability.png".to_string();
        let xl = names
            .iter()
            .enumerate()
            .map(|(i, n)| format!("{} {n}", i + 1))
            .collect::<Vec<_>>()
            .join(", ");
        line_figure(
            dir.join("fig_identifiability"),
            "Identifiability: posterior sd / prior sd (unconstrained coordinates)",
            &format!("parameter ({xl})"),
            "posterior sd / prior sd",
            &curves,
            true,
        )?;
        out.push((name, "identifiability per parameter".to_string()));
    }
    // 3. Basin maps.
    for p in &posts {
        let Some(b) = &p.basins else { continue };
        let nl = p.names.len().min(b.names.len());
        if nl < 2 {
            continue;
        }
        let (i, j) = map_pair(p, nl);
        for m in &b.methods {
            let mut curves = Vec::new();
            let n_show = m.basins.len().min(4);
            for k in 0..=n_show {
                let pick: Vec<&crate::bayes::basins::BasinStart> = m
                    .starts
                    .iter()
                    .filter(|s| match s.basin {
                        Some(bb) if k < n_show => bb == k,
                        Some(bb) => bb >= n_show,
                        None => false,
                    })
                    .collect();
                if pick.is_empty() {
                    continue;
                }
                let label = if k < n_show {
                    let d = m.distance_to_map_sd[k];
                    format!(
                        "basin {k} ({} starts, {:.1} sd from the MAP)",
                        pick.len(),
                        d
                    )
                } else {
                    format!("other basins ({} starts)", pick.len())
                };
                curves.push(Curve::points(
                    label,
                    pick.iter().map(|s| s.start[i].log10()).collect(),
                    pick.iter().map(|s| s.start[j].log10()).collect(),
                ));
            }
            let failed: Vec<&crate::bayes::basins::BasinStart> =
                m.starts.iter().filter(|s| s.basin.is_none()).collect();
            if !failed.is_empty() {
                curves.push(Curve::points(
                    format!("failed ({})", failed.len()),
                    failed.iter().map(|s| s.start[i].log10()).collect(),
                    failed.iter().map(|s| s.start[j].log10()).collect(),
                ));
            }
            if let Some(s) = m.starts.iter().find(|s| s.kind == "initial") {
                curves.push(
                    Curve::points(
                        "initial values (Table 4)",
                        vec![s.start[i].log10()],
                        vec![s.start[j].log10()],
                    )
                    .with_color((0, 0, 0)),
                );
            }
            if curves.is_empty() {
                continue;
            }
            let stem = format!("fig_basins_{}_{}_{}", p.level, p.model, m.method);
            line_figure(
                dir.join(&stem),
                &format!(
                    "{} at {}: where {} starts end ({})",
                    p.model,
                    p.level,
                    m.method.to_uppercase(),
                    if m.method == "map" {
                        "L-BFGS on -log posterior"
                    } else {
                        "global RFM"
                    }
                ),
                &format!("log10 {} ({}) at the start", p.names[i], p.units[i]),
                &format!("log10 {} ({}) at the start", p.names[j], p.units[j]),
                &curves,
                false,
            )?;
            out.push((
                format!("{stem}.png"),
                format!("basin map of {} at {} ({})", p.model, p.level, m.method),
            ));
        }
    }
    Ok(out)
}

fn mpa(v: f64) -> String {
    format!("{:.3}", v * 1e-6)
}

/// Report sections.
pub fn report(rep: &mut Report, results: &[LevelResults], figures: &[(String, String)]) {
    let posts: Vec<&PosteriorResult> = results.iter().flat_map(|r| r.posteriors.iter()).collect();
    let img = |rep: &mut Report, prefix: &str| {
        for (f, alt) in figures {
            if f.starts_with(prefix) {
                rep.image(f, alt);
            }
        }
    };
    for c in comparisons(results) {
        rep.heading(
            2,
            &format!("Across excitation levels: {} to {}", c.low, c.high),
        );
        let force = |f: Option<f64>| f.map_or(String::new(), |f| format!(" ({f} N RMS)"));
        rep.paragraph(&format!(
            "Change of E' and E'' from level {}{} to level {}{} over paired posterior draws of the two levels (independent posteriors), at the first two bending modes of the joint (from the lower level's MAP) and at chosen frequencies (`[inference.across_levels] freq_hz`). P(softer) is the probability that E' (or E'') is lower at the higher level. MPa.",
            c.low, force(c.force_low_n), c.high, force(c.force_high_n)
        ));
        let headers = [
            "model",
            "quantity",
            "point",
            "f (Hz)",
            "low median",
            "high median",
            "change median",
            "change 95 % interval",
            "P(lower at high level)",
            "truth's change",
        ];
        let rows: Vec<Vec<String>> = c
            .rows
            .iter()
            .map(|r| {
                let s = &r.stats;
                let tc = r.truth_high - r.truth_low;
                vec![
                    r.model.clone(),
                    if r.quantity == "storage" {
                        "E'".into()
                    } else {
                        "E''".into()
                    },
                    r.point.clone(),
                    format!("{:.1}", r.freq_hz),
                    mpa(s.low.median),
                    mpa(s.high.median),
                    mpa(s.change.median),
                    format!("[{}, {}]", mpa(s.change.q2_5), mpa(s.change.q97_5)),
                    format!("{:.3}", s.p_lower),
                    if tc.is_finite() {
                        format!(
                            "{}{}",
                            mpa(tc),
                            if s.change.contains95(tc) {
                                " (inside)"
                            } else {
                                " (OUTSIDE)"
                            }
                        )
                    } else {
                        "-".into()
                    },
                ]
            })
            .collect();
        rep.table(&headers, &rows);
        if !c.evidence.is_empty() {
            rep.paragraph("Shared or separate law parameters, decided by evidence: the shared posterior's likelihood is the product of both levels' likelihoods (noise coordinates per level), against separate parameters per level (log Z_low + log Z_high). log B = log Z_separate - log Z_shared: positive favours a law that changes with the excitation level. Evidence depends on the priors (the same per-parameter priors in both hypotheses here).");
            let rows: Vec<Vec<String>> = c
                .evidence
                .iter()
                .map(|e| {
                    let b = e.log_bayes_factor();
                    vec![
                        e.model.clone(),
                        e.method.to_string(),
                        format!("{:.2}", e.log_z_shared),
                        format!("{:.2}", e.log_z_separate),
                        format!("{b:.1}"),
                        if b > 5.0 {
                            "separate (level-dependent law) decisively".into()
                        } else if b < -5.0 {
                            "shared (no level dependence) decisively".into()
                        } else {
                            "not decisive (|log B| <= 5)".into()
                        },
                    ]
                })
                .collect();
            rep.table(
                &[
                    "model",
                    "method",
                    "log Z shared",
                    "log Z separate",
                    "log B (separate - shared)",
                    "favours",
                ],
                &rows,
            );
        }
        for n in &c.notes {
            rep.paragraph(&format!("Note: {n}."));
        }
        img(rep, "fig_levels_modulus");
    }
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
