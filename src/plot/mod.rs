//! Figures as PNG and SVG (plotters): FRF amplitude and phase, line plots (SCC, ACC,
//! convergence histories) and complex-modulus panels. Outside the numerical core.
//!
//! Text is drawn with the DejaVu Sans font embedded in the binary (`assets/DejaVuSans.ttf`,
//! registered once with plotters' `ab_glyph` backend), so no system font library is needed.
//!
//! Every function writes `<path_stem>.png` and `<path_stem>.svg`, each atomically (temporary
//! file in the same folder, then rename). Non-finite points (NaN, inf) and, on logarithmic
//! axes, non-positive values are skipped: lines are broken there. An empty curve, a curve
//! whose x and y lengths differ, or a panel with nothing to draw is an error, never a panic.

pub mod closed_loop;
mod draw;
mod error;
pub mod posterior;

use std::path::{Path, PathBuf};

use crate::common::C64;

pub use error::{DrawError, PlotError};

/// How a curve is drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum CurveStyle {
    /// A 2 px line (models).
    #[default]
    Line,
    /// A 1 px line (dense measured data).
    ThinLine,
    /// Filled circles, no line (measured lines, per-line estimates).
    Points,
}

/// A labelled real curve y(x).
#[derive(Clone, Debug, PartialEq)]
pub struct Curve {
    pub label: String,
    pub x: Vec<f64>,
    pub y: Vec<f64>,
    pub style: CurveStyle,
    /// RGB colour; `None` picks the next colour of the palette (by curve position).
    pub color: Option<(u8, u8, u8)>,
}

impl Curve {
    pub fn new(label: impl Into<String>, x: Vec<f64>, y: Vec<f64>, style: CurveStyle) -> Self {
        Curve {
            label: label.into(),
            x,
            y,
            style,
            color: None,
        }
    }
    /// A model curve ([`CurveStyle::Line`]).
    pub fn line(label: impl Into<String>, x: Vec<f64>, y: Vec<f64>) -> Self {
        Curve::new(label, x, y, CurveStyle::Line)
    }
    /// Scatter points ([`CurveStyle::Points`]).
    pub fn points(label: impl Into<String>, x: Vec<f64>, y: Vec<f64>) -> Self {
        Curve::new(label, x, y, CurveStyle::Points)
    }
    /// Sets an explicit colour.
    pub fn with_color(mut self, rgb: (u8, u8, u8)) -> Self {
        self.color = Some(rgb);
        self
    }
}

/// A labelled complex FRF H(f).
#[derive(Clone, Debug, PartialEq)]
pub struct FrfCurve {
    pub label: String,
    /// Values on the figure's frequency grid, or on `freq_hz` when given.
    pub h: Vec<C64>,
    /// Own frequency grid (Hz), e.g. a finer grid for a model curve; `None` uses the figure's.
    pub freq_hz: Option<Vec<f64>>,
    pub style: CurveStyle,
    pub color: Option<(u8, u8, u8)>,
}

impl FrfCurve {
    /// A curve on the figure's frequency grid.
    pub fn new(label: impl Into<String>, h: Vec<C64>, style: CurveStyle) -> Self {
        FrfCurve {
            label: label.into(),
            h,
            freq_hz: None,
            style,
            color: None,
        }
    }
    /// A curve on its own frequency grid (Hz).
    pub fn on_grid(
        label: impl Into<String>,
        freq_hz: Vec<f64>,
        h: Vec<C64>,
        style: CurveStyle,
    ) -> Self {
        FrfCurve {
            freq_hz: Some(freq_hz),
            ..FrfCurve::new(label, h, style)
        }
    }
    pub fn with_color(mut self, rgb: (u8, u8, u8)) -> Self {
        self.color = Some(rgb);
        self
    }
}

/// Figure settings.
#[derive(Clone, Debug, PartialEq)]
pub struct PlotParams {
    /// Width of the PNG/SVG in pixels. Default 1000.
    pub width_px: u32,
    /// Height in pixels. Default 0 = automatic (560 for one panel, 800 for two).
    pub height_px: u32,
    /// Base font size in pixels (tick labels); titles and axis names are scaled from it.
    /// Default 15.
    pub font_px: u32,
    /// Logarithmic frequency (x) axis. Default false.
    pub log_x: bool,
    /// Y-axis name of the FRF amplitude panel. Default `"|H| ((m/s^2)/N)"` (accelerance).
    pub amplitude_label: String,
    /// X-axis name of FRF and modulus figures. Default `"Frequency (Hz)"`.
    pub freq_label: String,
}

impl Default for PlotParams {
    fn default() -> Self {
        PlotParams {
            width_px: 1000,
            height_px: 0,
            font_px: 15,
            log_x: false,
            amplitude_label: "|H| ((m/s^2)/N)".to_string(),
            freq_label: "Frequency (Hz)".to_string(),
        }
    }
}

/// The two files a figure function wrote.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FigureFiles {
    pub png: PathBuf,
    pub svg: PathBuf,
}

