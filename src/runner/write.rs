//! Result files of a run. Tables (parquet, units in the file metadata key `rfmlab.units`):
//!
//! | table | columns (unit) |
//! |---|---|
//! | `frf` | level, model (`""` for measured), kind (measured / initial / updated), response_id, reference_id, freq_hz (Hz), accelerance_re, accelerance_im ((m/s^2)/N) |
//! | `parameters` | level, model, parameter, unit, initial, identified (SI unit in `unit`), iterations, stop_reason, frac_initial_<id>, frac_updated_<id> (1) per response id |
//! | `iterations` | level, model, iteration, parameter, value (SI), relative_change (1), residual_modulus (Pa), frf_relative_residual (1), rank, step_scale (1) |
//! | `correlation` | level, model, kind (initial / updated), response_id, frac (1) |
//! | `correlation_curves` | level, model, kind, freq_hz (Hz), scc (1), acc (1) |
//! | `modulus` | level, source (model name, `per_line_combined`, `per_line_<id>`), kind (initial / updated / estimate), freq_hz (Hz), storage_modulus, loss_modulus (Pa) |
//! | `svd` | level, model, index, singular_value (Pa), condition_number (1), rank, weak (bool), direction (d ln p, as text) |
//! | `modal` | level, method (circle_fit / iem / rfm_model1_band), center_hz, width_hz (Hz), response_id, freq_hz (Hz), loss_factor (1), storage_modulus, loss_modulus (Pa; NaN for circle fit), iterations |
//! | `sensitivity` | level, response_id, freq_hz (Hz), storage (1), loss (1): |dH'/dE'| E'/max|H'| and |dH'/dE''| E''/max|H'| |
//!
//! Plus `manifest.json` (written last), `report.md` and figures `fig_*.png` / `.svg`.

use super::{LevelData, RunError};
use crate::common::C64;
use crate::identify::frf_of;
use crate::output::{Columns as Cols, Report, Table};
use crate::pipeline::results::LevelResults;
use crate::plot::{Curve, CurveStyle, FrfCurve};
use crate::study::Study;
use std::path::Path;

const TWO_PI: f64 = 2.0 * std::f64::consts::PI;

/// Paper values (MPa, kPa s) of Table 4 identified rows, by model name, for the report.
fn paper_identified(model: &str, level: &str) -> Option<Vec<f64>> {
    if level != "L1" {
        return None;
    }
    let k: usize = model.strip_prefix("model")?.parse().ok()?;
    let (id, _) = crate::material::try_paper_table4(k).ok()?;
    Some(id)
}

/// Report scale of a unit: (factor, report unit).
fn report_unit(unit: &str) -> (f64, &'static str) {
    match unit {
        "Pa" => (1e-6, "MPa"),
        "Pa s" => (1e-3, "kPa s"),
        _ => (1.0, ""),
    }
}

/// Paper Table 2 / 3 reference values: (level, approx centre) -> (f, eta, E' MPa, E'' MPa).
fn paper_mode(level: &str, center_hz: f64) -> Option<(f64, f64, f64, f64)> {
    let low = center_hz < 150.0;
    match (level, low) {
        ("L1", true) => Some((22.26, 0.2044, 6.9740, 1.4827)),
        ("L1", false) => Some((394.45, 0.0720, 9.6404, 1.6085)),
        ("L2", true) => Some((19.28, 0.2202, 5.1831, 1.1757)),
        ("L2", false) => Some((387.33, 0.1121, 8.7146, 2.1234)),
        _ => None,
    }
}

fn s(v: impl Into<String>) -> String {
    v.into()
}

struct Tables {
    frf: Table,
    parameters: Table,
    iterations: Table,
    correlation: Table,
    curves: Table,
    modulus: Table,
    svd: Table,
    modal: Table,
    sensitivity: Table,
}

