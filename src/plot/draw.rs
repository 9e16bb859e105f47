//! Rendering shared by every figure: font registration, data preparation (skipping
//! non-finite points), axis ranges, panels, legends and atomic PNG/SVG output.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use plotters::coord::ranged1d::{AsRangedCoord, ValueFormatter};
use plotters::coord::Shift;
use plotters::prelude::*;

use super::{Curve, CurveStyle, DrawError, FigureFiles, PlotError, PlotParams};
use crate::output::{check_parent, commit, temp_sibling, write_atomic_bytes};

/// The embedded font (DejaVu Sans, freely licensed), registered as "sans-serif".
static FONT_BYTES: &[u8] = include_bytes!("../../assets/DejaVuSans.ttf");
static FONT: OnceLock<Result<(), String>> = OnceLock::new();

pub(crate) fn ensure_font() -> Result<(), PlotError> {
    FONT.get_or_init(|| {
        plotters::style::register_font("sans-serif", FontStyle::Normal, FONT_BYTES)
            .map_err(|_| "DejaVuSans.ttf is not a valid TrueType font".to_string())
    })
    .clone()
    .map_err(PlotError::Font)
}

/// Colours given to curves without an explicit one, in order (black first: measured data).
pub(crate) const PALETTE: [(u8, u8, u8); 10] = [
    (0, 0, 0),
    (31, 119, 180),
    (214, 39, 40),
    (44, 160, 44),
    (255, 127, 14),
    (148, 103, 189),
    (140, 86, 75),
    (227, 119, 194),
    (127, 127, 127),
    (23, 190, 207),
];

/// What a figure function asks to draw in one panel.
pub(crate) struct PanelSpec<'a> {
    pub y_label: String,
    pub log_y: bool,
    /// Fixed y range (phase: -180..180) instead of the data range.
    pub y_fixed: Option<(f64, f64)>,
    /// Break lines where consecutive values jump by more than 180 (wrapped phase).
    pub wrap_deg: bool,
    pub curves: &'a [Curve],
    pub legend: bool,
}

struct Prepared {
    label: String,
    segments: Vec<Vec<(f64, f64)>>,
    style: CurveStyle,
    color: RGBColor,
}

struct Panel {
    y_label: String,
    y_range: (f64, f64),
    log_y: bool,
    curves: Vec<Prepared>,
    legend: bool,
    legend_pos: LegendCorner,
}

/// Legend placements tried, in order of preference.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum LegendCorner {
    UpperRight,
    UpperLeft,
    LowerRight,
    LowerLeft,
    UpperMiddle,
    LowerMiddle,
}

impl LegendCorner {
    const ALL: [LegendCorner; 6] = [
        LegendCorner::UpperRight,
        LegendCorner::UpperLeft,
        LegendCorner::LowerRight,
        LegendCorner::LowerLeft,
        LegendCorner::UpperMiddle,
        LegendCorner::LowerMiddle,
    ];
    /// The box (x0, x1, y0, y1) in plot coordinates normalised to [0, 1] the legend covers
    /// (roughly: 35 % of the width, 12 % of the height per line of legend text, at most 60 %).
    fn region(self, n_entries: usize) -> (f64, f64, f64, f64) {
        let h = (0.12 * n_entries as f64 + 0.04).min(0.6);
        let (x0, x1) = match self {
            LegendCorner::UpperRight | LegendCorner::LowerRight => (0.65, 1.0),
            LegendCorner::UpperLeft | LegendCorner::LowerLeft => (0.0, 0.35),
            _ => (0.325, 0.675),
        };
        let (y0, y1) = match self {
            LegendCorner::UpperRight | LegendCorner::UpperLeft | LegendCorner::UpperMiddle => {
                (1.0 - h, 1.0)
            }
            _ => (0.0, h),
        };
        (x0, x1, y0, y1)
    }
    fn to_plotters(self) -> SeriesLabelPosition {
        match self {
            LegendCorner::UpperRight => SeriesLabelPosition::UpperRight,
            LegendCorner::UpperLeft => SeriesLabelPosition::UpperLeft,
            LegendCorner::LowerRight => SeriesLabelPosition::LowerRight,
            LegendCorner::LowerLeft => SeriesLabelPosition::LowerLeft,
            LegendCorner::UpperMiddle => SeriesLabelPosition::UpperMiddle,
            LegendCorner::LowerMiddle => SeriesLabelPosition::LowerMiddle,
        }
    }
}

