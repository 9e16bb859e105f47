//! report.md: the results of a run for a reader, sections in this order:
//!
//! 1. [`identification`]: the title, study, FRF engine, declared effects, measurement model;
//! 2. [`modal`]: Tables 2 and 3 of the paper (circle fit, IEM, Model 1 over bands) beside
//!    ours;
//! 3. [`identification`]: Tables 4 and 5 (global RFM per level and model) and the singular
//!    values, then every figure;
//! 4. the mesh's discretisation error (`[analyses] mesh_error`);
//! 5. [`posterior`]: the posteriors (`[inference]`);
//! 6. [`comparison`]: the model comparison per level;
//! 7. [`levels`]: the comparison across excitation levels;
//! 8. [`redundancy`]: parameter redundancy and initial-value sensitivity (basins).
//!
//! [`crate::report::write`] then adds the closed loop's section when it ran. Moduli in MPa
//! and viscosities in kPa s in the report only; the parquet tables are in SI units.

mod comparison;
mod identification;
mod levels;
mod modal;
mod posterior;
mod redundancy;

use crate::bayes::PosteriorResult;
use crate::diagnose;
use crate::output::Report;
use crate::pipeline::Results;
use crate::stage::preflight::ModeDiscretisation;

/// A value with 4 decimals, `-` when not finite.
fn f4(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.4}")
    } else {
        "-".into()
    }
}

/// The report of `results` with the figures drawn (`figures`: PNG file name and caption).
pub(super) fn build(results: &Results, figures: &[(String, String)]) -> Report {
    let levels = results.levels();
    let level_results = results.level_results();
    let posts: Vec<&PosteriorResult> = results.posteriors().collect();
    let loop_status = results
        .closed_loop()
        .map(|o| diagnose::status_line(&o.summary.levels));
    let mut rep = identification::header(results, loop_status.as_deref());
    modal::modal_tables(&mut rep, levels, level_results);
    identification::global_tables(&mut rep, levels, level_results);
    if !figures.is_empty() {
        rep.heading(2, "Figures");
        for (file, alt) in figures {
            rep.image(file, alt);
        }
    }
    mesh_error_section(&mut rep, results.mesh_error());
    posterior::section(&mut rep, levels, &posts, figures);
    comparison::section(&mut rep, &posts);
    levels::across_levels(&mut rep, level_results, figures);
    redundancy::redundancy(&mut rep, level_results, figures);
    redundancy::basins(&mut rep, level_results, figures);
    rep
}

/// The mesh's discretisation error per low mode (`[analyses] mesh_error`), with the warnings
/// `rfmlab check` gives.
fn mesh_error_section(report: &mut crate::output::Report, modes: &[ModeDiscretisation]) {
    let Some(first) = modes.first() else {
        return;
    };
    report.heading(2, "Mesh discretisation error");
    report.paragraph(&format!(
        "Richardson extrapolation from the study's mesh and the mesh refined twice per direction (order {}), real modes at the first model's initial storage modulus. The posterior's intervals do not include this error.",
        first.order
    ));
    let rows: Vec<Vec<String>> = modes
        .iter()
        .map(|d| {
            vec![
                d.mode.to_string(),
                format!("{:.4}", d.freq_hz),
                format!("{:.4}", d.freq_refined_hz),
                format!("{:+.3e}", d.error_hz),
                format!("{:+.3}", 100.0 * d.rel_error),
            ]
        })
        .collect();
    report.table(
        &[
            "mode",
            "f, study mesh (Hz)",
            "f, refined (Hz)",
            "estimated error (Hz)",
            "error (%)",
        ],
        &rows,
    );
    for w in crate::stage::preflight::mesh_error_warnings(modes) {
        report.paragraph(&format!("**Warning**: {w}"));
    }
}
