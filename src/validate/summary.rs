//! The validation's verdicts from the merged tables: SBC rank histograms and their
//! chi-square uniformity test, interval coverage against the binomial 99 % band, the rate at
//! which the evidence picks the generating model, and evidence estimators against quadrature;
//! summary tables, the rank-histogram figure and a markdown summary.

use super::stats::{binom_band, uniformity};
use super::{ValidateError, LEVELS};
use crate::output::{ColumnData, Table};
use crate::plot::{line_figure_with, Curve, PlotParams};
use std::fmt::Write as _;
use std::path::Path;

/// Required p-value of the SBC uniformity test.
pub const SBC_P_MIN: f64 = 0.01;
/// Required fraction of replicates in which the evidence picks the generating model.
pub const SELECTION_MIN: f64 = 0.95;

/// What [`summarise`] concluded.
#[derive(Clone, Debug, Default)]
pub struct Verdict {
    pub markdown: String,
    pub tables: Vec<Table>,
    /// (check, passed) per acceptance check that had data.
    pub checks: Vec<(String, bool)>,
}

fn strs<'t>(t: &'t Table, c: &str) -> &'t [String] {
    match t.column(c) {
        Some(ColumnData::Str(v)) => v,
        _ => &[],
    }
}
fn f64s<'t>(t: &'t Table, c: &str) -> &'t [f64] {
    t.column(c).and_then(|c| c.as_f64()).unwrap_or(&[])
}
fn i64s<'t>(t: &'t Table, c: &str) -> &'t [i64] {
    match t.column(c) {
        Some(ColumnData::I64(v)) => v,
        _ => &[],
    }
}
fn bools<'t>(t: &'t Table, c: &str) -> &'t [bool] {
    match t.column(c) {
        Some(ColumnData::Bool(v)) => v,
        _ => &[],
    }
}
/// Distinct values in first-seen order.
fn distinct(v: &[String]) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    for s in v {
        if !out.contains(s) {
            out.push(s.clone());
        }
    }
    out
}