fn build_tables(levels: &[LevelData], results: &[LevelResults]) -> Result<Tables, RunError> {
    let (mut frf, mut par, mut it, mut cor, mut cur, mut modu, mut svd, mut modal, mut sens) = (
        Cols::default(),
        Cols::default(),
        Cols::default(),
        Cols::default(),
        Cols::default(),
        Cols::default(),
        Cols::default(),
        Cols::default(),
        Cols::default(),
    );
    for (ld, r) in levels.iter().zip(results) {
        let n_out = ld.column.outputs.len();
        let lv = &ld.name;
        let mut push_frf = |model: &str, kind: &str, v: &[C64]| {
            for (l, &f) in ld.freq_hz.iter().enumerate() {
                for k in 0..n_out {
                    frf.s("level", lv.clone());
                    frf.s("model", s(model));
                    frf.s("kind", s(kind));
                    frf.i("response_id", ld.response_ids[k] as i64);
                    frf.i("reference_id", ld.reference_id as i64);
                    frf.f("freq_hz", "Hz", f);
                    let z = v[l * n_out + k];
                    frf.f("accelerance_re", "(m/s^2)/N", z.re);
                    frf.f("accelerance_im", "(m/s^2)/N", z.im);
                }
            }
        };
        push_frf("", "measured", &ld.column.accelerance);
        for g in &r.global {
            push_frf(&g.result.model_name, "initial", &g.initial_frf);
            push_frf(&g.result.model_name, "updated", &g.updated_frf);
        }
        for g in &r.global {
            let res = &g.result;
            let law = crate::material::model_from_name(&res.model_name, None).ok();
            let units = law
                .map(|l| l.param_units())
                .unwrap_or_else(|| vec![String::new(); res.params.len()]);
            for (p, name) in res.param_names.iter().enumerate() {
                par.s("level", lv.clone());
                par.s("model", res.model_name.clone());
                par.s("parameter", name.clone());
                par.s("unit", units.get(p).cloned().unwrap_or_default());
                par.s("stop_reason", res.stop_reason.to_string());
                par.i("iterations", res.iterations as i64);
                par.f("initial", "SI (see unit)", res.initial[p]);
                par.f("identified", "SI (see unit)", res.params[p]);
                for k in 0..n_out {
                    let id = ld.response_ids[k];
                    par.f(&format!("frac_initial_{id}"), "1", g.frac_initial[k]);
                    par.f(&format!("frac_updated_{id}"), "1", g.frac_updated[k]);
                }
            }
            for h in &res.history {
                for (p, name) in res.param_names.iter().enumerate() {
                    it.s("level", lv.clone());
                    it.s("model", res.model_name.clone());
                    it.s("parameter", name.clone());
                    it.i("iteration", h.iteration as i64);
                    it.i("rank", h.rank as i64);
                    it.f("value", "SI", h.params[p]);
                    it.f("relative_change", "1", h.relative_change);
                    it.f("residual_modulus", "Pa", h.residual_modulus_pa);
                    it.f("frf_relative_residual", "1", h.frf_relative_residual);
                    it.f("step_scale", "1", h.step_scale);
                }
            }
            for (kind, fr, sc, ac) in [
                ("initial", &g.frac_initial, &g.scc_initial, &g.acc_initial),
                ("updated", &g.frac_updated, &g.scc_updated, &g.acc_updated),
            ] {
                for (k, &v) in fr.iter().enumerate() {
                    cor.s("level", lv.clone());
                    cor.s("model", res.model_name.clone());
                    cor.s("kind", s(kind));
                    cor.i("response_id", ld.response_ids[k] as i64);
                    cor.f("frac", "1", v);
                }
                for (l, &f) in ld.freq_hz.iter().enumerate() {
                    cur.s("level", lv.clone());
                    cur.s("model", res.model_name.clone());
                    cur.s("kind", s(kind));
                    cur.f("freq_hz", "Hz", f);
                    cur.f("scc", "1", sc.get(l).copied().unwrap_or(f64::NAN));
                    cur.f("acc", "1", ac.get(l).copied().unwrap_or(f64::NAN));
                }
            }
            for (kind, m) in [("initial", &g.initial_modulus), ("updated", &res.modulus)] {
                for (l, &f) in ld.freq_hz.iter().enumerate() {
                    modu.s("level", lv.clone());
                    modu.s("source", res.model_name.clone());
                    modu.s("kind", s(kind));
                    modu.f("freq_hz", "Hz", f);
                    modu.f("storage_modulus", "Pa", m[l].re);
                    modu.f("loss_modulus", "Pa", m[l].im);
                }
            }
            let smax = res.singular_values.first().copied().unwrap_or(0.0);
            for (k, &sv) in res.singular_values.iter().enumerate() {
                let weak = res.weak_directions.iter().find(|w| w.singular_value == sv);
                svd.s("level", lv.clone());
                svd.s("model", res.model_name.clone());
                svd.s(
                    "direction",
                    weak.map(|w| {
                        res.param_names
                            .iter()
                            .zip(&w.direction)
                            .map(|(n, d)| format!("{d:+.3} {n}"))
                            .collect::<Vec<_>>()
                            .join(" ")
                    })
                    .unwrap_or_default(),
                );
                svd.s("weak", s(if weak.is_some() { "true" } else { "false" }));
                svd.i("index", k as i64);
                svd.i("rank", res.rank as i64);
                svd.f("singular_value", "Pa", sv);
                svd.f(
                    "relative_singular_value",
                    "1",
                    if smax > 0.0 { sv / smax } else { 0.0 },
                );
                svd.f("condition_number", "1", res.condition_number);
            }
        }
        if let Some(pl) = &r.per_line {
            for (l, e) in pl.iter().enumerate() {
                let f = ld.freq_hz[l];
                let mut push = |src: String, z: C64| {
                    modu.s("level", lv.clone());
                    modu.s("source", src);
                    modu.s("kind", s("estimate"));
                    modu.f("freq_hz", "Hz", f);
                    modu.f("storage_modulus", "Pa", z.re);
                    modu.f("loss_modulus", "Pa", z.im);
                };
                push(s("per_line_combined"), e.modulus_combined);
                for (k, &z) in e.modulus_per_frf.iter().enumerate() {
                    push(format!("per_line_{}", ld.response_ids[k]), z);
                }
            }
        }
        let mut push_modal =
            |method: &str, c: f64, w: f64, id: i64, f: f64, eta: f64, e: C64, iters: i64| {
                modal.s("level", lv.clone());
                modal.s("method", s(method));
                modal.i("response_id", id);
                modal.i("iterations", iters);
                modal.f("center_hz", "Hz", c);
                modal.f("width_hz", "Hz", w);
                modal.f("freq_hz", "Hz", f);
                modal.f("loss_factor", "1", eta);
                modal.f("storage_modulus", "Pa", e.re);
                modal.f("loss_modulus", "Pa", e.im);
            };
        for m in &r.iem {
            let nan = C64::new(f64::NAN, f64::NAN);
            push_modal(
                "circle_fit",
                m.center_hz,
                m.width_hz,
                m.response_id as i64,
                m.circle.freq_hz,
                m.circle.loss_factor,
                nan,
                0,
            );
            if let Ok(iem) = &m.iem {
                push_modal(
                    "iem",
                    m.center_hz,
                    m.width_hz,
                    m.response_id as i64,
                    iem.freq_hz,
                    iem.loss_factor,
                    iem.modulus,
                    iem.iterations as i64,
                );
            }
        }
        for b in &r.band_constant {
            push_modal(
                "rfm_model1_band",
                b.center_hz,
                b.width_hz,
                -1,
                f64::NAN,
                f64::NAN,
                b.result.modulus,
                b.result.run.iterations as i64,
            );
        }
        if let Some(sc) = &r.sensitivity {
            for k in 0..n_out {
                for (l, &f) in ld.freq_hz.iter().enumerate() {
                    sens.s("level", lv.clone());
                    sens.s("at", sc.at.clone());
                    sens.i("response_id", ld.response_ids[k] as i64);
                    sens.f("freq_hz", "Hz", f);
                    sens.f("storage", "1", sc.storage[k][l]);
                    sens.f("loss", "1", sc.loss[k][l]);
                }
            }
        }
    }
    Ok(Tables {
        frf: frf.table("frf")?,
        parameters: par.table("parameters")?,
        iterations: it.table("iterations")?,
        correlation: cor.table("correlation")?,
        curves: cur.table("correlation_curves")?,
        modulus: modu.table("modulus")?,
        svd: svd.table("svd")?,
        modal: modal.table("modal")?,
        sensitivity: sens.table("sensitivity")?,
    })
}

