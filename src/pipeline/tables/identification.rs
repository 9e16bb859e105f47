//! The tables of the deterministic identification (global RFM per model, per-line RFM, circle
//! fit and IEM, Model 1 over bands, correlation, sensitivities). Tables (parquet, units in the
//! file metadata key `rfmlab.units`):
//!
//! | table | columns (unit) |
//! |---|---|
//! | `frf` | level, model (`""` for measured), kind (measured / initial / updated), response_id, reference_id, freq_hz (Hz), accelerance_re, accelerance_im ((m/s^2)/N) |
//! | `parameters` | level, model, parameter, unit, initial, identified (SI unit in `unit`), iterations (updates made, all leakage passes together), stop_reason, status (`converged` / `flagged`), status_reason (why flagged, in words; empty when converged), frac_initial_<id>, frac_updated_<id> (1) per response id |
//! | `iterations` | level, model, iteration, parameter, value (SI), relative_change (1), residual_modulus (Pa), frf_relative_residual (1), rank, step_scale (1) |
//! | `correlation` | level, model, kind (initial / updated), response_id, frac (1) |
//! | `correlation_curves` | level, model, kind, freq_hz (Hz), scc (1), acc (1) |
//! | `modulus` | level, source (model name, `per_line_combined`, `per_line_<id>`), kind (initial / updated / estimate), freq_hz (Hz), storage_modulus, loss_modulus (Pa) |
//! | `svd` | level, model, index, singular_value (Pa), condition_number (1), rank, weak (bool), direction (d ln p, as text) |
//! | `modal` | level, method (circle_fit / iem / rfm_model1_band), center_hz, width_hz (Hz), response_id, freq_hz (Hz), loss_factor (1), storage_modulus, loss_modulus (Pa; NaN for circle fit), iterations |
//! | `sensitivity` | level, response_id, freq_hz (Hz), storage (1), loss (1): |dH'/dE'| E'/max|H'| and |dH'/dE''| E''/max|H'| |

use crate::common::C64;
use crate::output::{Columns as Cols, Table};
use crate::pipeline::LevelResults;
use crate::stage::{LevelData, RunError};

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
                par.s("status", s(g.status.label()));
                par.s("status_reason", g.status.reason_text());
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

/// The deterministic tables, in the order they are written.
pub(super) fn tables(
    levels: &[LevelData],
    results: &[LevelResults],
) -> Result<Vec<Table>, RunError> {
    let t = build_tables(levels, results)?;
    Ok(vec![
        t.frf,
        t.parameters,
        t.iterations,
        t.correlation,
        t.curves,
        t.modulus,
        t.svd,
        t.modal,
        t.sensitivity,
    ])
}