/// Verdicts, summary tables and the figure (written to `dir` unless `figures` is false).
pub fn summarise(
    merged: &[Table],
    dir: &Path,
    figures: bool,
    bins: usize,
    header: &str,
) -> Result<Verdict, ValidateError> {
    let get = |n: &str| merged.iter().find(|t| t.name() == n);
    let mut v = Verdict::default();
    let mut md = String::new();
    md.push_str(header);

    // SBC.
    if let Some(t) = get("sbc").filter(|t| t.n_rows() > 0) {
        let (par, rank, nl, status) = (
            strs(t, "parameter"),
            i64s(t, "rank"),
            i64s(t, "n_posterior"),
            strs(t, "status"),
        );
        let names = distinct(par);
        let l = nl.first().copied().unwrap_or(0) as usize;
        let per = (l + 1) / bins.max(1);
        let mut tab = (
            Vec::new(),
            Vec::new(),
            Vec::new(),
            Vec::new(),
            Vec::new(),
            Vec::new(),
        );
        let mut hist = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        let mut curves = Vec::new();
        let failed = status.iter().filter(|s| *s != "ok").count();
        writeln!(
            md,
            "## Simulation-based calibration (Model 4)\n\n{} prior draws, {l} posterior draws each (ranks 0..{l} in {bins} bins); {} failed rows.\n\n| parameter | draws | chi-square | dof | p | counts per bin | pass (p > {SBC_P_MIN}) |\n|---|---|---|---|---|---|---|",
            t.n_rows() / names.len().max(1),
            failed
        )
        .unwrap();
        for name in &names {
            let mut counts = vec![0usize; bins];
            for r in 0..t.n_rows() {
                if &par[r] == name && status[r] == "ok" {
                    counts[(rank[r] as usize / per.max(1)).min(bins - 1)] += 1;
                }
            }
            let (stat, dof, p) = uniformity(&counts);
            let pass = p > SBC_P_MIN;
            v.checks.push((format!("SBC {name}"), pass));
            writeln!(
                md,
                "| {name} | {} | {stat:.2} | {dof} | {p:.3} | {:?} | {} |",
                counts.iter().sum::<usize>(),
                counts,
                if pass { "yes" } else { "NO" }
            )
            .unwrap();
            tab.0.push(name.clone());
            tab.1.push(counts.iter().sum::<usize>() as i64);
            tab.2.push(stat);
            tab.3.push(dof as i64);
            tab.4.push(p);
            tab.5.push(pass);
            let mut x = Vec::new();
            let mut y = Vec::new();
            for (b, c) in counts.iter().enumerate() {
                hist.0.push(name.clone());
                hist.1.push(b as i64);
                hist.2.push(*c as i64);
                hist.3
                    .push(counts.iter().sum::<usize>() as f64 / bins as f64);
                x.extend([b as f64, (b + 1) as f64]);
                y.extend([*c as f64, *c as f64]);
            }
            curves.push(Curve::line(name.clone(), x, y));
        }
        let mut s = Table::new("sbc_summary");
        s.push_str("parameter", tab.0)?;
        s.push_i64("draws", "", tab.1)?;
        s.push_f64("chi2", "", tab.2)?;
        s.push_i64("dof", "", tab.3)?;
        s.push_f64("p_value", "", tab.4)?;
        s.push_bool("pass", tab.5)?;
        v.tables.push(s);
        let mut h = Table::new("sbc_histogram");
        h.push_str("parameter", hist.0)?;
        h.push_i64("bin", "", hist.1)?;
        h.push_i64("count", "", hist.2)?;
        h.push_f64("expected", "", hist.3)?;
        v.tables.push(h);
        if figures && !curves.is_empty() {
            let n = t.n_rows() / names.len().max(1);
            let e = n as f64 / bins as f64;
            // The binomial 99 % band of one bin's count under uniform ranks.
            let (lo, hi) = binom_band(n, 1.0 / bins as f64, 0.99);
            curves.push(
                Curve::line("expected", vec![0.0, bins as f64], vec![e, e]).with_color((0, 0, 0)),
            );
            curves.push(
                Curve::line("99 % band", vec![0.0, bins as f64], vec![lo as f64; 2])
                    .with_color((150, 150, 150)),
            );
            curves.push(
                Curve::line("", vec![0.0, bins as f64], vec![hi as f64; 2])
                    .with_color((150, 150, 150)),
            );
            line_figure_with(
                dir.join("sbc_ranks"),
                "SBC rank histograms, Model 4",
                "rank bin",
                "count",
                &curves,
                false,
                &PlotParams::default(),
            )
            .map_err(|e| ValidateError::Plot(e.to_string()))?;
            md.push_str("\nFigure: sbc_ranks.png (step per parameter, expected count and the per-bin binomial 99 % band).\n");
        }
        md.push('\n');
    }

    // Coverage.
    if let Some(t) = get("coverage").filter(|t| t.n_rows() > 0) {
        let (par, status) = (strs(t, "parameter"), strs(t, "status"));
        let names = distinct(par);
        let mut tab = (
            Vec::new(),
            Vec::new(),
            Vec::new(),
            Vec::new(),
            Vec::new(),
            Vec::new(),
            Vec::new(),
        );
        writeln!(md, "## Coverage of central credible intervals (Model 4 at the default data's truth)\n\n| parameter | level | hits / replicates | binomial 99 % band | pass |\n|---|---|---|---|---|").unwrap();
        for name in &names {
            for lv in LEVELS {
                let p = (lv * 100.0).round() as u32;
                let hit = bools(t, &format!("in{p}"));
                let rows: Vec<usize> = (0..t.n_rows())
                    .filter(|&r| &par[r] == name && status[r] == "ok")
                    .collect();
                let n = rows.len();
                let h = rows.iter().filter(|&&r| hit[r]).count();
                let (lo, hi) = binom_band(n, lv, 0.99);
                let pass = n > 0 && (lo..=hi).contains(&h);
                v.checks.push((format!("coverage {name} {p} %"), pass));
                writeln!(
                    md,
                    "| {name} | {p} % | {h} / {n} | {lo}-{hi} | {} |",
                    if pass { "yes" } else { "NO" }
                )
                .unwrap();
                tab.0.push(name.clone());
                tab.1.push(lv);
                tab.2.push(h as i64);
                tab.3.push(n as i64);
                tab.4.push(lo as i64);
                tab.5.push(hi as i64);
                tab.6.push(pass);
            }
        }
        let mut s = Table::new("coverage_summary");
        s.push_str("parameter", tab.0)?;
        s.push_f64("level", "", tab.1)?;
        s.push_i64("hits", "", tab.2)?;
        s.push_i64("replicates", "", tab.3)?;
        s.push_i64("band_lo", "", tab.4)?;
        s.push_i64("band_hi", "", tab.5)?;
        s.push_bool("pass", tab.6)?;
        v.tables.push(s);
        md.push('\n');
    }

    // Model selection.
    if let Some(t) = get("selection").filter(|t| t.n_rows() > 0) {
        let (gen, cand, best, unit) = (
            strs(t, "generating"),
            strs(t, "candidate"),
            bools(t, "best"),
            i64s(t, "unit"),
        );
        let models = distinct(cand);
        let mut tab = (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
        writeln!(md, "## Model selection by the Laplace evidence\n\n| generating | replicates | picked ({}) | correct | pass (>= {:.0} %) |\n|---|---|---|---|---|", models.join(", "), 100.0 * SELECTION_MIN).unwrap();
        for g in distinct(gen) {
            let mut units: Vec<i64> = (0..t.n_rows())
                .filter(|&r| gen[r] == g)
                .map(|r| unit[r])
                .collect();
            units.dedup();
            let picked: Vec<usize> = models
                .iter()
                .map(|m| {
                    (0..t.n_rows())
                        .filter(|&r| gen[r] == g && &cand[r] == m && best[r])
                        .count()
                })
                .collect();
            let n = units.len();
            let correct = models.iter().position(|m| *m == g).map_or(0, |i| picked[i]);
            let frac = correct as f64 / n.max(1) as f64;
            let pass = frac >= SELECTION_MIN;
            v.checks.push((format!("selection {g}"), pass));
            writeln!(
                md,
                "| {g} | {n} | {picked:?} | {:.1} % | {} |",
                100.0 * frac,
                if pass { "yes" } else { "NO" }
            )
            .unwrap();
            tab.0.push(g.clone());
            tab.1.push(n as i64);
            tab.2.push(correct as i64);
            tab.3.push(frac);
            tab.4.push(pass);
        }
        let mut s = Table::new("selection_summary");
        s.push_str("generating", tab.0)?;
        s.push_i64("replicates", "", tab.1)?;
        s.push_i64("correct", "", tab.2)?;
        s.push_f64("fraction", "", tab.3)?;
        s.push_bool("pass", tab.4)?;
        v.tables.push(s);
        md.push('\n');
    }

    // Quadrature.
    if let Some(t) = get("quadrature").filter(|t| t.n_rows() > 0) {
        let (model, est, unit, lz, se, status) = (
            strs(t, "model"),
            strs(t, "estimator"),
            i64s(t, "unit"),
            f64s(t, "log_evidence"),
            f64s(t, "se"),
            strs(t, "status"),
        );
        writeln!(md, "## Evidence against brute-force quadrature (two-parameter models)\n\n| model | unit | estimator | log Z (nat) | se | minus quadrature | pass (within 0.1 nat) |\n|---|---|---|---|---|---|---|").unwrap();
        let mut tab = (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for r in 0..t.n_rows() {
            if status[r] != "ok" {
                writeln!(
                    md,
                    "| {} | {} | {} | failed: {} | | | NO |",
                    model[r], unit[r], est[r], status[r]
                )
                .unwrap();
                v.checks
                    .push((format!("quadrature {} unit {}", model[r], unit[r]), false));
                continue;
            }
            let q = (0..t.n_rows())
                .find(|&j| unit[j] == unit[r] && est[j] == "quadrature")
                .map(|j| lz[j]);
            let diff = q.map_or(f64::NAN, |q| lz[r] - q);
            let pass = diff.abs() <= 0.1;
            if est[r] != "quadrature" {
                v.checks.push((
                    format!("quadrature {} unit {} {}", model[r], unit[r], est[r]),
                    pass,
                ));
            }
            writeln!(
                md,
                "| {} | {} | {} | {:.4} | {:.3} | {:+.4} | {} |",
                model[r],
                unit[r],
                est[r],
                lz[r],
                se[r],
                diff,
                if est[r] == "quadrature" {
                    "-"
                } else if pass {
                    "yes"
                } else {
                    "NO"
                }
            )
            .unwrap();
            tab.0.push(model[r].clone());
            tab.1.push(unit[r]);
            tab.2.push(est[r].clone());
            tab.3.push(lz[r]);
            tab.4.push(diff);
        }
        let mut s = Table::new("quadrature_summary");
        s.push_str("model", tab.0)?;
        s.push_i64("unit", "", tab.1)?;
        s.push_str("estimator", tab.2)?;
        s.push_f64("log_evidence", "nat", tab.3)?;
        s.push_f64("minus_quadrature", "nat", tab.4)?;
        v.tables.push(s);
        md.push('\n');
    }
    let failed: Vec<&str> = v
        .checks
        .iter()
        .filter(|c| !c.1)
        .map(|c| c.0.as_str())
        .collect();
    writeln!(
        md,
        "## Verdict\n\n{} of {} checks pass{}",
        v.checks.len() - failed.len(),
        v.checks.len(),
        if failed.is_empty() {
            ".".to_string()
        } else {
            format!("; failing: {}.", failed.join(", "))
        }
    )
    .unwrap();
    v.markdown = md;
    Ok(v)
}