fn f4(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.4}")
    } else {
        "-".into()
    }
}

/// The report: Tables 2-5 of the paper with its values beside ours, and the figures.
pub(crate) fn build_report(
    study: &Study,
    levels: &[LevelData],
    results: &[LevelResults],
    figures: &[(String, String)],
    engine_note: &str,
    loop_status: Option<&str>,
) -> Report {
    let mut rep = Report::new();
    // With the closed loop, the first line gives its status per level.
    rep.heading(
        1,
        &match loop_status {
            Some(s) => format!("rfmlab study: {}: closed loop {s}", study.name),
            None => format!("rfmlab study: {}", study.name),
        },
    );
    if !study.description.is_empty() {
        rep.paragraph(&study.description);
    }
    rep.paragraph(&format!(
        "Study file `{}` (SHA-256 `{}`). Moduli in MPa, viscosities in kPa s in this report only; the parquet tables are in SI units. Paper values from Tables 2-4 of the paper (Table 5's numbers are lost; Level 2 has no paper column).",
        study.file.display(),
        study.sha256
    ));
    rep.paragraph(&format!("FRF {engine_note}."));
    if let Some(note) = super::declared::deterministic_note(study) {
        rep.paragraph(&note);
    }
    if let Some(e) = study
        .measurements
        .as_ref()
        .and_then(|m| m.estimator.as_ref())
    {
        let passes: Vec<usize> = results
            .iter()
            .flat_map(|r| {
                r.band_constant
                    .iter()
                    .map(|b| b.leakage_passes)
                    .chain(r.iem.iter().map(|m| m.leakage_passes))
                    .chain(r.global.iter().map(|g| g.leakage_passes))
            })
            .collect();
        rep.paragraph(&format!(
            "Measurement model: the data are H1 estimates with a {:?} window over {} s blocks (fs {} Hz){}. Every fit (Model 1 bands, circle fit + IEM, global RFM, per-line RFM) is made to the data minus the estimator's leakage bias at the fitted model, iterated to a fixed point ({}..{} corrected passes); circle fits are of the corrected data; FRFs and FRAC compare the data with the predicted measurement (model plus leakage).",
            e.window,
            e.block_s,
            e.fs_hz,
            match e.shaker {
                Some(s) => format!(
                    ", force spectrum coloured by a shaker with armature mass {} kg on a stinger of {:.3e} N/m",
                    s.armature_mass_kg, s.stinger_stiffness_n_m
                ),
                None => ", flat force spectrum".into(),
            },
            passes.iter().min().copied().unwrap_or(0),
            passes.iter().max().copied().unwrap_or(0),
        ));
    }
    // Table 2.
    let mut t2 = Vec::new();
    let mut t3 = Vec::new();
    let has_truth = levels.iter().any(|l| l.truth.is_some());
    // (what, E' error, E'' error) against the truth curve, for the summary under Table 3.
    let mut truth_errors: Vec<(String, f64, f64)> = Vec::new();
    for (ld, r) in levels.iter().zip(results) {
        // Truth E*(f) (MPa columns) and the errors of `e` against it.
        let truth_at = |f: f64| ld.truth.as_ref().map(|t| t.modulus(TWO_PI * f));
        for m in &r.iem {
            let p = paper_mode(&r.level, m.center_hz);
            t2.push(vec![
                r.level.clone(),
                format!("{:.0}", m.center_hz),
                format!("{}", m.response_id),
                format!("{:.2}", m.circle.freq_hz),
                f4(m.circle.loss_factor),
                p.map(|p| format!("{:.2}", p.0))
                    .unwrap_or_else(|| "-".into()),
                p.map(|p| f4(p.1)).unwrap_or_else(|| "-".into()),
            ]);
            let band = r
                .band_constant
                .iter()
                .find(|b| (b.center_hz - m.center_hz).abs() <= m.width_hz);
            t3.push(vec![
                r.level.clone(),
                format!("{:.0}", m.center_hz),
                m.iem
                    .as_ref()
                    .map(|i| f4(i.modulus.re * 1e-6))
                    .unwrap_or_else(|_| "failed".into()),
                m.iem
                    .as_ref()
                    .map(|i| f4(i.modulus.im * 1e-6))
                    .unwrap_or_else(|_| "failed".into()),
                band.map(|b| f4(b.result.modulus.re * 1e-6))
                    .unwrap_or_else(|| "-".into()),
                band.map(|b| f4(b.result.modulus.im * 1e-6))
                    .unwrap_or_else(|| "-".into()),
                p.map(|p| f4(p.2)).unwrap_or_else(|| "-".into()),
                p.map(|p| f4(p.3)).unwrap_or_else(|| "-".into()),
            ]);
            if has_truth {
                // At the mode: the IEM's analytical frequency, else the circle fit's.
                let f = m
                    .iem
                    .as_ref()
                    .map(|i| i.freq_hz)
                    .unwrap_or(m.circle.freq_hz);
                let t = truth_at(f);
                let row = t3.last_mut().expect("row just pushed");
                row.insert(2, format!("{f:.2}"));
                row.insert(7, t.map(|t| f4(t.re * 1e-6)).unwrap_or_else(|| "-".into()));
                row.insert(8, t.map(|t| f4(t.im * 1e-6)).unwrap_or_else(|| "-".into()));
                if let Some(t) = t {
                    let err = |e: C64| ((e.re - t.re) / t.re, (e.im - t.im) / t.im);
                    if let Ok(i) = &m.iem {
                        let (a, b) = err(i.modulus);
                        truth_errors.push((format!("{} IEM at {f:.1} Hz", r.level), a, b));
                    }
                    if let Some(b) = band {
                        let (x, y) = err(b.result.modulus);
                        truth_errors.push((format!("{} Model 1 band at {f:.1} Hz", r.level), x, y));
                    }
                }
            }
        }
        for b in &r.band_constant {
            if r.iem
                .iter()
                .any(|m| (b.center_hz - m.center_hz).abs() <= m.width_hz)
            {
                continue;
            }
            let p = paper_mode(&r.level, b.center_hz);
            t3.push(vec![
                r.level.clone(),
                format!("{:.0}", b.center_hz),
                "-".into(),
                "-".into(),
                f4(b.result.modulus.re * 1e-6),
                f4(b.result.modulus.im * 1e-6),
                p.map(|p| f4(p.2)).unwrap_or_else(|| "-".into()),
                p.map(|p| f4(p.3)).unwrap_or_else(|| "-".into()),
            ]);
            if has_truth {
                let t = truth_at(b.center_hz);
                let row = t3.last_mut().expect("row just pushed");
                row.insert(2, format!("{:.2}", b.center_hz));
                row.insert(7, t.map(|t| f4(t.re * 1e-6)).unwrap_or_else(|| "-".into()));
                row.insert(8, t.map(|t| f4(t.im * 1e-6)).unwrap_or_else(|| "-".into()));
            }
        }
    }
    if !t2.is_empty() {
        rep.heading(2, "Table 2: circle-fit modal analysis");
        rep.table(
            &[
                "Level",
                "Band centre (Hz)",
                "FRF (response)",
                "f (Hz)",
                "eta",
                "paper f (Hz)",
                "paper eta",
            ],
            &t2,
        );
    }
    let failures: Vec<String> = results
        .iter()
        .flat_map(|r| r.iem.iter().filter_map(|m| m.iem.as_ref().err().cloned()))
        .collect();
    if !t3.is_empty() {
        rep.heading(2, "Table 3: IEM and Model 1 RFM over 10 Hz bands (MPa)");
        for f in &failures {
            rep.paragraph(&format!("**Warning:** {f}"));
        }
        let mut h3 = vec![
            "Level",
            "Band centre (Hz)",
            "IEM E'",
            "IEM E''",
            "RFM Model 1 E'",
            "RFM Model 1 E''",
            "paper IEM E'",
            "paper IEM E''",
        ];
        if has_truth {
            h3.insert(2, "f (Hz)");
            h3.insert(7, "truth E'");
            h3.insert(8, "truth E''");
        }
        rep.table(&h3, &t3);
        if !truth_errors.is_empty() {
            rep.paragraph(
                "Against the truth curve of the simulated data (`measurements.truth`), at f:",
            );
            let rows: Vec<Vec<String>> = truth_errors
                .iter()
                .map(|(w, a, b)| {
                    vec![
                        w.clone(),
                        format!("{:+.2} %", 100.0 * a),
                        format!("{:+.2} %", 100.0 * b),
                    ]
                })
                .collect();
            rep.table(&["Estimate", "E' error", "E'' error"], &rows);
        }
    }
    // Tables 4 and 5.
    for (ld, r) in levels.iter().zip(results) {
        if r.global.is_empty() {
            continue;
        }
        let title = if r.level == "L1" {
            format!("Table 4: global RFM, level {}", r.level)
        } else {
            format!("Table 5: global RFM, level {}", r.level)
        };
        rep.heading(2, &title);
        let mut headers = vec![s("Model"), s("Row")];
        let maxp = r
            .global
            .iter()
            .map(|g| g.result.params.len())
            .max()
            .unwrap_or(0);
        for k in 0..maxp {
            headers.push(format!("p{}", k + 1));
        }
        headers.push(s("Iterations"));
        headers.push(s("Stop"));
        for id in &ld.response_ids {
            headers.push(format!("FRAC {id}"));
        }
        let mut rows = Vec::new();
        for g in &r.global {
            let res = &g.result;
            let units = crate::material::model_from_name(&res.model_name, None)
                .map(|l| l.param_units())
                .unwrap_or_default();
            let fmt = |v: &[f64]| -> Vec<String> {
                v.iter()
                    .enumerate()
                    .map(|(k, &x)| {
                        let (sc, u) = report_unit(units.get(k).map(String::as_str).unwrap_or(""));
                        format!("{} = {:.4} {u}", res.param_names[k], x * sc)
                    })
                    .collect()
            };
            let mut row = vec![res.model_name.clone(), s("initial")];
            let mut c = fmt(&res.initial);
            c.resize(maxp, String::new());
            row.extend(c);
            row.extend([s(""), s("")]);
            row.extend(g.frac_initial.iter().map(|&v| f4(v)));
            rows.push(row);
            let mut row = vec![res.model_name.clone(), s("identified")];
            let mut c = fmt(&res.params);
            c.resize(maxp, String::new());
            row.extend(c);
            row.extend([res.iterations.to_string(), res.stop_reason.to_string()]);
            row.extend(g.frac_updated.iter().map(|&v| f4(v)));
            rows.push(row);
            if let Some(t) = ld.truth.as_ref().filter(|t| t.law == res.model_name) {
                let mut row = vec![res.model_name.clone(), s("truth")];
                let mut c = fmt(&t.params);
                c.resize(maxp, String::new());
                row.extend(c);
                rows.push(row);
            }
            if let Some(p) = paper_identified(&res.model_name, &r.level) {
                let mut row = vec![res.model_name.clone(), s("paper")];
                let mut c = fmt(&p);
                c.resize(maxp, String::new());
                row.extend(c);
                rows.push(row);
            }
        }
        rep.table(&headers, &rows);
        let mut svd_rows = Vec::new();
        for g in &r.global {
            let res = &g.result;
            svd_rows.push(vec![
                res.model_name.clone(),
                res.singular_values
                    .iter()
                    .map(|v| format!("{v:.3e}"))
                    .collect::<Vec<_>>()
                    .join(", "),
                format!("{:.3e}", res.condition_number),
                format!("{}/{}", res.rank, res.params.len()),
            ]);
        }
        rep.paragraph("Singular values of U (log-parameters), condition number and rank:");
        rep.table(
            &["Model", "singular values (Pa)", "condition", "rank"],
            &svd_rows,
        );
    }
    if !figures.is_empty() {
        rep.heading(2, "Figures");
        for (file, alt) in figures {
            rep.image(file, alt);
        }
    }
    rep
}

