//! The opening of report.md and its global RFM sections: the title (with the closed loop's
//! status per level), the study's description, file and SHA-256, the FRF engine, declared
//! effects and the H1 measurement model; then per level one table of the global RFM (Table 4
//! for level L1, Table 5 otherwise): every model's initial and identified parameters,
//! iterations, stop reason and FRAC per response, with the truth of simulated data and the
//! paper's values; and the singular values, condition number and rank of each global RFM.
//! Moduli in MPa and viscosities in kPa s (the parquet tables are in SI units).

use super::f4;
use crate::output::Report;
use crate::pipeline::LevelResults;
use crate::pipeline::Results;
use crate::stage::LevelData;

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

fn s(v: impl Into<String>) -> String {
    v.into()
}

/// The warning that opens the report when a fit is not a result ([`Results::flagged`]): one
/// line per flagged fit with its reasons, and where the status is in the tables.
fn flagged_block(rep: &mut Report, flagged: &[crate::pipeline::FlaggedFit]) {
    if flagged.is_empty() {
        return;
    }
    let mut text = format!(
        "> **WARNING: {} {}.** The values below are where the search stopped, not an identification: read the reasons before using them (the `status` and `status_reason` columns of parameters.parquet, `map_status` of summary.parquet). `rfmlab run` exits with code 3.\n>",
        flagged.len(),
        if flagged.len() == 1 {
            "fit is not a result"
        } else {
            "fits are not results"
        },
    );
    for f in flagged {
        text.push_str(&format!("\n> - {f}"));
    }
    rep.paragraph(&text);
}

/// The report's opening: title, study, engine, declared effects and measurement model.
pub(super) fn header(run: &Results, loop_status: Option<&str>) -> Report {
    let study = run.study();
    let engine_note = run.engine_note();
    let results = run.level_results();
    let mut rep = Report::new();
    // With the closed loop, the first line gives its status per level.
    rep.heading(
        1,
        &match loop_status {
            Some(s) => format!("rfmlab study: {}: closed loop {s}", study.name),
            None => format!("rfmlab study: {}", study.name),
        },
    );
    flagged_block(&mut rep, &run.flagged());
    // The pre-flight's warnings bear on every number below.
    for w in run.preflight_warnings() {
        rep.paragraph(&format!("**Warning (pre-flight):** {w}"));
    }
    if !study.description.is_empty() {
        rep.paragraph(&study.description);
    }
    rep.paragraph(&format!(
        "Study file `{}` (SHA-256 `{}`). Moduli in MPa, viscosities in kPa s in this report only; the parquet tables are in SI units. Paper values from Tables 2-4 of the paper (Table 5's numbers are lost; Level 2 has no paper column).",
        study.file.display(),
        study.sha256
    ));
    rep.paragraph(&format!("FRF {engine_note}."));
    if let Some(note) = crate::bayes::declared::deterministic_note(&study.declared_effects) {
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
    rep
}

/// Tables 4 and 5: the global RFM per level and model.
pub(super) fn global_tables(rep: &mut Report, levels: &[LevelData], results: &[LevelResults]) {
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
        headers.push(s("Status"));
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
            row.extend([s(""), s(""), s("")]);
            row.extend(g.frac_initial.iter().map(|&v| f4(v)));
            rows.push(row);
            let mut row = vec![res.model_name.clone(), s("identified")];
            let mut c = fmt(&res.params);
            c.resize(maxp, String::new());
            row.extend(c);
            row.extend([
                res.iterations.to_string(),
                res.stop_reason.to_string(),
                match &g.status {
                    crate::rfm::FitStatus::Converged => s("converged"),
                    crate::rfm::FitStatus::Flagged(_) => s("**FLAGGED** (see the warning above)"),
                },
            ]);
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
}