/// Picks the legend placement covering the least data: points count once, lines are sampled
/// densely along each segment (in normalised, log-aware coordinates).
fn place_legend(
    curves: &[Prepared],
    x_range: (f64, f64),
    y_range: (f64, f64),
    log_x: bool,
    log_y: bool,
) -> LegendCorner {
    let norm = |v: f64, (lo, hi): (f64, f64), log: bool| {
        if log {
            (v.ln() - lo.ln()) / (hi.ln() - lo.ln())
        } else {
            (v - lo) / (hi - lo)
        }
    };
    let mut samples: Vec<(f64, f64)> = Vec::new();
    for c in curves {
        for seg in &c.segments {
            let pts: Vec<(f64, f64)> = seg
                .iter()
                .map(|&(x, y)| (norm(x, x_range, log_x), norm(y, y_range, log_y)))
                .collect();
            if c.style == CurveStyle::Points || pts.len() == 1 {
                samples.extend(&pts);
                continue;
            }
            for w in pts.windows(2) {
                let (a, b) = (w[0], w[1]);
                let d = ((b.0 - a.0).powi(2) + (b.1 - a.1).powi(2)).sqrt();
                let n = ((d * 100.0).ceil() as usize).clamp(1, 100);
                for k in 0..n {
                    let t = k as f64 / n as f64;
                    samples.push((a.0 + t * (b.0 - a.0), a.1 + t * (b.1 - a.1)));
                }
            }
            samples.extend(pts.last());
        }
    }
    let n_entries = curves.len();
    let mut best = (usize::MAX, LegendCorner::UpperRight);
    for corner in LegendCorner::ALL {
        let (x0, x1, y0, y1) = corner.region(n_entries);
        let hits = samples
            .iter()
            .filter(|&&(x, y)| x >= x0 && x <= x1 && y >= y0 && y <= y1)
            .count();
        if hits < best.0 {
            best = (hits, corner);
        }
    }
    best.1
}

/// Splits a curve into runs of drawable points.
fn segments(c: &Curve, log_x: bool, log_y: bool, wrap_deg: bool) -> Vec<Vec<(f64, f64)>> {
    let mut out: Vec<Vec<(f64, f64)>> = Vec::new();
    let mut cur: Vec<(f64, f64)> = Vec::new();
    for (&x, &y) in c.x.iter().zip(&c.y) {
        let ok = x.is_finite() && y.is_finite() && (!log_x || x > 0.0) && (!log_y || y > 0.0);
        if !ok {
            if !cur.is_empty() {
                out.push(std::mem::take(&mut cur));
            }
            continue;
        }
        if wrap_deg {
            if let Some(&(_, py)) = cur.last() {
                if (y - py).abs() > 180.0 {
                    out.push(std::mem::take(&mut cur));
                }
            }
        }
        cur.push((x, y));
    }
    if !cur.is_empty() {
        out.push(cur);
    }
    out
}

/// Range of `v` padded for display; `None` when empty.
pub(crate) fn padded_range(mut it: impl Iterator<Item = f64>, log: bool) -> Option<(f64, f64)> {
    let first = it.next()?;
    let (lo, hi) = it.fold((first, first), |(a, b), v| (a.min(v), b.max(v)));
    Some(if log {
        let (lo, hi) = if hi / lo < 1.5 {
            (lo / 1.5, hi * 1.5)
        } else {
            (lo, hi)
        };
        (lo / 1.2, hi * 1.2)
    } else if hi > lo {
        let pad = 0.05 * (hi - lo);
        (lo - pad, hi + pad)
    } else {
        let d = if lo != 0.0 { 0.1 * lo.abs() } else { 1.0 };
        (lo - d, hi + d)
    })
}

