//! The closed loop's residual figure: the standardised residual magnitude
//! `|z|` of every channel against frequency, before (upper panel) and after (lower panel) the
//! accepted effects. Under a correct model `|z|^2` is chi-square with 2 degrees of freedom
//! (mean 1), so a residual consistent with noise scatters around 1; a missing effect shows as
//! bands of large `|z|` around the resonances it moves.

use std::path::Path;

use super::{draw, Curve, CurveStyle, FigureFiles, PlotError, PlotParams};
use crate::common::C64;

/// Write `<path_stem>.png` and `.svg`: `|z|` per channel (`[line * n + k]`, `n =
/// channel_ids.len()`) before and after, against `freq_hz`, on a logarithmic axis.
pub fn residual_figure(
    path_stem: impl AsRef<Path>,
    title: &str,
    freq_hz: &[f64],
    channel_ids: &[u32],
    z_before: &[C64],
    z_after: &[C64],
) -> Result<FigureFiles, PlotError> {
    let n = channel_ids.len();
    let curves = |z: &[C64]| -> Vec<Curve> {
        channel_ids
            .iter()
            .enumerate()
            .map(|(k, id)| {
                Curve::new(
                    format!("ch{id}"),
                    freq_hz.to_vec(),
                    (0..freq_hz.len())
                        .map(|l| z.get(l * n + k).map_or(f64::NAN, |v| v.norm()))
                        .collect(),
                    CurveStyle::ThinLine,
                )
            })
            .collect()
    };
    let (before, after) = (curves(z_before), curves(z_after));
    let panels = [
        draw::PanelSpec {
            y_label: "|z| before".to_string(),
            log_y: true,
            y_fixed: None,
            wrap_deg: false,
            curves: &before,
            legend: true,
        },
        draw::PanelSpec {
            y_label: "|z| after".to_string(),
            log_y: true,
            y_fixed: None,
            wrap_deg: false,
            curves: &after,
            legend: false,
        },
    ];
    let params = PlotParams::default();
    draw::figure(
        path_stem.as_ref(),
        title,
        &params.freq_label,
        &panels,
        &params,
    )
}