/// Draw the figures into `dir`; returns (file name of the PNG, caption).
pub(crate) fn draw_figures(
    dir: &Path,
    levels: &[LevelData],
    results: &[LevelResults],
) -> Result<Vec<(String, String)>, RunError> {
    let palette = [
        (31, 119, 180),
        (214, 39, 40),
        (44, 160, 44),
        (148, 103, 189),
        (255, 127, 14),
        (140, 86, 75),
    ];
    let mut out = Vec::new();
    for (ld, r) in levels.iter().zip(results) {
        let n_out = ld.column.outputs.len();
        let lv = &ld.name;
        for k in 0..n_out {
            let id = ld.response_ids[k];
            let mut curves = vec![FrfCurve::new(
                "measured",
                frf_of(&ld.column.accelerance, n_out, k),
                CurveStyle::Points,
            )
            .with_color((0, 0, 0))];
            for (c, g) in r.global.iter().enumerate() {
                curves.push(
                    FrfCurve::new(
                        format!("{} updated", g.result.model_name),
                        frf_of(&g.updated_frf, n_out, k),
                        CurveStyle::Line,
                    )
                    .with_color(palette[c % palette.len()]),
                );
            }
            let stem = format!("fig_frf_{lv}_{id}{}", ld.reference_id);
            crate::plot::frf_figure(
                dir.join(&stem),
                &format!("Level {lv}: H'{id}{} measured and updated", ld.reference_id),
                &ld.freq_hz,
                &curves,
            )?;
            out.push((
                format!("{stem}.png"),
                format!("FRF {id}{} level {lv}", ld.reference_id),
            ));
        }
        if !r.global.is_empty() {
            let mut sc = Vec::new();
            let mut ac = Vec::new();
            for (c, g) in r.global.iter().enumerate() {
                let col = palette[c % palette.len()];
                sc.push(
                    Curve::line(
                        &g.result.model_name,
                        ld.freq_hz.clone(),
                        g.scc_updated.clone(),
                    )
                    .with_color(col),
                );
                ac.push(
                    Curve::line(
                        &g.result.model_name,
                        ld.freq_hz.clone(),
                        g.acc_updated.clone(),
                    )
                    .with_color(col),
                );
            }
            for (name, cs) in [("scc", sc), ("acc", ac)] {
                let stem = format!("fig_{name}_{lv}");
                crate::plot::line_figure(
                    dir.join(&stem),
                    &format!("Level {lv}: {} of the updated models", name.to_uppercase()),
                    "Frequency (Hz)",
                    &name.to_uppercase(),
                    &cs,
                    false,
                )?;
                out.push((
                    format!("{stem}.png"),
                    format!("{} level {lv}", name.to_uppercase()),
                ));
            }
            let mut conv = Vec::new();
            for (c, g) in r.global.iter().enumerate() {
                let h = &g.result.history;
                conv.push(
                    Curve::line(
                        &g.result.model_name,
                        h.iter().map(|x| x.iteration as f64).collect(),
                        h.iter()
                            .map(|x| x.frf_relative_residual.max(1e-300))
                            .collect(),
                    )
                    .with_color(palette[c % palette.len()]),
                );
            }
            let stem = format!("fig_convergence_{lv}");
            crate::plot::line_figure(
                dir.join(&stem),
                &format!("Level {lv}: convergence (relative FRF residual)"),
                "Iteration",
                "Relative FRF residual",
                &conv,
                true,
            )?;
            out.push((format!("{stem}.png"), format!("convergence level {lv}")));
        }
        // E' (storage) and E'' (loss) curves of one modulus series, same label and colour
        let mut st = Vec::new();
        let mut lo = Vec::new();
        let mut push = |label: &str, e: &[C64], style: CurveStyle, rgb: (u8, u8, u8)| {
            let f = ld.freq_hz.clone();
            st.push(
                Curve::new(label, f.clone(), e.iter().map(|z| z.re).collect(), style)
                    .with_color(rgb),
            );
            lo.push(Curve::new(label, f, e.iter().map(|z| z.im).collect(), style).with_color(rgb));
        };
        if let Some(pl) = &r.per_line {
            let e: Vec<C64> = pl.iter().map(|x| x.modulus_combined).collect();
            push("per-line RFM", &e, CurveStyle::Points, (0, 0, 0));
        }
        for (c, g) in r.global.iter().enumerate() {
            let col = palette[c % palette.len()];
            push(
                &g.result.model_name,
                &g.result.modulus,
                CurveStyle::Line,
                col,
            );
        }
        if let Some(t) = &ld.truth {
            let e: Vec<C64> = ld.freq_hz.iter().map(|f| t.modulus(TWO_PI * f)).collect();
            push(
                "truth (simulated data)",
                &e,
                CurveStyle::Line,
                (120, 120, 120),
            );
        }
        if !st.is_empty() {
            let stem = format!("fig_modulus_{lv}");
            crate::plot::modulus_figure(
                dir.join(&stem),
                &format!("Level {lv}: E' and E''"),
                &st,
                &lo,
            )?;
            out.push((format!("{stem}.png"), format!("modulus level {lv}")));
        }
    }
    Ok(out)
}

/// Every table of a run, in the order they are written: the deterministic ones, then the
/// inference, comparison and across-level ones (those only when computed).
pub(crate) fn tables(
    levels: &[LevelData],
    results: &[LevelResults],
) -> Result<Vec<Table>, RunError> {
    let t = build_tables(levels, results)?;
    let mut out = vec![
        t.frf,
        t.parameters,
        t.iterations,
        t.correlation,
        t.curves,
        t.modulus,
        t.svd,
        t.modal,
        t.sensitivity,
    ];
    let posts: Vec<&super::bayes::PosteriorResult> =
        results.iter().flat_map(|r| r.posteriors.iter()).collect();
    out.extend(super::write_bayes::tables(levels, &posts)?);
    out.extend(super::write_compare::tables(&posts)?);
    out.extend(super::write_levels::tables(results)?);
    Ok(out)
}
