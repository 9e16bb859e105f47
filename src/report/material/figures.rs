//! The material study's figures: the fits of E' and E'', the residuals, the Kramers-Kronig
//! check.

use crate::material_fit::LoopResult;
use crate::output::ResultsDir;
use crate::plot::{line_figure_with, Curve, CurveStyle, PlotError, PlotParams};
use crate::study::material::MaterialStudy;

pub(super) fn figures(
    dir: &mut ResultsDir,
    study: &MaterialStudy,
    r: &LoopResult,
) -> Result<(), PlotError> {
    let c = &study.curve;
    let first = r.first_candidate();
    let last = r.final_candidate();
    let pp = PlotParams {
        log_x: true,
        ..PlotParams::default()
    };
    let black = (0, 0, 0);
    let mpa = |v: &[f64]| v.iter().map(|x| x * 1e-6).collect::<Vec<f64>>();
    let f = c.freq_hz.clone();
    for (stem, title, label, data, a, b) in [
        (
            "fit_storage",
            "Storage modulus: data and fits",
            "E' (MPa)",
            &c.storage_pa,
            &first.model_storage_pa,
            &last.model_storage_pa,
        ),
        (
            "fit_loss",
            "Loss modulus: data and fits",
            "E'' (MPa)",
            &c.loss_pa,
            &first.model_loss_pa,
            &last.model_loss_pa,
        ),
    ] {
        let curves = vec![
            Curve::new("data", f.clone(), mpa(data), CurveStyle::Points).with_color(black),
            Curve::line(format!("{} (first)", first.law.label()), f.clone(), mpa(a)),
            Curve::line(format!("{} (final)", last.law.label()), f.clone(), mpa(b)),
        ];
        let files = line_figure_with(
            dir.file_path(stem),
            title,
            "Frequency (Hz)",
            label,
            &curves,
            true,
            &pp,
        )?;
        dir.record(&files.png);
        dir.record(&files.svg);
    }
    let curves = vec![
        Curve::new(
            format!("E' {}", first.law.label()),
            f.clone(),
            first.res_log10_storage.clone(),
            CurveStyle::ThinLine,
        ),
        Curve::new(
            format!("E'' {}", first.law.label()),
            f.clone(),
            first.res_log10_loss.clone(),
            CurveStyle::ThinLine,
        ),
        Curve::new(
            format!("E' {}", last.law.label()),
            f.clone(),
            last.res_log10_storage.clone(),
            CurveStyle::Points,
        ),
        Curve::new(
            format!("E'' {}", last.law.label()),
            f.clone(),
            last.res_log10_loss.clone(),
            CurveStyle::Points,
        ),
    ];
    let files = line_figure_with(
        dir.file_path("residuals"),
        "Residuals log10(data / model), first and final law",
        "Frequency (Hz)",
        "log10 residual",
        &curves,
        false,
        &pp,
    )?;
    dir.record(&files.png);
    dir.record(&files.svg);
    let k = &r.kk;
    let curves = vec![
        Curve::new(
            "E'' measured / E'' implied by E'",
            f.clone(),
            k.res_loss_from_storage.clone(),
            CurveStyle::Points,
        ),
        Curve::new(
            "E' measured / E' implied by E''",
            f.clone(),
            k.res_storage_from_loss.clone(),
            CurveStyle::Points,
        ),
        Curve::new(
            "E' measured / best causal fit",
            f.clone(),
            k.res_causal_storage.clone(),
            CurveStyle::ThinLine,
        ),
        Curve::new(
            "E'' measured / best causal fit",
            f.clone(),
            k.res_causal_loss.clone(),
            CurveStyle::ThinLine,
        ),
    ];
    let files = line_figure_with(
        dir.file_path("kk"),
        "Kramers-Kronig check: log10(measured / implied)",
        "Frequency (Hz)",
        "log10 residual",
        &curves,
        false,
        &pp,
    )?;
    dir.record(&files.png);
    dir.record(&files.svg);
    Ok(())
}