/// Short tick labels: plain decimals for moderate magnitudes, else scientific.
pub(crate) fn fmt_tick(v: &f64) -> String {
    let a = v.abs();
    if a == 0.0 {
        return "0".to_string();
    }
    if !(1e-3..1e5).contains(&a) {
        let s = format!("{v:.1e}");
        return s.replace(".0e", "e");
    }
    let decimals = (3 - a.log10().floor() as i32).clamp(0, 6) as usize;
    let s = format!("{v:.decimals$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

fn prepare(specs: &[PanelSpec], log_x: bool) -> Result<(Vec<Panel>, (f64, f64)), PlotError> {
    let mut panels = Vec::with_capacity(specs.len());
    let mut xs: Vec<f64> = Vec::new();
    let mut any_points = false;
    for spec in specs {
        let mut curves = Vec::with_capacity(spec.curves.len());
        for (i, c) in spec.curves.iter().enumerate() {
            if c.x.len() != c.y.len() {
                return Err(PlotError::LengthMismatch {
                    label: c.label.clone(),
                    x_len: c.x.len(),
                    y_len: c.y.len(),
                });
            }
            if c.x.is_empty() {
                return Err(PlotError::EmptyCurve {
                    label: c.label.clone(),
                });
            }
            let (r, g, b) = c.color.unwrap_or(PALETTE[i % PALETTE.len()]);
            curves.push(Prepared {
                label: c.label.clone(),
                segments: segments(c, log_x, spec.log_y, spec.wrap_deg),
                style: c.style,
                color: RGBColor(r, g, b),
            });
        }
        let pts = || curves.iter().flat_map(|c| c.segments.iter().flatten());
        let no_data = || PlotError::NoFiniteData {
            panel: spec.y_label.clone(),
            log_axis: spec.log_y || log_x,
        };
        let y_range = match spec.y_fixed {
            Some(r) => {
                if pts().next().is_none() {
                    return Err(no_data());
                }
                r
            }
            None => padded_range(pts().map(|p| p.1), spec.log_y).ok_or_else(no_data)?,
        };
        xs.extend(pts().map(|p| p.0));
        any_points |= curves.iter().any(|c| c.style == CurveStyle::Points);
        panels.push(Panel {
            y_label: spec.y_label.clone(),
            y_range,
            log_y: spec.log_y,
            curves,
            legend: spec.legend,
            legend_pos: LegendCorner::UpperRight,
        });
    }
    let x_range = match padded_range(xs.iter().copied(), log_x) {
        // Lines start and end at the axis limits; markers get a small margin so that the
        // first and last ones are not cut in half.
        Some(padded) => {
            let lo = xs.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = xs.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            if hi <= lo {
                padded
            } else if !any_points {
                (lo, hi)
            } else if log_x {
                let r = (hi / lo).powf(0.015);
                (lo / r, hi * r)
            } else {
                let d = 0.015 * (hi - lo);
                (lo - d, hi + d)
            }
        }
        None => {
            return Err(PlotError::NoFiniteData {
                panel: "x axis".to_string(),
                log_axis: log_x,
            })
        }
    };
    for p in &mut panels {
        p.legend_pos = place_legend(&p.curves, x_range, p.y_range, log_x, p.log_y);
    }
    Ok((panels, x_range))
}

pub(crate) fn append_ext(stem: &Path, ext: &str) -> PathBuf {
    let mut s = stem.as_os_str().to_owned();
    s.push(".");
    s.push(ext);
    PathBuf::from(s)
}

/// Renders the panels (stacked, sharing the x axis) to `<stem>.png` and `<stem>.svg`.
pub(crate) fn figure(
    stem: &Path,
    title: &str,
    x_label: &str,
    specs: &[PanelSpec],
    params: &PlotParams,
) -> Result<FigureFiles, PlotError> {
    ensure_font()?;
    let (panels, x_range) = prepare(specs, params.log_x)?;
    let height = if params.height_px > 0 {
        params.height_px
    } else if panels.len() > 1 {
        800
    } else {
        560
    };
    let size = (params.width_px.max(200), height.max(150));
    let job = Job {
        title,
        x_label,
        panels: &panels,
        x_range,
        log_x: params.log_x,
        font_px: params.font_px.max(6),
    };
    write_png_svg(stem, size, &job)
}

/// Something that can draw itself on any plotters backend (PNG and SVG share one renderer).
pub(crate) trait Render {
    fn render<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), DrawError>;
}

/// Renders `job` to `<stem>.png` and `<stem>.svg` of `size` pixels, each written atomically.
pub(crate) fn write_png_svg<R: Render>(
    stem: &Path,
    size: (u32, u32),
    job: &R,
) -> Result<FigureFiles, PlotError> {
    ensure_font()?;
    let png = append_ext(stem, "png");
    let svg = append_ext(stem, "svg");
    check_parent(&png)?;

    // PNG: rendered into a temporary sibling (keeping the .png extension, which the encoder
    // needs), then moved over the target.
    let tmp = temp_sibling(&png)?;
    let result = {
        let root = BitMapBackend::new(&tmp, size).into_drawing_area();
        job.render(&root).and_then(|()| root.present().map_err(err))
    };
    if let Err(DrawError(message)) = result {
        let _ = std::fs::remove_file(&tmp);
        return Err(PlotError::Render { path: png, message });
    }
    commit(&tmp, &png)?;

    // SVG: rendered into memory, then written atomically.
    let mut text = String::new();
    let result = {
        let root = SVGBackend::with_string(&mut text, size).into_drawing_area();
        job.render(&root).and_then(|()| root.present().map_err(err))
    };
    if let Err(DrawError(message)) = result {
        return Err(PlotError::Render { path: svg, message });
    }
    write_atomic_bytes(&svg, text.as_bytes())?;
    Ok(FigureFiles { png, svg })
}

struct Job<'a> {
    title: &'a str,
    x_label: &'a str,
    panels: &'a [Panel],
    x_range: (f64, f64),
    log_x: bool,
    font_px: u32,
}

