//! The loop's markdown: `closed_loop.md` (its first line the status per level, then per level
//! the verdict, the candidates' ranking and refits, the residuals and parameters before and
//! after, and the residual signatures per resonance) and its section of the run's report.

use super::summary::{parameter_changes, DiagnoseLevel, LevelResult};
use std::fmt::Write as _;

/// The status of every level, `L1 `explained`, L2 `unexplained``: the first line of the
/// loop's markdown and of the run's report.
pub fn status_line(levels: &[DiagnoseLevel]) -> String {
    levels
        .iter()
        .map(|l| format!("{} `{}`", l.level, l.status))
        .collect::<Vec<_>>()
        .join(", ")
}

/// The loop's markdown as a section of the run's report: its headings one level down, its
/// figures under `sub/`.
pub fn report_section(md: &str, sub: &str) -> String {
    let mut text = String::from("## Closed loop (`[closed_loop]`)\n");
    for line in md.lines().skip(1) {
        let line = line.replace("](residuals_", &format!("]({sub}/residuals_"));
        if line.starts_with('#') {
            let _ = writeln!(text, "#{line}");
        } else {
            let _ = writeln!(text, "{line}");
        }
    }
    text
}

/// `closed_loop.md` of `study` and `model`: the status line, the legend, the term ROM's
/// certificate when effects needed one, then one section per level.
pub(crate) fn markdown(
    study: &str,
    model: &str,
    results: &[LevelResult],
    summary: &[DiagnoseLevel],
    term: Option<(&[String], &crate::rom::TermCertificate)>,
) -> String {
    let mut s = String::new();
    // The first line: the status of every level.
    let _ = writeln!(
        s,
        "# Closed loop: {study}, {model}: {}\n",
        status_line(summary)
    );
    let _ = writeln!(
        s,
        "Status per level: `nothing_missing` (the residual is consistent with noise, no effect needed), `explained` (effects accepted, the final residual consistent with noise), `unexplained` (the residual stays above the calibrated null level: the effects accepted on the way are tentative and the adhesive's parameters carry a warning), `confounded` (an effect the data cannot separate from the adhesive's parameters: they are given as a range). Consistent with noise: the normalised chi-square at most the threshold of its null level, calibrated on replicates of the fitted model through the same measurement chain.\n"
    );
    if let Some((names, c)) = term {
        let _ = writeln!(
            s,
            "Effects with matrices of their own ({}) are evaluated by a reduced model with their terms: {} basis vectors ({} before the POD compression), {} against the full model with each term on to {:.2e} of each FRF's peak ({} moduli x {} lines per case).\n",
            names.join(", "),
            c.basis_size,
            c.enriched_basis_size,
            if c.passed { "certified" } else { "NOT certified" },
            c.max_rel_error,
            c.n_moduli,
            c.n_lines
        );
    }
    for ((level, _, ids, res, truth), l) in results.iter().zip(summary) {
        let v = &l.verdict;
        let _ = writeln!(
            s,
            "## Level {level}: `{}`\n\n**{}**\n\n{}\n",
            v.status, v.sentence, res.conclusion
        );
        if let Some(w) = &v.warning {
            let _ = writeln!(s, "**Warning on the adhesive's parameters:** {w}.\n");
        }
        for d in &v.drop_one {
            let _ = writeln!(
                s,
                "- drop-one check of {}: {:.1} nats in the final model, {:.1} once widened by kappa = {:.2}: {}",
                d.effect,
                d.gain,
                d.scaled_gain,
                d.kappa,
                if d.kept { "kept (tentative)" } else { "dropped" }
            );
        }
        for d in &v.not_needed {
            let _ = writeln!(
                s,
                "- {} = {:.4e} {} left out: the final model refitted without it reads a normalised chi-square of {:.3}, within the noise (threshold {:.3}); its evidence gain came from a difference it stands in for",
                d.effect, d.size, d.unit, d.chi2_without, v.threshold
            );
        }
        if !v.drop_one.is_empty() || !v.not_needed.is_empty() {
            s.push('\n');
        }
        let _ = writeln!(
            s,
            "| round | rank | effect | score T | p | evidence gain (nat) | size +- sd | 95 % interval | verdict |\n|---|---|---|---|---|---|---|---|---|"
        );
        for c in res
            .candidates
            .iter()
            .filter(|c| c.rank <= 5 || c.refit.is_some() || c.profile_gain.is_some())
        {
            let (g, sz, iv, v) = match &c.refit {
                Some(r) => (
                    format!("{:.1}", r.evidence_gain),
                    format!("{:.4e} +- {:.1e} {}", r.size, r.sd, c.effect.unit()),
                    format!(
                        "[{:.4e}, {:.4e}]",
                        r.size - 1.96 * r.sd,
                        r.size + 1.96 * r.sd
                    ),
                    r.verdict.to_string(),
                ),
                None if c.predicted_gain.is_finite() => (
                    "".into(),
                    "".into(),
                    "".into(),
                    format!("not refitted (predicted gain {:.1} nats)", c.predicted_gain),
                ),
                None => ("".into(), "".into(), "".into(), "not refitted".into()),
            };
            // Ranked by the profile (the residual far from noise): its gain beside the verdict.
            let v = match c.profile_gain {
                Some(pg) => format!("{v} (profile gain {pg:.1} nats)"),
                None => v,
            };
            let _ = writeln!(
                s,
                "| {} | {} | {} | {:.1} | {:.2e} | {g} | {sz} | {iv} | {v} |",
                c.round,
                c.rank,
                c.effect.name(),
                c.score,
                c.p_value
            );
        }
        for c in &res.law_candidates {
            let _ = writeln!(
                s,
                "| {} | - | {} (alternative law) | - | - | {} | - | - | {} |",
                c.round,
                c.law,
                if c.refit.evidence_gain.is_finite() {
                    format!("{:.1}", c.refit.evidence_gain)
                } else {
                    String::new()
                },
                c.refit.verdict
            );
        }
        for (e, _, _) in &res.accepted {
            let _ = writeln!(s, "\n- {}: {}", e.name(), e.physics());
        }
        if !res.confounded.is_empty() {
            let _ = writeln!(
                s,
                "\n**Not identifiable from these data** (the law's parameters absorb them; R^2 of the effect's Jacobian column on the law's, src/closed_loop/confounding.rs):\n"
            );
            for c in &res.confounded {
                let _ = writeln!(s, "- {c}");
            }
        }
        if res.before.law != res.after.law {
            let _ = writeln!(
                s,
                "\n- the law {} was replaced by {}: not nested, so no score test; the whole model was refitted with the new law (started from its fit to the previous MAP's E*(w)) and won by the Laplace evidence gain above. Parameters below: the new law's after, the old law's (`{}.*`) before.",
                res.before.law, res.after.law, res.before.law
            );
        }
        let _ = writeln!(s, "\n| | before | after |\n|---|---|---|");
        let (b, a) = (&res.before.residuals, &res.after.residuals);
        let _ = writeln!(
            s,
            "| normalised chi-square | {:.3} | {:.3} |",
            b.chi2_normalised, a.chi2_normalised
        );
        let _ = writeln!(
            s,
            "| relative residual norm | {:.4} | {:.4} |",
            b.relative_norm, a.relative_norm
        );
        for (k, id) in ids.iter().enumerate() {
            let _ = writeln!(s, "| FRAC ch{id} | {:.5} | {:.5} |", b.frac[k], a.frac[k]);
        }
        let _ = writeln!(
            s,
            "\n| parameter | before +- sd | after +- sd | truth |\n|---|---|---|---|"
        );
        for pc in parameter_changes(res, truth.as_deref()) {
            let before = match (pc.before, pc.before_sd) {
                (Some(v), Some(sd)) => format!("{v:.5e} +- {sd:.2e}"),
                _ => String::new(),
            };
            let after = if pc.after.is_nan() {
                String::new()
            } else {
                format!("{:.5e} +- {:.2e}", pc.after, pc.after_sd)
            };
            let t = pc.truth.map_or(String::new(), |v| format!("{v:.5e}"));
            let _ = writeln!(s, "| {} | {before} | {after} | {t} |", pc.name);
        }
        let _ = writeln!(
            s,
            "\n![standardised residuals before and after](residuals_{level}.png)\n\n|z| per channel and line; under a correct model |z|^2 has mean 1."
        );
        signatures_markdown(&mut s, b, a);
        s.push('\n');
    }
    s
}

