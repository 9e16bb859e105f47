//! The material study's report.md: the data, the steps with their error and evidence, the
//! residual analysis, the Kramers-Kronig check and the figures.

use super::{e, fmt_params, rms};
use crate::material_fit::LoopResult;
use crate::output::Report;
use crate::study::material::MaterialStudy;

pub(super) fn report(study: &MaterialStudy, r: &LoopResult, with_figures: bool) -> Report {
    let c = &study.curve;
    let mut rep = Report::new();
    rep.heading(1, &format!("Material study {}", study.name));
    if !study.description.is_empty() {
        rep.paragraph(&study.description);
    }
    rep.paragraph(&format!(
        "Data: `{}`, {} points, {:.3e} to {:.3e} Hz; E' {:.4} to {:.4} MPa, E'' {:.4} to {:.4} MPa. \
         Likelihood on ln E' and ln E'' with one inferred relative scatter each; priors log-uniform: \
         moduli [{:.3e}, {:.3e}] Pa, relaxation times [{:.3e}, {:.3e}] s, scatters [1e-4, 1]; fractional order uniform (0, 1). \
         Evidence: Laplace + ln n! for n exchangeable branches; it depends on these priors.",
        study.data_file.display(),
        c.len(),
        c.freq_hz[0],
        c.freq_hz[c.len() - 1],
        c.storage_pa.iter().cloned().fold(f64::INFINITY, f64::min) * 1e-6,
        c.storage_pa.iter().cloned().fold(0.0, f64::max) * 1e-6,
        c.loss_pa.iter().cloned().fold(f64::INFINITY, f64::min) * 1e-6,
        c.loss_pa.iter().cloned().fold(0.0, f64::max) * 1e-6,
        r.prior_box.modulus_pa.0,
        r.prior_box.modulus_pa.1,
        r.prior_box.tau_s.0,
        r.prior_box.tau_s.1,
    ));
    rep.heading(2, "Steps: error and evidence");
    let rows: Vec<Vec<String>> = r
        .candidates
        .iter()
        .enumerate()
        .map(|(i, k)| {
            vec![
                i.to_string(),
                k.step.to_string(),
                k.proposal.clone(),
                k.law.label(),
                k.n_params().to_string(),
                e(k.log_evidence),
                e(k.evidence_gain),
                format!("{:.4}", k.rms_log10_storage),
                format!("{:.4}", k.rms_log10_loss),
                format!("{} / {}", k.stats_storage.verdict(), k.stats_loss.verdict()),
                if k.causal_floor_ratio.is_finite() {
                    format!("{:.2}", k.causal_floor_ratio)
                } else {
                    String::new()
                },
                if r.path.contains(&i) {
                    "yes".into()
                } else {
                    "".into()
                },
            ]
        })
        .collect();
    rep.table(
        &[
            "#",
            "step",
            "proposal",
            "law",
            "params",
            "log Z (nat)",
            "gain (nat)",
            "RMS log10 E'",
            "RMS log10 E''",
            "residual E' / E''",
            "misfit / causal floor",
            "accepted",
        ],
        &rows,
    );
    let first = r.first_candidate();
    let last = r.final_candidate();
    rep.paragraph(&format!(
        "Stop: {}. Before (first law, {}): RMS log10 error E' {:.4}, E'' {:.4}. After (final law, {}, {} parameters): E' {:.4}, E'' {:.4}; \
         evidence gain {:.1} nats over the first law.",
        r.stop.as_str(),
        first.law.label(),
        first.rms_log10_storage,
        first.rms_log10_loss,
        last.law.label(),
        last.n_params(),
        last.rms_log10_storage,
        last.rms_log10_loss,
        last.log_evidence - first.log_evidence
    ));
    rep.paragraph(&format!(
        "Final parameters (MAP, SI): {}.",
        fmt_params(last)
    ));
    rep.heading(2, "Residual analysis");
    let mut rows = Vec::new();
    for (name, k) in [("first", first), ("final", last)] {
        for (q, s) in [("E'", &k.stats_storage), ("E''", &k.stats_loss)] {
            rows.push(vec![
                format!("{name} ({})", k.law.label()),
                q.to_string(),
                format!("{:.4}", s.rms),
                format!("{} / {:.1}", s.runs, s.runs_expected),
                format!("{:.2}", s.runs_z),
                format!("{:.2e}", s.runs_p),
                format!("{:.4}", s.scatter_sd),
                format!("{:.2}", s.chi2_norm),
                s.verdict().to_string(),
            ]);
        }
    }
    rep.table(
        &[
            "law",
            "quantity",
            "RMS log10",
            "runs / expected",
            "runs z",
            "runs p",
            "scatter (log10, successive differences)",
            "chi2 / scatter^2",
            "verdict",
        ],
        &rows,
    );
    let k = &r.kk;
    let n_bad = k.non_causal.iter().filter(|b| **b).count();
    let regions: Vec<String> = k
        .regions_hz
        .iter()
        .map(|(a, b)| format!("{a:.3e}-{b:.3e} Hz"))
        .collect();
    rep.heading(2, "Kramers-Kronig check of the data");
    rep.paragraph(&format!(
        "Non-negative relaxation spectrum on {} relaxation times ({} per decade, one decade beyond the data at each end; \
         the first and last decade of the data are the least certain). Best causal fit: RMS log10 error E' {:.4}, E'' {:.4} \
         (sum {:.4}; the final law's sum is {:.4}). Point-to-point scatter about it: E' {:.4}, E'' {:.4} (log10). \
         RMS log10 of E'' implied by E' against the measured E'': {:.4}; of E' implied by E'': {:.4} (one-sided transforms, ill-posed where the other quantity is flat). \
         {} of {} points are non-causal (the best causal fit's 5-point averaged residual beyond {} white-noise sds){}.",
        k.tau_s.len(),
        study.params.kk_per_decade,
        k.causal_rms_log10_storage,
        k.causal_rms_log10_loss,
        k.causal_rms_log10_storage + k.causal_rms_log10_loss,
        last.rms_log10_sum(),
        k.scatter_log10_storage,
        k.scatter_log10_loss,
        rms(&k.res_loss_from_storage),
        rms(&k.res_storage_from_loss),
        n_bad,
        c.len(),
        k.threshold,
        if regions.is_empty() { String::new() } else { format!(": {}", regions.join(", ")) }
    ));
    let systematic = last.stats_storage.is_systematic() || last.stats_loss.is_systematic();
    let near_floor = last.causal_floor_ratio <= 1.25;
    let verdict = match (systematic, near_floor) {
        (false, _) => "The final law's residual is consistent with scatter (runs test at 1 %).".to_string(),
        (true, true) => format!(
            "The final law's residual is systematic, but its weighted misfit is {:.2} times that of the best causal fit \
             with the same weights (any non-negative relaxation spectrum): the remaining residual is the data's causal \
             (Kramers-Kronig) inconsistency, not missing relaxation content{}.",
            last.causal_floor_ratio,
            if regions.is_empty() { String::new() } else { format!("; the data are non-causal at {}", regions.join(", ")) }
        ),
        (true, false) => format!(
            "The final law's residual is systematic and its weighted misfit is {:.2} times the best causal fit's with the \
             same weights: part of the residual is relaxation content the law lacks (the loop stopped because {}); \
             the rest is the data's causal inconsistency{}.",
            last.causal_floor_ratio,
            r.stop.as_str(),
            if regions.is_empty() { String::new() } else { format!(" at {}", regions.join(", ")) }
        ),
    };
    rep.paragraph(&verdict);
    if with_figures {
        rep.heading(2, "Figures");
        rep.image("fit_storage.png", "E' data and fits");
        rep.image("fit_loss.png", "E'' data and fits");
        rep.image("residuals.png", "residuals");
        rep.image("kk.png", "Kramers-Kronig check");
    }
    rep
}