pub(crate) fn err<E: std::fmt::Display>(e: E) -> DrawError {
    DrawError(e.to_string())
}

impl Render for Job<'_> {
    fn render<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), DrawError> {
        let fs = f64::from(self.font_px);
        root.fill(&WHITE).map_err(err)?;
        let area = root
            .titled(self.title, ("sans-serif", 1.4 * fs))
            .map_err(err)?;
        let areas = area.split_evenly((self.panels.len(), 1));
        let (x0, x1) = self.x_range;
        let last = self.panels.len().saturating_sub(1);
        for (i, (a, p)) in areas.iter().zip(self.panels).enumerate() {
            // Only the bottom panel names the shared x axis.
            let x_label = if i == last { self.x_label } else { "" };
            let (y0, y1) = p.y_range;
            match (self.log_x, p.log_y) {
                (false, false) => self.panel(a, p, x_label, x0..x1, y0..y1),
                (false, true) => self.panel(a, p, x_label, x0..x1, (y0..y1).log_scale()),
                (true, false) => self.panel(a, p, x_label, (x0..x1).log_scale(), y0..y1),
                (true, true) => {
                    self.panel(a, p, x_label, (x0..x1).log_scale(), (y0..y1).log_scale())
                }
            }?;
        }
        Ok(())
    }
}