/// The residual signatures per resonance before and after (`closed_loop::signatures`): the
/// data's frequency and loss-factor change against the model, in sds, and the findings.
fn signatures_markdown(
    s: &mut String,
    b: &crate::closed_loop::Residuals,
    a: &crate::closed_loop::Residuals,
) {
    let (rb, ra) = (&b.signatures.resonances, &a.signatures.resonances);
    if rb.is_empty() {
        return;
    }
    let _ = writeln!(
        s,
        "\nResidual signatures per resonance (a local modal fit of the data against the model's own modal terms; z in sds of the data's noise):\n\n| resonance (Hz) | df/f before (z) | df/f after (z) | d(loss factor) before (z) | after (z) |\n|---|---|---|---|---|"
    );
    for r in rb {
        let after = ra
            .iter()
            .min_by(|x, y| {
                (x.freq_hz - r.freq_hz)
                    .abs()
                    .total_cmp(&(y.freq_hz - r.freq_hz).abs())
            })
            .filter(|x| (x.freq_hz - r.freq_hz).abs() < 0.05 * r.freq_hz);
        let (fa, la) = after.map_or(("-".to_string(), "-".to_string()), |x| {
            (
                format!("{:+.3} % ({:.1})", 100.0 * x.freq_shift, x.freq_z()),
                format!("{:+.2e} ({:.1})", x.loss_change, x.loss_z()),
            )
        });
        let _ = writeln!(
            s,
            "| {:.1} | {:+.3} % ({:.1}) | {fa} | {:+.2e} ({:.1}) | {la} |",
            r.freq_hz,
            100.0 * r.freq_shift,
            r.freq_z(),
            r.loss_change,
            r.loss_z()
        );
    }
    for (when, res) in [("before", b), ("after", a)] {
        let f = res.signatures.findings(5.0);
        if !f.is_empty() {
            let _ = writeln!(s, "\nSignatures beyond 5 sd {when}: {}.", f.join("; "));
        }
    }
}