/// FRF figure: amplitude |H| (log axis) above phase (degrees, -180..180) against frequency,
/// one legend entry per curve. Measured data are usually [`CurveStyle::Points`] or
/// [`CurveStyle::ThinLine`], models [`CurveStyle::Line`]. Curves without their own grid must
/// have `freq_hz.len()` values. Writes `<path_stem>.png` and `<path_stem>.svg`.
pub fn frf_figure(
    path_stem: impl AsRef<Path>,
    title: &str,
    freq_hz: &[f64],
    curves: &[FrfCurve],
) -> Result<FigureFiles, PlotError> {
    frf_figure_with(path_stem, title, freq_hz, curves, &PlotParams::default())
}

/// [`frf_figure`] with explicit settings.
pub fn frf_figure_with(
    path_stem: impl AsRef<Path>,
    title: &str,
    freq_hz: &[f64],
    curves: &[FrfCurve],
    params: &PlotParams,
) -> Result<FigureFiles, PlotError> {
    if curves.is_empty() {
        return Err(PlotError::NoCurves {
            figure: title.to_string(),
        });
    }
    let mut amp = Vec::with_capacity(curves.len());
    let mut phase = Vec::with_capacity(curves.len());
    for c in curves {
        let f = c.freq_hz.as_deref().unwrap_or(freq_hz).to_vec();
        let mut a = Curve::new(
            c.label.clone(),
            f.clone(),
            c.h.iter().map(|z| z.norm()).collect(),
            c.style,
        );
        a.color = c.color;
        let mut p = Curve::new(
            c.label.clone(),
            f,
            c.h.iter().map(|z| z.arg().to_degrees()).collect(),
            c.style,
        );
        p.color = c.color;
        amp.push(a);
        phase.push(p);
    }
    let panels = [
        draw::PanelSpec {
            y_label: params.amplitude_label.clone(),
            log_y: true,
            y_fixed: None,
            wrap_deg: false,
            curves: &amp,
            legend: true,
        },
        draw::PanelSpec {
            y_label: "Phase (deg)".to_string(),
            log_y: false,
            y_fixed: Some((-180.0, 180.0)),
            wrap_deg: true,
            curves: &phase,
            legend: false,
        },
    ];
    draw::figure(
        path_stem.as_ref(),
        title,
        &params.freq_label,
        &panels,
        params,
    )
}

/// A single-panel figure of labelled curves (SCC and ACC against frequency, convergence
/// histories against iteration), optionally with a logarithmic y axis.
pub fn line_figure(
    path_stem: impl AsRef<Path>,
    title: &str,
    x_label: &str,
    y_label: &str,
    curves: &[Curve],
    log_y: bool,
) -> Result<FigureFiles, PlotError> {
    line_figure_with(
        path_stem,
        title,
        x_label,
        y_label,
        curves,
        log_y,
        &PlotParams::default(),
    )
}

/// [`line_figure`] with explicit settings.
pub fn line_figure_with(
    path_stem: impl AsRef<Path>,
    title: &str,
    x_label: &str,
    y_label: &str,
    curves: &[Curve],
    log_y: bool,
    params: &PlotParams,
) -> Result<FigureFiles, PlotError> {
    if curves.is_empty() {
        return Err(PlotError::NoCurves {
            figure: title.to_string(),
        });
    }
    let panels = [draw::PanelSpec {
        y_label: y_label.to_string(),
        log_y,
        y_fixed: None,
        wrap_deg: false,
        curves,
        legend: true,
    }];
    draw::figure(path_stem.as_ref(), title, x_label, &panels, params)
}

/// Complex modulus figure: storage modulus E'(f) above loss modulus E''(f). Curves hold
/// frequency in Hz as x and moduli **in Pa** as y (SI, as everywhere in rfmlab); the axes show
/// MPa. Per-line RFM estimates are usually [`CurveStyle::Points`], model curves
/// [`CurveStyle::Line`].
pub fn modulus_figure(
    path_stem: impl AsRef<Path>,
    title: &str,
    storage: &[Curve],
    loss: &[Curve],
) -> Result<FigureFiles, PlotError> {
    modulus_figure_with(path_stem, title, storage, loss, &PlotParams::default())
}

/// [`modulus_figure`] with explicit settings.
pub fn modulus_figure_with(
    path_stem: impl AsRef<Path>,
    title: &str,
    storage: &[Curve],
    loss: &[Curve],
    params: &PlotParams,
) -> Result<FigureFiles, PlotError> {
    if storage.is_empty() || loss.is_empty() {
        return Err(PlotError::NoCurves {
            figure: title.to_string(),
        });
    }
    let to_mpa = |cs: &[Curve]| -> Vec<Curve> {
        cs.iter()
            .map(|c| Curve {
                y: c.y.iter().map(|v| v * 1e-6).collect(),
                ..c.clone()
            })
            .collect()
    };
    let (s, l) = (to_mpa(storage), to_mpa(loss));
    let panels = [
        draw::PanelSpec {
            y_label: "E' (MPa)".to_string(),
            log_y: false,
            y_fixed: None,
            wrap_deg: false,
            curves: &s,
            legend: true,
        },
        draw::PanelSpec {
            y_label: "E'' (MPa)".to_string(),
            log_y: false,
            y_fixed: None,
            wrap_deg: false,
            curves: &l,
            legend: true,
        },
    ];
    draw::figure(
        path_stem.as_ref(),
        title,
        &params.freq_label,
        &panels,
        params,
    )
}