impl Job<'_> {
    fn panel<DB, XS, YS>(
        &self,
        area: &DrawingArea<DB, Shift>,
        p: &Panel,
        x_label: &str,
        xs: XS,
        ys: YS,
    ) -> Result<(), DrawError>
    where
        DB: DrawingBackend,
        XS: AsRangedCoord<Value = f64>,
        YS: AsRangedCoord<Value = f64>,
        XS::CoordDescType: ValueFormatter<f64>,
        YS::CoordDescType: ValueFormatter<f64>,
    {
        let fs = f64::from(self.font_px);
        let mut chart = ChartBuilder::on(area)
            .margin((0.8 * fs) as u32)
            .x_label_area_size((2.8 * fs) as u32)
            .y_label_area_size((5.0 * fs) as u32)
            .build_cartesian_2d(xs, ys)
            .map_err(err)?;
        let mut mesh = chart.configure_mesh();
        mesh.y_desc(p.y_label.as_str())
            .label_style(("sans-serif", fs))
            .axis_desc_style(("sans-serif", 1.1 * fs))
            .x_label_formatter(&fmt_tick)
            .y_label_formatter(&fmt_tick)
            .light_line_style(RGBColor(0, 0, 0).mix(0.04))
            .bold_line_style(RGBColor(0, 0, 0).mix(0.12));
        if !x_label.is_empty() {
            mesh.x_desc(x_label);
        }
        mesh.draw().map_err(err)?;

        for c in &p.curves {
            let color = c.color;
            match c.style {
                CurveStyle::Points => {
                    // Smaller markers for dense data so that the line shape stays visible.
                    let n: usize = c.segments.iter().map(Vec::len).sum();
                    let base = if n > 150 { fs / 7.5 } else { fs / 5.0 };
                    let r = base.round().max(1.0) as i32;
                    chart
                        .draw_series(
                            c.segments
                                .iter()
                                .flatten()
                                .map(move |&pt| Circle::new(pt, r, color.filled())),
                        )
                        .map_err(err)?
                        .label(c.label.as_str())
                        .legend(move |(x, y)| Circle::new((x + 10, y), r + 1, color.filled()));
                }
                CurveStyle::Line | CurveStyle::ThinLine => {
                    let w = if c.style == CurveStyle::Line { 2 } else { 1 };
                    chart
                        .draw_series(
                            c.segments
                                .iter()
                                .map(move |s| PathElement::new(s.clone(), color.stroke_width(w))),
                        )
                        .map_err(err)?
                        .label(c.label.as_str())
                        .legend(move |(x, y)| {
                            PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(w))
                        });
                }
            }
        }
        if p.legend {
            chart
                .configure_series_labels()
                .label_font(("sans-serif", fs))
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK.mix(0.5))
                .position(p.legend_pos.to_plotters())
                .draw()
                .map_err(err)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn segments_break_at_nan_and_log_nonpositive() {
        let c = Curve::line(
            "c",
            vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0],
            vec![1.0, f64::NAN, 2.0, -1.0, 3.0, f64::INFINITY],
        );
        assert_eq!(segments(&c, false, false, false).len(), 2);
        let s = segments(&c, false, true, false);
        assert_eq!(
            s,
            vec![vec![(1.0, 1.0)], vec![(3.0, 2.0)], vec![(5.0, 3.0)]]
        );
    }

    #[test]
    fn wrapped_phase_breaks_lines() {
        let c = Curve::line("p", vec![1.0, 2.0, 3.0], vec![170.0, -175.0, -170.0]);
        assert_eq!(segments(&c, false, false, true).len(), 2);
    }

    #[test]
    fn tick_labels_are_short() {
        assert_eq!(fmt_tick(&0.0), "0");
        assert_eq!(fmt_tick(&100.0), "100");
        assert_eq!(fmt_tick(&0.25), "0.25");
        assert_eq!(fmt_tick(&1e-5), "1e-5");
        assert_eq!(fmt_tick(&2.5e6), "2.5e6");
    }
}
