//! report.md's sections on the comparison across excitation levels: per pair of levels the
//! change of E' and E'' (MPa) at the first two bending modes and chosen frequencies, with its
//! 95 % interval, the probability of a lower value at the higher level and the truth's
//! change; the evidence for shared or separate law parameters.

use crate::output::Report;
use crate::pipeline::tables::levels::comparisons;
use crate::pipeline::LevelResults;

fn mpa(v: f64) -> String {
    format!("{:.3}", v * 1e-6)
}

/// The sections across levels, one per compared pair of levels.
pub(super) fn across_levels(
    rep: &mut Report,
    results: &[LevelResults],
    figures: &[(String, String)],
) {
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
}
