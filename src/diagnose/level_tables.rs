//! The loop's tables with one status per level: `closed_loop` (parameters and residual
//! statistics before and after, with the level's status and warnings) and `verdict` (the
//! status, the null level, where the residual is, the tentative, dropped and confounded
//! effects).

use super::summary::{parameter_changes, DiagnoseLevel, LevelResult};
use crate::closed_loop::Residuals;
use crate::output::Table;
use crate::stage::RunError;

/// `closed_loop`: per level and quantity, before and after (parameters with sds, and the
/// residual statistics), and the truth where the data are simulated.
/// Every row carries the level's `status`; the law's parameters of an `unexplained` level
/// carry its warning, those of a `confounded` level (and its other accepted effects) their
/// range over the effect's plausible sizes.
pub(crate) fn closed_loop_table(
    results: &[LevelResult],
    summary: &[DiagnoseLevel],
    term_box: Option<&crate::rom::ModulusRange>,
) -> Result<Table, RunError> {
    let (mut fit_status, mut fit_reason) = (Vec::new(), Vec::new());
    let (mut lv, mut q) = (Vec::new(), Vec::new());
    let (mut b, mut bs, mut a, mut as_, mut tr) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let (mut status, mut warning) = (Vec::new(), Vec::new());
    for ((level, _, ids, res, truth), l) in results.iter().zip(summary) {
        let v = &l.verdict;
        let n_rows = q.len();
        for pc in parameter_changes(res, truth.as_deref()) {
            let law_param = res.after.names[..res.after.n_law].contains(&pc.name);
            let range = v.confounded.first().and_then(|c| {
                c.ranges
                    .iter()
                    .chain(&c.effects)
                    .find(|r| r.0 == pc.name)
                    .map(|(_, lo, hi)| {
                        format!(
                            "confounded with {} (correlation {:.4}): range [{lo:.4e}, {hi:.4e}]",
                            c.effect, c.correlation
                        )
                    })
            });
            warning.push(match (law_param, &v.warning, range) {
                (true, Some(w), _) => w.clone(),
                (_, None, Some(r)) => r,
                _ => String::new(),
            });
            lv.push(level.clone());
            q.push(pc.name);
            b.push(pc.before);
            bs.push(pc.before_sd);
            a.push(Some(pc.after).filter(|x| !x.is_nan()));
            as_.push(Some(pc.after_sd).filter(|x| !x.is_nan()));
            tr.push(pc.truth);
        }
        let stat = |r: &Residuals| -> Vec<(String, f64)> {
            let mut v = vec![
                ("chi2_normalised".to_string(), r.chi2_normalised),
                ("relative_residual_norm".to_string(), r.relative_norm),
                ("chi2_p_value".to_string(), r.p_value),
            ];
            for (k, id) in ids.iter().enumerate() {
                v.push((format!("frac_ch{id}"), r.frac[k]));
                v.push((format!("runs_z_ch{id}"), r.channels[k].runs_z));
            }
            v
        };
        for ((n, x), (_, y)) in stat(&res.before.residuals)
            .into_iter()
            .zip(stat(&res.after.residuals))
        {
            lv.push(level.clone());
            q.push(n);
            b.push(Some(x));
            bs.push(None);
            a.push(Some(y));
            as_.push(None);
            tr.push(None);
            warning.push(String::new());
        }
        status.extend(std::iter::repeat_n(v.status.to_string(), q.len() - n_rows));
        let fs = after_status(res, results_lines(results, level), term_box);
        fit_status.extend(std::iter::repeat_n(
            fs.label().to_string(),
            q.len() - n_rows,
        ));
        fit_reason.extend(std::iter::repeat_n(fs.reason_text(), q.len() - n_rows));
    }
    let mut t = Table::new("closed_loop");
    t.push_str("level", lv)
        .and_then(|t| t.push_str("status", status))
        .and_then(|t| t.push_str("quantity", q))
        .and_then(|t| t.push_opt_f64("before", "SI", b))
        .and_then(|t| t.push_opt_f64("before_sd", "SI", bs))
        .and_then(|t| t.push_opt_f64("after", "SI", a))
        .and_then(|t| t.push_opt_f64("after_sd", "SI", as_))
        .and_then(|t| t.push_opt_f64("truth", "SI", tr))
        .and_then(|t| t.push_str("warning", warning))
        .and_then(|t| t.push_str("fit_status", fit_status))
        .and_then(|t| t.push_str("fit_status_reason", fit_reason))
        .map_err(RunError::Output)?;
    Ok(t)
}

/// The lines (Hz) of `level` among `results`.
fn results_lines<'r>(results: &'r [LevelResult], level: &str) -> &'r [f64] {
    results
        .iter()
        .find(|r| r.0 == level)
        .map(|r| r.1.as_slice())
        .unwrap_or(&[])
}

