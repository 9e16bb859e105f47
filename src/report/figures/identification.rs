//! The figures of the deterministic identification, per level: the measured and updated FRFs
//! per response (`fig_frf_<level>_<response><reference>`), SCC and ACC of the updated models
//! (`fig_scc_<level>`, `fig_acc_<level>`), the convergence of each model's relative FRF
//! residual (`fig_convergence_<level>`) and E'(f), E''(f) of the per-line estimates, the
//! updated models and the truth of simulated data (`fig_modulus_<level>`); each as `.png` and
//! `.svg`.

use crate::common::C64;
use crate::identify::frf_of;
use crate::pipeline::LevelResults;
use crate::plot::{Curve, CurveStyle, FrfCurve};
use crate::stage::{LevelData, RunError};
use std::path::Path;

const TWO_PI: f64 = 2.0 * std::f64::consts::PI;

/// Draw the figures into `dir`; returns (file name of the PNG, caption).
pub(super) fn draw_figures(
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
