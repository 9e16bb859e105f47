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
    mesh_error_section(&mut rep, results.discretisation());
    posterior::section(&mut rep, levels, &posts, figures);
    comparison::section(&mut rep, &posts);
    levels::across_levels(&mut rep, level_results, figures);
    redundancy::redundancy(&mut rep, level_results, figures);
    redundancy::basins(&mut rep, level_results, figures);
    rep
}

/// The mesh: how it was chosen, the estimated discretisation error per low mode and what the
/// results do with it.
fn mesh_error_section(
    report: &mut crate::output::Report,
    d: Option<&crate::discretisation::Discretisation>,
) {
    let Some(d) = d else {
        return;
    };
    report.heading(2, "Mesh discretisation error");
    if d.rule == "refined" {
        report.paragraph(&format!(
            "The joint was meshed to a tolerance of {:.2} % of each mode's frequency ({}): cells graded towards the bond line's edges, the edge cells halved per level. Estimated error from the last meshes: the last step extrapolated at order {} (twice the step where the last three meshes do not converge monotonically; the order column is the observed one), real modes at {:.3} MPa.",
            100.0 * d.tolerance,
            if d.reached { "reached".to_string() } else { format!("not reached: {}", d.note) },
            crate::discretisation::ORDER,
            1e-6 * d.reference_modulus_pa
        ));
        let rows: Vec<Vec<String>> = d
            .levels
            .iter()
            .map(|l| {
                let mut r = vec![
                    l.level.to_string(),
                    format!("{:.3}", 1e3 * l.edge_m),
                    l.n_dof.to_string(),
                ];
                r.extend(l.freqs_hz.iter().take(3).map(|f| format!("{f:.4}")));
                r
            })
            .collect();
        report.table(
            &[
                "level",
                "edge cells (mm)",
                "DOFs",
                "f1 (Hz)",
                "f2 (Hz)",
                "f3 (Hz)",
            ],
            &rows,
        );
    } else {
        report.paragraph(&format!(
            "The study fixes the mesh. Estimated error against the mesh refined twice per direction (order {}), real modes at {:.3} MPa.",
            crate::discretisation::ORDER,
            1e-6 * d.reference_modulus_pa
        ));
    }
    let rows: Vec<Vec<String>> = d
        .modes
        .iter()
        .map(|m| {
            vec![
                m.mode.to_string(),
                format!("{:.4}", m.freq_hz),
                format!("{:+.3e}", m.error_hz),
                format!("{:+.3}", 100.0 * m.rel_error),
                if m.order.is_finite() {
                    format!("{:.2}", m.order)
                } else {
                    "not monotone".to_string()
                },
                format!("{:.3}", m.adhesive_share),
                format!("{:.3}", m.measured_share),
            ]
        })
        .collect();
    report.table(
        &[
            "mode",
            "f, mesh used (Hz)",
            "estimated error (Hz)",
            "error (%)",
            "observed order",
            "adhesive share",
            "measured share",
        ],
        &rows,
    );
    report.paragraph(&if d.allowance {
        format!(
            "Allowance: the adhesive's stiffness on this mesh exceeds the continuum's by about {:+.3} % (sd {:.3} %){} (from 2 e_k / f_k = share_k x excess + (1 - share_k) x the adherends' over the modes, each weighted by its measured share). The posteriors carry the per-mode errors: the law's parameters are moved by what these errors do to them and widened by their uncertainty (docs/method.md); the deterministic fits (Tables 4 and 5) are the mesh's.",
            100.0 * d.stiffness_excess,
            100.0 * d.stiffness_excess_sd,
            d.adherends_clause()
        )
    } else {
        "No allowance (`allowance = false`): the study declares that its data were made on this very mesh; the results do not include the estimate.".to_string()
    });
    for w in crate::stage::preflight::mesh_error_warnings(Some(d)) {
        report.paragraph(&format!("**Warning**: {w}"));
    }
}