/// Whether the loop's final MAP is a result ([`crate::rfm::status`]): its law's parameters
/// finite and, for a modulus, physical; its modulus on `freq_hz` inside the term ROM's
/// certified box when the loop ran on one.
fn after_status(
    res: &crate::closed_loop::ClosedLoopResult,
    freq_hz: &[f64],
    term_box: Option<&crate::rom::ModulusRange>,
) -> crate::rfm::FitStatus {
    use crate::rfm::status::{box_flag, parameter_flags, ParamCheck};
    let after = &res.after;
    let n = after.n_law.min(after.values.len()).min(after.names.len());
    let Ok(law) = crate::material::model_from_name(&after.law, None) else {
        return crate::rfm::FitStatus::Converged;
    };
    let units = law.param_units();
    let checks: Vec<ParamCheck<'_>> = (0..n)
        .map(|k| ParamCheck {
            name: &after.names[k],
            unit: units.get(k).map(String::as_str).unwrap_or(""),
            value: after.values[k],
            range: (f64::NEG_INFINITY, f64::INFINITY),
        })
        .collect();
    let mut reasons = parameter_flags(&checks);
    if let (Some(range), true) = (term_box, n == law.n_params()) {
        let curve: Vec<(f64, crate::common::C64)> = freq_hz
            .iter()
            .map(|&f| {
                (
                    f,
                    law.modulus(&after.values[..n], std::f64::consts::TAU * f),
                )
            })
            .collect();
        reasons.extend(box_flag(&curve, range));
    }
    crate::rfm::FitStatus::from_reasons(reasons)
}

/// `verdict`: one row per level: the status, the null level and threshold, where the residual
/// is, the tentative, dropped and confounded effects, and the sentence of the report.
pub(crate) fn verdict_table(
    results: &[LevelResult],
    summary: &[DiagnoseLevel],
) -> Result<Table, RunError> {
    let verdicts: Vec<&crate::closed_loop::verdict::Verdict> =
        summary.iter().map(|l| &l.verdict).collect();
    let mut t = Table::new("verdict");
    let lv: Vec<String> = results.iter().map(|r| r.0.clone()).collect();
    let st: Vec<String> = verdicts.iter().map(|v| v.status.to_string()).collect();
    let f = |g: &dyn Fn(&crate::closed_loop::verdict::Verdict) -> f64| -> Vec<f64> {
        verdicts.iter().map(|v| g(v)).collect()
    };
    let text = |g: &dyn Fn(&crate::closed_loop::verdict::Verdict) -> String| -> Vec<String> {
        verdicts.iter().map(|v| g(v)).collect()
    };
    let join = |v: Vec<String>| v.join("; ");
    t.push_str("level", lv)
        .and_then(|t| t.push_str("status", st))
        .and_then(|t| t.push_f64("chi2_before", "1", f(&|v| v.chi2_before)))
        .and_then(|t| t.push_f64("chi2_after", "1", f(&|v| v.chi2_after)))
        .and_then(|t| t.push_f64("null_mean", "1", f(&|v| v.null_mean)))
        .and_then(|t| t.push_f64("null_sd", "1", f(&|v| v.null_sd)))
        .and_then(|t| t.push_f64("threshold", "1", f(&|v| v.threshold)))
        .and_then(|t| t.push_f64("false_alarm", "1", f(&|v| v.false_alarm)))
        .and_then(|t| t.push_f64("excess", "1", f(&|v| v.excess)))
        .and_then(|t| {
            t.push_str(
                "null_method",
                summary.iter().map(|s| s.null.method.clone()).collect(),
            )
        })
        .and_then(|t| {
            t.push_str(
                "worst_bands",
                text(&|v| {
                    join(
                        v.bands
                            .iter()
                            .map(|b| {
                                format!(
                                    "{:.0}-{:.0} Hz: {:.3}",
                                    b.lo_hz, b.hi_hz, b.chi2_normalised
                                )
                            })
                            .collect(),
                    )
                }),
            )
        })
        .and_then(|t| {
            t.push_str(
                "channels",
                text(&|v| {
                    join(
                        v.channels
                            .iter()
                            .map(|c| {
                                format!(
                                    "ch{}: {:.3} (null {:.3})",
                                    c.id, c.chi2_normalised, c.null_mean
                                )
                            })
                            .collect(),
                    )
                }),
            )
        })
        .and_then(|t| {
            t.push_str(
                "closest",
                text(&|v| {
                    join(
                        v.closest
                            .iter()
                            .map(|c| format!("{}: {:.2} nats", c.name, c.gain))
                            .collect(),
                    )
                }),
            )
        })
        .and_then(|t| t.push_str("tentative", text(&|v| join(v.tentative.clone()))))
        .and_then(|t| {
            t.push_str(
                "dropped",
                text(&|v| {
                    join(
                        v.drop_one
                            .iter()
                            .filter(|d| !d.kept)
                            .map(|d| d.effect.clone())
                            .collect(),
                    )
                }),
            )
        })
        .and_then(|t| {
            t.push_str(
                "left_out",
                text(&|v| join(v.not_needed.iter().map(|d| d.entry()).collect())),
            )
        })
        .and_then(|t| {
            t.push_str(
                "confounded",
                text(&|v| {
                    join(
                        v.confounded
                            .iter()
                            .map(|c| format!("{} (correlation {:.4})", c.effect, c.correlation))
                            .collect(),
                    )
                }),
            )
        })
        .and_then(|t| t.push_str("sentence", text(&|v| v.sentence.clone())))
        .map_err(RunError::Output)?;
    Ok(t)
}
