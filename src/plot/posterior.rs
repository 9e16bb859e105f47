//! Figures of the Bayesian layer: MCMC traces with per-chain marginal densities, a corner
//! (pair) plot with the MAP and the Laplace 95 % ellipses, and posterior bands of the
//! complex modulus E*(f) = E' + j E''.
//!
//! Like the other figures, every function takes plain data (no type of the inference code),
//! writes `<stem>.png` and `<stem>.svg` atomically (`path_png` may end in `.png` or be the bare
//! stem), skips non-finite values, and turns every bad input (no draws, mismatched lengths,
//! nothing finite to draw) into a [`PlotError`], never a panic.

use crate::common::quantile_sorted;
use std::path::{Path, PathBuf};

use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use super::draw::{self, err, Render, PALETTE};
use super::{DrawError, PlotError};

/// Base font size (tick labels), as the other figures.
const FS: f64 = 15.0;
/// Width of the trace and band figures, as the other figures.
const WIDTH: u32 = 1000;
/// chi-square(2) 0.95 quantile: the Laplace 95 % ellipse is (x-m)' S^-1 (x-m) = 5.991.
const CHI2_2_95: f64 = 5.991;
/// At most this many points of a chain's trace are drawn (min/max per bin beyond).
const TRACE_MAX_POINTS: usize = 1600;
/// At most this many draws are scattered in all pair panels together (regular thinning
/// beyond), with 500 to 2000 per panel: keeps the SVG of an 8-parameter corner plot small.
const PAIR_MAX_POINTS_TOTAL: usize = 6000;

/// Points drawn over the bands: `(label, freq_hz, E' (Pa), E'' (Pa))`, e.g. the per-line RFM
/// estimates of one level.
pub type Overlay = (String, Vec<f64>, Vec<f64>, Vec<f64>);

/// One group of posterior draws of E*(f) for [`posterior_bands_figure`] (e.g. one excitation
/// level), drawn in its own colour.
#[derive(Clone, Debug, PartialEq)]
pub struct BandGroup {
    pub label: String,
    /// Frequency lines (Hz).
    pub freq_hz: Vec<f64>,
    /// Storage modulus E' (Pa), `[draw][line]`; every row has `freq_hz.len()` values.
    pub storage: Vec<Vec<f64>>,
    /// Loss modulus E'' (Pa), `[draw][line]`.
    pub loss: Vec<Vec<f64>>,
}

// ------------------------------------------------------------------------------------------
// Public figure functions
// ------------------------------------------------------------------------------------------

/// Trace figure: one row per parameter; left the trace of every chain against the draw index
/// (one colour per chain, thin lines), right the marginal density of each chain (Gaussian
/// kernel density, Silverman bandwidth) drawn sideways on the same value axis, so that the
/// chains' densities line up with their traces. `draws` is `[param][chain][draw]`; all
/// parameters must have the same number of chains, every chain at least one draw.
pub fn trace_figure(
    path_png: &Path,
    names: &[String],
    draws: &[Vec<Vec<f64>>],
    title: &str,
) -> Result<(), PlotError> {
    let bad = |reason: String| invalid(title, reason);
    if names.len() != draws.len() {
        return Err(bad(format!(
            "{} parameter names but draws of {} parameters",
            names.len(),
            draws.len()
        )));
    }
    if draws.is_empty() {
        return Err(bad("no parameters".to_string()));
    }
    let n_chains = draws[0].len();
    if n_chains == 0 {
        return Err(bad("no chains".to_string()));
    }
    let mut rows = Vec::with_capacity(draws.len());
    for (name, chains) in names.iter().zip(draws) {
        if chains.len() != n_chains {
            return Err(bad(format!(
                "parameter '{name}' has {} chains, '{}' has {n_chains}",
                chains.len(),
                names[0]
            )));
        }
        if let Some(c) = chains.iter().position(Vec::is_empty) {
            return Err(bad(format!(
                "parameter '{name}': chain {} has no draws",
                c + 1
            )));
        }
        let finite = || chains.iter().flatten().copied().filter(|v| v.is_finite());
        let y_range = draw::padded_range(finite(), false).ok_or(PlotError::NoFiniteData {
            panel: name.clone(),
            log_axis: false,
        })?;
        let traces: Vec<Vec<Vec<(f64, f64)>>> = chains
            .iter()
            .map(|c| decimate(c, TRACE_MAX_POINTS))
            .collect();
        let grid: Vec<f64> = (0..=200)
            .map(|k| y_range.0 + (y_range.1 - y_range.0) * f64::from(k) / 200.0)
            .collect();
        let densities: Vec<Vec<(f64, f64)>> = chains
            .iter()
            .map(|c| {
                let xs: Vec<f64> = c.iter().copied().filter(|v| v.is_finite()).collect();
                if xs.is_empty() {
                    return Vec::new();
                }
                let d = kde(&xs, &grid, y_range.1 - y_range.0);
                d.into_iter().zip(grid.iter().copied()).collect()
            })
            .collect();
        let d_max = densities
            .iter()
            .flatten()
            .map(|p| p.0)
            .fold(0.0f64, f64::max);
        rows.push(TraceRow {
            name: name.clone(),
            y_range,
            traces,
            densities,
            d_max: if d_max > 0.0 { d_max } else { 1.0 },
        });
    }
    let n_max = draws
        .iter()
        .flatten()
        .map(Vec::len)
        .max()
        .unwrap_or(1)
        .max(2);
    let row_h = match rows.len() {
        1..=3 => 220,
        4..=5 => 180,
        _ => 150,
    };
    let height = 110 + row_h * rows.len() as u32 + (3.0 * FS) as u32;
    let job = TraceJob {
        title,
        rows: &rows,
        n_chains,
        n_max,
    };
    draw::write_png_svg(&stem_of(path_png), (WIDTH, height), &job).map(|_| ())
}

/// Corner (pair) plot of `d` parameters: histograms on the diagonal, the (thinned) draws of
/// every pair below it, the sample correlation above it. `draws` is `[param][draw]` (chains
/// pooled). `map` (length d) is marked by a cross (and a vertical line on the diagonal);
/// `laplace_cov` (row-major d x d, the units of the draws) gives on each lower panel the
/// Laplace 95 % ellipse of the 2 x 2 sub-covariance (chi-square(2) 0.95 = 5.991) and on the
/// diagonal the Laplace marginal density, centred at the MAP (at the posterior mean when no
/// MAP is given). A sub-covariance that is not positive definite draws no ellipse.
pub fn pair_figure(
    path_png: &Path,
    names: &[String],
    draws: &[Vec<f64>],
    map: Option<&[f64]>,
    laplace_cov: Option<&[f64]>,
    title: &str,
) -> Result<(), PlotError> {
    let bad = |reason: String| invalid(title, reason);
    let d = draws.len();
    if names.len() != d {
        return Err(bad(format!(
            "{} parameter names but draws of {d} parameters",
            names.len()
        )));
    }
    if d == 0 {
        return Err(bad("no parameters".to_string()));
    }
    let n = draws[0].len();
    if n == 0 {
        return Err(bad("no draws".to_string()));
    }
    if let Some(i) = draws.iter().position(|v| v.len() != n) {
        return Err(bad(format!(
            "parameter '{}' has {} draws, '{}' has {n}",
            names[i],
            draws[i].len(),
            names[0]
        )));
    }
    if let Some(m) = map {
        if m.len() != d {
            return Err(bad(format!(
                "MAP has {} values for {d} parameters",
                m.len()
            )));
        }
    }
    if let Some(c) = laplace_cov {
        if c.len() != d * d {
            return Err(bad(format!(
                "Laplace covariance has {} values, a {d} x {d} matrix needs {}",
                c.len(),
                d * d
            )));
        }
    }
    let mut params = Vec::with_capacity(d);
    for i in 0..d {
        let xs: Vec<f64> = draws[i].iter().copied().filter(|v| v.is_finite()).collect();
        if xs.is_empty() {
            return Err(PlotError::NoFiniteData {
                panel: names[i].clone(),
                log_axis: false,
            });
        }
        let mean = xs.iter().sum::<f64>() / xs.len() as f64;
        let centre = map.map(|m| m[i]).filter(|v| v.is_finite()).unwrap_or(mean);
        let var = laplace_cov
            .map(|c| c[i * d + i])
            .filter(|v| v.is_finite() && *v > 0.0);
        let mut extent: Vec<f64> = vec![
            xs.iter().copied().fold(f64::INFINITY, f64::min),
            xs.iter().copied().fold(f64::NEG_INFINITY, f64::max),
        ];
        if let Some(m) = map {
            if m[i].is_finite() {
                extent.push(m[i]);
            }
        }
        if let Some(v) = var {
            let r = (CHI2_2_95 * v).sqrt();
            extent.extend([centre - r, centre + r]);
        }
        let range =
            draw::padded_range(extent.into_iter(), false).ok_or(PlotError::NoFiniteData {
                panel: names[i].clone(),
                log_axis: false,
            })?;
        let hist = histogram(&xs, range);
        let laplace_pdf = var.map(|v| {
            let s = v.sqrt();
            (0..=200)
                .map(|k| {
                    let x = range.0 + (range.1 - range.0) * f64::from(k) / 200.0;
                    let z = (x - centre) / s;
                    (
                        x,
                        (-0.5 * z * z).exp() / (s * (2.0 * std::f64::consts::PI).sqrt()),
                    )
                })
                .collect::<Vec<_>>()
        });
        params.push(PairParam {
            name: names[i].clone(),
            range,
            hist,
            laplace_pdf,
            map: map.map(|m| m[i]).filter(|v| v.is_finite()),
            centre,
        });
    }
    // Scatter: regular thinning of the pooled draws.
    let per_panel = (PAIR_MAX_POINTS_TOTAL / (d * (d - 1) / 2).max(1)).clamp(500, 2000);
    let stride = n.div_ceil(per_panel).max(1);
    let mut cells = Vec::new();
    for i in 1..d {
        for j in 0..i {
            let pts: Vec<(f64, f64)> = (0..n)
                .step_by(stride)
                .map(|k| (draws[j][k], draws[i][k]))
                .filter(|p| p.0.is_finite() && p.1.is_finite())
                .collect();
            let ellipse = laplace_cov.and_then(|c| {
                laplace_ellipse(
                    (params[j].centre, params[i].centre),
                    c[j * d + j],
                    0.5 * (c[j * d + i] + c[i * d + j]),
                    c[i * d + i],
                )
            });
            cells.push(PairCell {
                i,
                j,
                pts,
                ellipse,
                rho: correlation(&draws[j], &draws[i]),
            });
        }
    }
    let panel = (900 / d as u32).clamp(140, 450);
    // Label areas + d squares; title and legend strip (about 62 px) above.
    let side = (6.0 * FS) as u32 + panel * d as u32 + 30;
    let height = panel * d as u32 + (3.2 * FS) as u32 + 80;
    let job = PairJob {
        title,
        params: &params,
        cells: &cells,
        has_map: params.iter().any(|p| p.map.is_some()),
        has_laplace: laplace_cov.is_some(),
    };
    draw::write_png_svg(&stem_of(path_png), (side.max(560), height.max(400)), &job).map(|_| ())
}

/// Posterior bands of E'(f) (upper panel) and E''(f) (lower panel) of one set of draws:
/// median line, 50 % and 95 % equal-tailed bands (filled, translucent), and `overlays` as
/// points (`(label, freq_hz, E', E'')`, e.g. the per-line RFM estimates). Moduli in Pa; the
/// axes show MPa against a linear frequency axis, as [`super::modulus_figure`].
pub fn posterior_band_figure(
    path_png: &Path,
    freq_hz: &[f64],
    storage: &[Vec<f64>],
    loss: &[Vec<f64>],
    overlays: &[Overlay],
    title: &str,
) -> Result<(), PlotError> {
    let group = BandGroup {
        label: "posterior".to_string(),
        freq_hz: freq_hz.to_vec(),
        storage: storage.to_vec(),
        loss: loss.to_vec(),
    };
    posterior_bands_figure(path_png, std::slice::from_ref(&group), overlays, title)
}

/// [`posterior_band_figure`] for several groups (e.g. two excitation levels) sharing one
/// figure, each in its own colour. When there are as many overlays as groups (and more than
/// one group), overlay k takes a darker shade of group k's colour; otherwise overlays are
/// black / neutral. Overlays always differ in marker shape.
pub fn posterior_bands_figure(
    path_png: &Path,
    groups: &[BandGroup],
    overlays: &[Overlay],
    title: &str,
) -> Result<(), PlotError> {
    if groups.is_empty() {
        return Err(PlotError::NoCurves {
            figure: title.to_string(),
        });
    }
    let mut bands = Vec::with_capacity(groups.len());
    for (g, group) in groups.iter().enumerate() {
        let nf = group.freq_hz.len();
        if nf == 0 {
            return Err(PlotError::EmptyCurve {
                label: group.label.clone(),
            });
        }
        let mut panels = Vec::with_capacity(2);
        for (part, rows) in [("E'", &group.storage), ("E''", &group.loss)] {
            let label = format!("{} {part}", group.label);
            if rows.is_empty() {
                return Err(invalid(title, format!("'{label}' has no draws")));
            }
            if let Some(r) = rows.iter().find(|r| r.len() != nf) {
                return Err(PlotError::LengthMismatch {
                    label,
                    x_len: nf,
                    y_len: r.len(),
                });
            }
            panels.push(quantile_band(&group.freq_hz, rows));
        }
        let loss = panels.pop().unwrap_or_default();
        let storage = panels.pop().unwrap_or_default();
        bands.push(GroupBands {
            label: group.label.clone(),
            color: rgb(PALETTE[1 + g % (PALETTE.len() - 1)]),
            storage,
            loss,
        });
    }
    let matched = overlays.len() == groups.len() && groups.len() > 1;
    let mut points = Vec::with_capacity(overlays.len());
    for (k, (label, f, s, l)) in overlays.iter().enumerate() {
        if f.is_empty() {
            return Err(PlotError::EmptyCurve {
                label: label.clone(),
            });
        }
        for y in [s, l] {
            if y.len() != f.len() {
                return Err(PlotError::LengthMismatch {
                    label: label.clone(),
                    x_len: f.len(),
                    y_len: y.len(),
                });
            }
        }
        let pick = |y: &[f64]| -> Vec<(f64, f64)> {
            f.iter()
                .zip(y)
                .map(|(&x, &v)| (x, v * 1e-6))
                .filter(|p| p.0.is_finite() && p.1.is_finite())
                .collect()
        };
        let color = if matched {
            let c = bands[k].color;
            RGBColor(
                (f64::from(c.0) * 0.6) as u8,
                (f64::from(c.1) * 0.6) as u8,
                (f64::from(c.2) * 0.6) as u8,
            )
        } else {
            rgb(OVERLAY_COLORS[k % OVERLAY_COLORS.len()])
        };
        points.push(OverlayPoints {
            label: label.clone(),
            storage: pick(s),
            loss: pick(l),
            color,
            shape: Shape::ALL[k % Shape::ALL.len()],
        });
    }
    let mut xs: Vec<f64> = Vec::new();
    let mut ranges = Vec::with_capacity(2);
    for (part, name) in [(0usize, "E' (MPa)"), (1, "E'' (MPa)")] {
        let mut ys: Vec<f64> = Vec::new();
        for b in &bands {
            let band = if part == 0 { &b.storage } else { &b.loss };
            for seg in band {
                for q in seg {
                    xs.push(q.f);
                    ys.extend([q.q[0], q.q[4]]);
                }
            }
        }
        for o in &points {
            let pts = if part == 0 { &o.storage } else { &o.loss };
            xs.extend(pts.iter().map(|p| p.0));
            ys.extend(pts.iter().map(|p| p.1));
        }
        ranges.push(
            draw::padded_range(ys.into_iter(), false).ok_or(PlotError::NoFiniteData {
                panel: name.to_string(),
                log_axis: false,
            })?,
        );
    }
    let x_range = {
        let lo = xs.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = xs.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        if hi > lo {
            let d = 0.015 * (hi - lo);
            (lo - d, hi + d)
        } else {
            draw::padded_range([lo].into_iter(), false).unwrap_or((lo - 1.0, lo + 1.0))
        }
    };
    let job = BandJob {
        title,
        groups: &bands,
        overlays: &points,
        x_range,
        y_ranges: [ranges[0], ranges[1]],
    };
    draw::write_png_svg(&stem_of(path_png), (WIDTH, 860), &job).map(|_| ())
}

// ------------------------------------------------------------------------------------------
// Numerics of the figures
// ------------------------------------------------------------------------------------------

/// Overlay colours when overlays are not matched to groups (black first: measured data).
const OVERLAY_COLORS: [(u8, u8, u8); 4] =
    [(0, 0, 0), (140, 86, 75), (148, 103, 189), (127, 127, 127)];

fn rgb((r, g, b): (u8, u8, u8)) -> RGBColor {
    RGBColor(r, g, b)
}

fn invalid(figure: &str, reason: String) -> PlotError {
    PlotError::InvalidInput {
        figure: figure.to_string(),
        reason,
    }
}

/// `a/b.png` -> `a/b`; a path without the `.png` extension is taken as the stem.
fn stem_of(path_png: &Path) -> PathBuf {
    match path_png.extension() {
        Some(e) if e.eq_ignore_ascii_case("png") => path_png.with_extension(""),
        _ => path_png.to_path_buf(),
    }
}

/// Trace of one chain as line segments (broken at non-finite draws); beyond `max_points`
/// the draws are binned and each bin contributes its minimum and maximum (in draw order),
/// which keeps the envelope and the spikes of the trace.
fn decimate(ys: &[f64], max_points: usize) -> Vec<Vec<(f64, f64)>> {
    let bin = ys.len().div_ceil((max_points / 2).max(1)).max(1);
    let mut out: Vec<Vec<(f64, f64)>> = Vec::new();
    let mut cur: Vec<(f64, f64)> = Vec::new();
    for (b, chunk) in ys.chunks(bin).enumerate() {
        let base = b * bin;
        if bin == 1 {
            let y = chunk[0];
            if y.is_finite() {
                cur.push((base as f64, y));
            } else if !cur.is_empty() {
                out.push(std::mem::take(&mut cur));
            }
            continue;
        }
        let mut lo: Option<(usize, f64)> = None;
        let mut hi: Option<(usize, f64)> = None;
        for (k, &y) in chunk.iter().enumerate() {
            if !y.is_finite() {
                continue;
            }
            if lo.is_none_or(|(_, v)| y < v) {
                lo = Some((k, y));
            }
            if hi.is_none_or(|(_, v)| y > v) {
                hi = Some((k, y));
            }
        }
        match (lo, hi) {
            (Some(a), Some(b2)) => {
                let (first, second) = if a.0 <= b2.0 { (a, b2) } else { (b2, a) };
                cur.push(((base + first.0) as f64, first.1));
                if second.0 != first.0 {
                    cur.push(((base + second.0) as f64, second.1));
                }
            }
            _ => {
                if !cur.is_empty() {
                    out.push(std::mem::take(&mut cur));
                }
            }
        }
    }
    if !cur.is_empty() {
        out.push(cur);
    }
    out
}

/// Gaussian kernel density of `xs` (finite, non-empty) on `grid`, Silverman's bandwidth
/// 0.9 min(sd, IQR/1.34) n^(-1/5); a constant sample gets a narrow kernel (span/50).
fn kde(xs: &[f64], grid: &[f64], span: f64) -> Vec<f64> {
    let n = xs.len() as f64;
    let mean = xs.iter().sum::<f64>() / n;
    let sd = (xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0).max(1.0)).sqrt();
    let mut sorted = xs.to_vec();
    sorted.sort_by(f64::total_cmp);
    let iqr = quantile_sorted(&sorted, 0.75) - quantile_sorted(&sorted, 0.25);
    let s = if iqr > 0.0 { sd.min(iqr / 1.34) } else { sd };
    let mut h = 0.9 * s * n.powf(-0.2);
    if !(h > 0.0) {
        h = if span > 0.0 { span / 50.0 } else { 1.0 };
    }
    let norm = 1.0 / (n * h * (2.0 * std::f64::consts::PI).sqrt());
    grid.iter()
        .map(|&g| {
            xs.iter()
                .map(|&x| {
                    let z = (g - x) / h;
                    if z.abs() > 8.0 {
                        0.0
                    } else {
                        (-0.5 * z * z).exp()
                    }
                })
                .sum::<f64>()
                * norm
        })
        .collect()
}

/// A histogram as density bars (x0, x1, density) over the sample range (2 n^(1/3) bins,
/// 8 to 40); a constant sample gives one bar 1/20 of the axis wide.
fn histogram(xs: &[f64], axis: (f64, f64)) -> Vec<(f64, f64, f64)> {
    let lo = xs.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = xs.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let n = xs.len() as f64;
    if !(hi > lo) {
        let w = (axis.1 - axis.0) / 20.0;
        return vec![(lo - 0.5 * w, lo + 0.5 * w, 1.0 / w)];
    }
    let bins = ((2.0 * n.cbrt()).round() as usize).clamp(8, 40);
    let w = (hi - lo) / bins as f64;
    let mut counts = vec![0usize; bins];
    for &x in xs {
        let k = (((x - lo) / w) as usize).min(bins - 1);
        counts[k] += 1;
    }
    counts
        .iter()
        .enumerate()
        .map(|(k, &c)| {
            let x0 = lo + w * k as f64;
            (x0, x0 + w, c as f64 / (n * w))
        })
        .collect()
}

/// Pearson correlation over the pairs where both values are finite; `None` when undefined.
fn correlation(x: &[f64], y: &[f64]) -> Option<f64> {
    let pairs: Vec<(f64, f64)> = x
        .iter()
        .zip(y)
        .map(|(&a, &b)| (a, b))
        .filter(|p| p.0.is_finite() && p.1.is_finite())
        .collect();
    if pairs.len() < 2 {
        return None;
    }
    let n = pairs.len() as f64;
    let (mx, my) = pairs
        .iter()
        .fold((0.0, 0.0), |(a, b), p| (a + p.0 / n, b + p.1 / n));
    let (mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0);
    for &(a, b) in &pairs {
        sxx += (a - mx) * (a - mx);
        syy += (b - my) * (b - my);
        sxy += (a - mx) * (b - my);
    }
    let r = sxy / (sxx * syy).sqrt();
    r.is_finite().then_some(r)
}

/// The 95 % ellipse {x : (x-c)' S^-1 (x-c) = 5.991} of S = [[sxx, sxy], [sxy, syy]] as a
/// closed polygon; `None` unless S is finite and positive definite.
fn laplace_ellipse(c: (f64, f64), sxx: f64, sxy: f64, syy: f64) -> Option<Vec<(f64, f64)>> {
    if !(sxx > 0.0 && syy > 0.0 && sxy.is_finite() && sxx.is_finite() && syy.is_finite()) {
        return None;
    }
    let l11 = sxx.sqrt();
    let l21 = sxy / l11;
    let r = syy - l21 * l21;
    if !(r > 0.0) || !c.0.is_finite() || !c.1.is_finite() {
        return None;
    }
    let l22 = r.sqrt();
    let k = CHI2_2_95.sqrt();
    Some(
        (0..=120)
            .map(|t| {
                let a = 2.0 * std::f64::consts::PI * f64::from(t) / 120.0;
                let (u, v) = (a.cos(), a.sin());
                (c.0 + k * l11 * u, c.1 + k * (l21 * u + l22 * v))
            })
            .collect(),
    )
}

/// 2.5, 25, 50, 75 and 97.5 % quantiles (MPa) of the finite draws at each frequency line.
#[derive(Clone, Copy, Debug)]
struct LineQuantiles {
    f: f64,
    q: [f64; 5],
}

/// Quantiles per line, lines sorted by frequency, split into runs broken where a line has no
/// finite draw (or a non-finite frequency).
fn quantile_band(freq: &[f64], rows: &[Vec<f64>]) -> Vec<Vec<LineQuantiles>> {
    let mut order: Vec<usize> = (0..freq.len()).collect();
    order.sort_by(|&a, &b| freq[a].total_cmp(&freq[b]));
    let mut out: Vec<Vec<LineQuantiles>> = Vec::new();
    let mut cur: Vec<LineQuantiles> = Vec::new();
    for k in order {
        let mut v: Vec<f64> = rows
            .iter()
            .map(|r| r[k] * 1e-6)
            .filter(|x| x.is_finite())
            .collect();
        if v.is_empty() || !freq[k].is_finite() {
            if !cur.is_empty() {
                out.push(std::mem::take(&mut cur));
            }
            continue;
        }
        v.sort_by(f64::total_cmp);
        let q = [0.025, 0.25, 0.5, 0.75, 0.975].map(|p| quantile_sorted(&v, p));
        cur.push(LineQuantiles { f: freq[k], q });
    }
    if !cur.is_empty() {
        out.push(cur);
    }
    out
}

/// Tick labels that stay distinct on a narrow range far from zero (a posterior of E0 between
/// 5.50e6 and 5.56e6): as many digits as the tick spacing needs, trailing zeros trimmed.
fn range_fmt(lo: f64, hi: f64) -> impl Fn(&f64) -> String {
    let span = (hi - lo).abs();
    let mag = lo.abs().max(hi.abs());
    move |v: &f64| {
        let v = *v;
        if !(span > 0.0 && mag > 0.0 && v.is_finite()) {
            return draw::fmt_tick(&v);
        }
        if v.abs() < 1e-9 * span {
            return "0".to_string();
        }
        let step_exp = (span / 10.0).log10().floor() as i32;
        let trim = |s: &str| -> String {
            if s.contains('.') {
                s.trim_end_matches('0').trim_end_matches('.').to_string()
            } else {
                s.to_string()
            }
        };
        if (1e-3..1e5).contains(&mag) {
            let dec = (-step_exp).clamp(0, 9) as usize;
            trim(&format!("{v:.dec$}"))
        } else {
            let digits = ((v.abs().log10().floor() as i32) - step_exp).clamp(0, 9) as usize;
            let s = format!("{v:.digits$e}");
            match s.split_once('e') {
                Some((m, e)) => format!("{}e{e}", trim(m)),
                None => s,
            }
        }
    }
}

// ------------------------------------------------------------------------------------------
// Legend strip (below the title; never covers data)
// ------------------------------------------------------------------------------------------

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Shape {
    Circle,
    Triangle,
    Square,
    Diamond,
}

impl Shape {
    const ALL: [Shape; 4] = [
        Shape::Circle,
        Shape::Triangle,
        Shape::Square,
        Shape::Diamond,
    ];
}

/// Draws markers of `shape` and radius `r` px at `pts` (data coordinates of `chart`).
fn draw_markers<DB: DrawingBackend>(
    chart: &mut Chart<'_, DB>,
    pts: &[(f64, f64)],
    shape: Shape,
    r: i32,
    color: RGBColor,
) -> Result<(), DrawError> {
    let style = color.filled();
    let at = |q: (f64, f64)| EmptyElement::at(q);
    match shape {
        Shape::Circle => chart
            .draw_series(pts.iter().map(|&q| at(q) + Circle::new((0, 0), r, style)))
            .map(|_| ()),
        Shape::Triangle => chart
            .draw_series(
                pts.iter()
                    .map(|&q| at(q) + TriangleMarker::new((0, 0), r + 1, style)),
            )
            .map(|_| ()),
        Shape::Square => chart
            .draw_series(
                pts.iter()
                    .map(|&q| at(q) + Rectangle::new([(-r, -r), (r, r)], style)),
            )
            .map(|_| ()),
        Shape::Diamond => {
            let d = r + 1;
            chart
                .draw_series(
                    pts.iter().map(|&q| {
                        at(q) + Polygon::new(vec![(0, -d), (d, 0), (0, d), (-d, 0)], style)
                    }),
                )
                .map(|_| ())
        }
    }
    .map_err(err)
}

/// One marker at pixel `at` of `area` (legend swatches).
fn area_marker<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    at: (i32, i32),
    shape: Shape,
    r: i32,
    color: RGBColor,
) -> Result<(), DrawError> {
    let style = color.filled();
    let e = EmptyElement::at(at);
    match shape {
        Shape::Circle => area.draw(&(e + Circle::new((0, 0), r, style))),
        Shape::Triangle => area.draw(&(e + TriangleMarker::new((0, 0), r + 1, style))),
        Shape::Square => area.draw(&(e + Rectangle::new([(-r, -r), (r, r)], style))),
        Shape::Diamond => {
            let d = r + 1;
            area.draw(&(e + Polygon::new(vec![(0, -d), (d, 0), (0, d), (-d, 0)], style)))
        }
    }
    .map_err(err)
}

enum Swatch {
    Line(RGBColor, u32),
    Marker(RGBColor, Shape),
    Cross(RGBColor),
    Band(RGBColor),
    Bar(RGBColor),
}

struct LegendEntry {
    swatch: Swatch,
    label: String,
}

/// Draws the entries in centred rows across the top of `area` and returns the rest of it.
fn legend_strip<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    entries: &[LegendEntry],
) -> Result<DrawingArea<DB, Shift>, DrawError> {
    if entries.is_empty() {
        return Ok(area.clone());
    }
    let font: TextStyle = ("sans-serif", FS).into_font().into();
    let (w, _) = area.dim_in_pixel();
    let (sw, gap, sep) = (26i32, 6i32, 22i32);
    let mut widths = Vec::with_capacity(entries.len());
    for e in entries {
        let (tw, _) = area.estimate_text_size(&e.label, &font).map_err(err)?;
        widths.push(sw + gap + tw as i32);
    }
    let avail = w as i32 - 40;
    let mut rows: Vec<Vec<usize>> = vec![Vec::new()];
    let mut used = 0;
    for (k, &ew) in widths.iter().enumerate() {
        let last = rows.last_mut().expect("one row");
        if !last.is_empty() && used + sep + ew > avail {
            rows.push(vec![k]);
            used = ew;
        } else {
            used += if last.is_empty() { ew } else { sep + ew };
            last.push(k);
        }
    }
    let row_h = (1.6 * FS) as i32;
    let strip_h = row_h * rows.len() as i32 + (0.5 * FS) as i32;
    let (strip, body) = area.split_vertically(strip_h);
    let font = font.pos(Pos::new(HPos::Left, VPos::Center));
    for (r, row) in rows.iter().enumerate() {
        let total: i32 = row.iter().map(|&k| widths[k]).sum::<i32>() + sep * (row.len() as i32 - 1);
        let mut x = (w as i32 - total) / 2;
        let y = row_h * r as i32 + row_h / 2;
        for &k in row {
            let e = &entries[k];
            match e.swatch {
                Swatch::Line(c, wd) => strip
                    .draw(&PathElement::new(
                        vec![(x, y), (x + sw, y)],
                        c.stroke_width(wd),
                    ))
                    .map_err(err)?,
                Swatch::Marker(c, s) => area_marker(&strip, (x + sw / 2, y), s, 4, c)?,
                Swatch::Cross(c) => strip
                    .draw(&Cross::new((x + sw / 2, y), 6, c.stroke_width(2)))
                    .map_err(err)?,
                Swatch::Band(c) => {
                    strip
                        .draw(&Rectangle::new(
                            [(x, y - 8), (x + sw, y + 8)],
                            c.mix(0.18).filled(),
                        ))
                        .map_err(err)?;
                    strip
                        .draw(&Rectangle::new(
                            [(x, y - 4), (x + sw, y + 4)],
                            c.mix(0.35).filled(),
                        ))
                        .map_err(err)?;
                    strip
                        .draw(&PathElement::new(
                            vec![(x, y), (x + sw, y)],
                            c.stroke_width(2),
                        ))
                        .map_err(err)?;
                }
                Swatch::Bar(c) => {
                    strip
                        .draw(&Rectangle::new(
                            [(x + 3, y - 7), (x + sw - 3, y + 7)],
                            c.mix(0.35).filled(),
                        ))
                        .map_err(err)?;
                    strip
                        .draw(&Rectangle::new(
                            [(x + 3, y - 7), (x + sw - 3, y + 7)],
                            c.stroke_width(1),
                        ))
                        .map_err(err)?;
                }
            }
            strip
                .draw_text(&e.label, &font, (x + sw + gap, y))
                .map_err(err)?;
            x += widths[k] + sep;
        }
    }
    Ok(body)
}

type Chart<'a, DB> = ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// Light grid and tick labels in the style of the other figures.
#[allow(clippy::too_many_arguments)]
fn mesh<DB: DrawingBackend>(
    chart: &mut Chart<'_, DB>,
    x_fmt: &dyn Fn(&f64) -> String,
    y_fmt: &dyn Fn(&f64) -> String,
    x_desc: &str,
    y_desc: &str,
    n_ticks: (usize, usize),
    font: f64,
) -> Result<(), DrawError> {
    let mut m = chart.configure_mesh();
    m.label_style(("sans-serif", font))
        .axis_desc_style(("sans-serif", 1.1 * FS))
        .x_label_formatter(x_fmt)
        .y_label_formatter(y_fmt)
        .x_labels(n_ticks.0)
        .y_labels(n_ticks.1)
        .light_line_style(RGBColor(0, 0, 0).mix(0.04))
        .bold_line_style(RGBColor(0, 0, 0).mix(0.12));
    if !x_desc.is_empty() {
        m.x_desc(x_desc);
    }
    if !y_desc.is_empty() {
        m.y_desc(y_desc);
    }
    m.draw().map_err(err)
}

fn blank(_: &f64) -> String {
    String::new()
}

// ------------------------------------------------------------------------------------------
// Trace figure
// ------------------------------------------------------------------------------------------

struct TraceRow {
    name: String,
    y_range: (f64, f64),
    /// `[chain]` -> segments of (draw index, value).
    traces: Vec<Vec<Vec<(f64, f64)>>>,
    /// `[chain]` -> (density, value).
    densities: Vec<Vec<(f64, f64)>>,
    d_max: f64,
}

struct TraceJob<'a> {
    title: &'a str,
    rows: &'a [TraceRow],
    n_chains: usize,
    n_max: usize,
}

fn chain_color(c: usize) -> RGBColor {
    rgb(PALETTE[1 + c % (PALETTE.len() - 1)])
}

impl Render for TraceJob<'_> {
    fn render<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), DrawError> {
        root.fill(&WHITE).map_err(err)?;
        let area = root
            .titled(self.title, ("sans-serif", 1.4 * FS))
            .map_err(err)?;
        let entries: Vec<LegendEntry> = (0..self.n_chains)
            .map(|c| LegendEntry {
                swatch: Swatch::Line(chain_color(c), 2),
                label: format!("chain {}", c + 1),
            })
            .collect();
        let body = legend_strip(&area, &entries)?;
        let (w, h) = body.dim_in_pixel();
        let x_area = (3.0 * FS) as i32;
        let d = self.rows.len() as i32;
        let row_h = (h as i32 - x_area) / d;
        let ys: Vec<i32> = (1..d).map(|k| k * row_h).collect();
        let split_x = (0.7 * f64::from(w)) as i32;
        let cells = body.split_by_breakpoints([split_x], ys);
        let m = (0.5 * FS) as i32;
        for (r, row) in self.rows.iter().enumerate() {
            let last = r + 1 == self.rows.len();
            let (y0, y1) = row.y_range;
            let yf = range_fmt(y0, y1);
            // Traces.
            let mut chart = ChartBuilder::on(&cells[2 * r])
                .margin_top(m)
                .margin_bottom(m)
                .margin_left(m)
                .margin_right(m)
                .x_label_area_size(if last { x_area } else { 0 })
                .y_label_area_size((6.0 * FS) as i32)
                .build_cartesian_2d(0.0..(self.n_max - 1) as f64, y0..y1)
                .map_err(err)?;
            mesh(
                &mut chart,
                &draw::fmt_tick,
                &yf,
                if last { "Draw" } else { "" },
                &row.name,
                (8, 4),
                FS,
            )?;
            for (c, segs) in row.traces.iter().enumerate() {
                let color = chain_color(c).mix(0.75);
                chart
                    .draw_series(
                        segs.iter()
                            .map(move |s| PathElement::new(s.clone(), color.stroke_width(1))),
                    )
                    .map_err(err)?;
            }
            // Densities, sideways on the same value axis.
            let mut chart = ChartBuilder::on(&cells[2 * r + 1])
                .margin_top(m)
                .margin_bottom(m)
                .margin_left(m)
                .margin_right(2 * m)
                .x_label_area_size(if last { x_area } else { 0 })
                .y_label_area_size(0)
                .build_cartesian_2d(0.0..1.08 * row.d_max, y0..y1)
                .map_err(err)?;
            mesh(
                &mut chart,
                &blank,
                &blank,
                if last { "Density" } else { "" },
                "",
                (4, 4),
                FS,
            )?;
            for (c, pts) in row.densities.iter().enumerate() {
                let color = chain_color(c);
                chart
                    .draw_series(std::iter::once(PathElement::new(
                        pts.clone(),
                        color.stroke_width(2),
                    )))
                    .map_err(err)?;
            }
        }
        Ok(())
    }
}

// ------------------------------------------------------------------------------------------
// Pair (corner) figure
// ------------------------------------------------------------------------------------------

struct PairParam {
    name: String,
    range: (f64, f64),
    /// (x0, x1, density) bars.
    hist: Vec<(f64, f64, f64)>,
    /// Laplace marginal density (x, pdf).
    laplace_pdf: Option<Vec<(f64, f64)>>,
    map: Option<f64>,
    /// Centre of the Laplace ellipses: the MAP, else the posterior mean.
    centre: f64,
}

struct PairCell {
    i: usize,
    j: usize,
    pts: Vec<(f64, f64)>,
    ellipse: Option<Vec<(f64, f64)>>,
    rho: Option<f64>,
}

struct PairJob<'a> {
    title: &'a str,
    params: &'a [PairParam],
    cells: &'a [PairCell],
    has_map: bool,
    has_laplace: bool,
}

const DRAW_COLOR: RGBColor = RGBColor(31, 119, 180);
const LAPLACE_COLOR: RGBColor = RGBColor(255, 127, 14);
const MAP_COLOR: RGBColor = RGBColor(214, 39, 40);

impl Render for PairJob<'_> {
    fn render<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), DrawError> {
        root.fill(&WHITE).map_err(err)?;
        let area = root
            .titled(self.title, ("sans-serif", 1.4 * FS))
            .map_err(err)?;
        let mut entries = vec![LegendEntry {
            swatch: Swatch::Bar(DRAW_COLOR),
            label: "posterior draws".to_string(),
        }];
        if self.has_map {
            entries.push(LegendEntry {
                swatch: Swatch::Cross(MAP_COLOR),
                label: "MAP".to_string(),
            });
        }
        if self.has_laplace {
            entries.push(LegendEntry {
                swatch: Swatch::Line(LAPLACE_COLOR, 2),
                label: "Laplace (95 % ellipse, marginal)".to_string(),
            });
        }
        let body = legend_strip(&area, &entries)?;
        let (w, h) = body.dim_in_pixel();
        let d = self.params.len() as i32;
        let y_area = (6.0 * FS) as i32;
        let x_area = (3.2 * FS) as i32;
        let p = ((w as i32 - y_area - 16) / d)
            .min((h as i32 - x_area - 4) / d)
            .max(20);
        let m = 3;
        // Exact p x p plotting squares: the spare width / height goes to an extra (unused)
        // column and row at the right and bottom.
        let xs: Vec<i32> = (1..=d)
            .map(|k| y_area + k * p + if k == d { 12 - m } else { 0 })
            .collect();
        let ys: Vec<i32> = (1..=d)
            .map(|k| k * p + if k == d { x_area } else { 0 })
            .collect();
        let cells = body.split_by_breakpoints(xs, ys);
        let small = p < 220;
        let ticks = if small {
            3
        } else if p < 320 {
            4
        } else {
            5
        };
        let tick_font = if small { 0.85 * FS } else { FS };
        let idx = |i: usize, j: usize| i * (d as usize + 1) + j;
        let last = d as usize - 1;
        let chart_on = |i: usize, j: usize, xr: (f64, f64), yr: (f64, f64)| {
            ChartBuilder::on(&cells[idx(i, j)])
                .margin(m)
                .margin_right(if j == last { 12 } else { m })
                .x_label_area_size(if i == last { x_area } else { 0 })
                .y_label_area_size(if j == 0 { y_area } else { 0 })
                .build_cartesian_2d(xr.0..xr.1, yr.0..yr.1)
                .map_err(err)
        };
        // Diagonal.
        for (i, prm) in self.params.iter().enumerate() {
            let h_max = prm
                .hist
                .iter()
                .map(|b| b.2)
                .chain(prm.laplace_pdf.iter().flatten().map(|q| q.1))
                .fold(0.0f64, f64::max);
            let h_max = if h_max > 0.0 { h_max } else { 1.0 };
            let mut chart = chart_on(i, i, prm.range, (0.0, 1.1 * h_max))?;
            let xf = range_fmt(prm.range.0, prm.range.1);
            let x_desc = if i == last { prm.name.as_str() } else { "" };
            let y_desc = if self.params.len() == 1 {
                "Density"
            } else {
                ""
            };
            mesh(
                &mut chart,
                &xf,
                &blank,
                x_desc,
                y_desc,
                (ticks, ticks),
                tick_font,
            )?;
            chart
                .draw_series(prm.hist.iter().map(|&(a, b, y)| {
                    Rectangle::new([(a, 0.0), (b, y)], DRAW_COLOR.mix(0.35).filled())
                }))
                .map_err(err)?;
            chart
                .draw_series(std::iter::once(PathElement::new(
                    step_outline(&prm.hist),
                    DRAW_COLOR.stroke_width(1),
                )))
                .map_err(err)?;
            if let Some(pdf) = &prm.laplace_pdf {
                chart
                    .draw_series(std::iter::once(PathElement::new(
                        pdf.clone(),
                        LAPLACE_COLOR.stroke_width(2),
                    )))
                    .map_err(err)?;
            }
            if let Some(mx) = prm.map {
                chart
                    .draw_series(std::iter::once(PathElement::new(
                        vec![(mx, 0.0), (mx, 1.1 * h_max)],
                        MAP_COLOR.stroke_width(2),
                    )))
                    .map_err(err)?;
            }
        }
        // Below the diagonal.
        let dot = if self.cells.iter().map(|c| c.pts.len()).max().unwrap_or(0) > 800 {
            1
        } else {
            2
        };
        for cell in self.cells {
            let (px, py) = (&self.params[cell.j], &self.params[cell.i]);
            let mut chart = chart_on(cell.i, cell.j, px.range, py.range)?;
            let xf = range_fmt(px.range.0, px.range.1);
            let yf = range_fmt(py.range.0, py.range.1);
            mesh(
                &mut chart,
                &xf,
                &yf,
                if cell.i == last { px.name.as_str() } else { "" },
                if cell.j == 0 { py.name.as_str() } else { "" },
                (ticks, ticks),
                tick_font,
            )?;
            chart
                .draw_series(
                    cell.pts
                        .iter()
                        .map(|&q| Circle::new(q, dot, DRAW_COLOR.mix(0.35).filled())),
                )
                .map_err(err)?;
            if let Some(e) = &cell.ellipse {
                chart
                    .draw_series(std::iter::once(PathElement::new(
                        e.clone(),
                        LAPLACE_COLOR.stroke_width(2),
                    )))
                    .map_err(err)?;
            }
            if let (Some(mx), Some(my)) = (px.map, py.map) {
                chart
                    .draw_series(std::iter::once(Cross::new(
                        (mx, my),
                        6,
                        MAP_COLOR.stroke_width(2),
                    )))
                    .map_err(err)?;
            }
        }
        // Above the diagonal: the sample correlation, centred by its measured size (the
        // text anchor is not honoured by every backend).
        let font: TextStyle = ("sans-serif", 1.2 * FS)
            .into_font()
            .color(&RGBColor(80, 80, 80));
        for cell in self.cells {
            let a = &cells[idx(cell.j, cell.i)];
            let (aw, ah) = a.dim_in_pixel();
            let text = match cell.rho {
                Some(r) => format!("\u{3c1} = {r:.2}"),
                None => "\u{3c1} = n/a".to_string(),
            };
            let (tw, th) = a.estimate_text_size(&text, &font).map_err(err)?;
            let right = if cell.i == last { 12 } else { m };
            let cx = (aw as i32 - right + m) / 2;
            a.draw_text(
                &text,
                &font,
                (cx - tw as i32 / 2, (ah as i32 - th as i32) / 2),
            )
            .map_err(err)?;
        }
        Ok(())
    }
}

/// The outline of density bars as one step path.
fn step_outline(bars: &[(f64, f64, f64)]) -> Vec<(f64, f64)> {
    let mut out = Vec::with_capacity(2 * bars.len() + 2);
    if let Some(first) = bars.first() {
        out.push((first.0, 0.0));
    }
    for &(a, b, y) in bars {
        out.push((a, y));
        out.push((b, y));
    }
    if let Some(last) = bars.last() {
        out.push((last.1, 0.0));
    }
    out
}

// ------------------------------------------------------------------------------------------
// Band figure
// ------------------------------------------------------------------------------------------

struct GroupBands {
    label: String,
    color: RGBColor,
    storage: Vec<Vec<LineQuantiles>>,
    loss: Vec<Vec<LineQuantiles>>,
}

struct OverlayPoints {
    label: String,
    storage: Vec<(f64, f64)>,
    loss: Vec<(f64, f64)>,
    color: RGBColor,
    shape: Shape,
}

struct BandJob<'a> {
    title: &'a str,
    groups: &'a [GroupBands],
    overlays: &'a [OverlayPoints],
    x_range: (f64, f64),
    y_ranges: [(f64, f64); 2],
}

/// The polygon between quantiles `lo` and `hi` of one run of lines (a single line becomes a
/// narrow vertical bar so that it stays visible).
fn band_polygon(seg: &[LineQuantiles], lo: usize, hi: usize, x_span: f64) -> Vec<(f64, f64)> {
    if seg.len() == 1 {
        let (f, q) = (seg[0].f, seg[0].q);
        let dx = 0.004 * x_span;
        return vec![
            (f - dx, q[lo]),
            (f + dx, q[lo]),
            (f + dx, q[hi]),
            (f - dx, q[hi]),
        ];
    }
    seg.iter()
        .map(|l| (l.f, l.q[hi]))
        .chain(seg.iter().rev().map(|l| (l.f, l.q[lo])))
        .collect()
}

impl Render for BandJob<'_> {
    fn render<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), DrawError> {
        root.fill(&WHITE).map_err(err)?;
        let area = root
            .titled(self.title, ("sans-serif", 1.4 * FS))
            .map_err(err)?;
        let mut entries: Vec<LegendEntry> = self
            .groups
            .iter()
            .map(|g| LegendEntry {
                swatch: Swatch::Band(g.color),
                label: format!("{}: median, 50 % and 95 % bands", g.label),
            })
            .collect();
        entries.extend(self.overlays.iter().map(|o| LegendEntry {
            swatch: Swatch::Marker(o.color, o.shape),
            label: o.label.clone(),
        }));
        let body = legend_strip(&area, &entries)?;
        let panels = body.split_evenly((2, 1));
        let (x0, x1) = self.x_range;
        let x_span = x1 - x0;
        let n_pts: usize = self.overlays.iter().map(|o| o.storage.len()).sum();
        let r = if n_pts > 150 { 2 } else { 3 };
        for (part, a) in panels.iter().enumerate() {
            let (y0, y1) = self.y_ranges[part];
            let last = part == 1;
            let mut chart = ChartBuilder::on(a)
                .margin((0.8 * FS) as i32)
                .x_label_area_size((2.8 * FS) as i32)
                .y_label_area_size((5.0 * FS) as i32)
                .build_cartesian_2d(x0..x1, y0..y1)
                .map_err(err)?;
            let yf = range_fmt(y0, y1);
            mesh(
                &mut chart,
                &draw::fmt_tick,
                &yf,
                if last { "Frequency (Hz)" } else { "" },
                if part == 0 { "E' (MPa)" } else { "E'' (MPa)" },
                (10, 6),
                FS,
            )?;
            let band_of = |g: &'_ GroupBands| -> Vec<Vec<LineQuantiles>> {
                if part == 0 {
                    g.storage.clone()
                } else {
                    g.loss.clone()
                }
            };
            for (lo, hi, alpha) in [(0usize, 4usize, 0.16), (1, 3, 0.32)] {
                for g in self.groups {
                    let color = g.color.mix(alpha);
                    chart
                        .draw_series(band_of(g).iter().map(|seg| {
                            Polygon::new(band_polygon(seg, lo, hi, x_span), color.filled())
                        }))
                        .map_err(err)?;
                }
            }
            for g in self.groups {
                let color = g.color;
                chart
                    .draw_series(band_of(g).iter().map(|seg| {
                        PathElement::new(
                            seg.iter().map(|l| (l.f, l.q[2])).collect::<Vec<_>>(),
                            color.stroke_width(2),
                        )
                    }))
                    .map_err(err)?;
            }
            for o in self.overlays {
                let pts = if part == 0 { &o.storage } else { &o.loss };
                draw_markers(&mut chart, pts, o.shape, r, o.color)?;
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn narrow_ranges_keep_ticks_distinct() {
        let f = range_fmt(5.50e6, 5.56e6);
        assert_eq!(f(&5.52e6), "5.52e6");
        assert_ne!(f(&5.52e6), f(&5.53e6));
        let f = range_fmt(0.2, 0.3);
        assert_eq!(f(&0.25), "0.25");
        assert_eq!(f(&0.30000000000000004), "0.3");
        let f = range_fmt(-1.0, 1.0);
        assert_eq!(f(&1e-17), "0");
    }

    #[test]
    fn quantiles_and_ellipse() {
        let s = [1.0, 2.0, 3.0, 4.0, 5.0];
        assert_eq!(quantile_sorted(&s, 0.5), 3.0);
        assert_eq!(quantile_sorted(&s, 0.25), 2.0);
        assert_eq!(quantile_sorted(&[7.0], 0.9), 7.0);
        // Unit covariance: the ellipse is a circle of radius sqrt(5.991).
        let e = laplace_ellipse((1.0, 2.0), 1.0, 0.0, 1.0).unwrap();
        for (x, y) in e {
            let r2 = (x - 1.0).powi(2) + (y - 2.0).powi(2);
            assert!((r2 - CHI2_2_95).abs() < 1e-9);
        }
        // Correlated: every point satisfies (x-c)' S^-1 (x-c) = 5.991.
        let (a, b, c) = (4.0, 1.5, 1.0);
        let det = a * c - b * b;
        for (x, y) in laplace_ellipse((0.0, 0.0), a, b, c).unwrap() {
            let q = (c * x * x - 2.0 * b * x * y + a * y * y) / det;
            assert!((q - CHI2_2_95).abs() < 1e-9);
        }
        assert!(laplace_ellipse((0.0, 0.0), 1.0, 2.0, 1.0).is_none());
        assert!(laplace_ellipse((0.0, 0.0), -1.0, 0.0, 1.0).is_none());
    }

    #[test]
    fn decimation_keeps_extremes_and_breaks() {
        let ys: Vec<f64> = (0..10_000)
            .map(|k| if k == 5_000 { 100.0 } else { (k % 7) as f64 })
            .collect();
        let segs = decimate(&ys, 1000);
        let pts: Vec<(f64, f64)> = segs.into_iter().flatten().collect();
        assert!(pts.len() <= 1000);
        assert!(pts.contains(&(5000.0, 100.0)));
        let segs = decimate(&[1.0, f64::NAN, 2.0, 3.0], 100);
        assert_eq!(segs.len(), 2);
    }

    #[test]
    fn kde_integrates_to_one() {
        let xs: Vec<f64> = (0..500).map(|k| ((k * 37) % 101) as f64 / 100.0).collect();
        let grid: Vec<f64> = (0..=400).map(|k| -1.0 + 3.0 * k as f64 / 400.0).collect();
        let d = kde(&xs, &grid, 1.0);
        let integral: f64 = d.iter().sum::<f64>() * 3.0 / 400.0;
        assert!((integral - 1.0).abs() < 1e-3, "{integral}");
        let h = histogram(&xs, (0.0, 1.0));
        let mass: f64 = h.iter().map(|b| (b.1 - b.0) * b.2).sum();
        assert!((mass - 1.0).abs() < 1e-12);
    }

    #[test]
    fn stem_strips_png_only() {
        assert_eq!(stem_of(Path::new("a/b.png")), PathBuf::from("a/b"));
        assert_eq!(stem_of(Path::new("a/b.PNG")), PathBuf::from("a/b"));
        assert_eq!(stem_of(Path::new("a/b")), PathBuf::from("a/b"));
        assert_eq!(
            stem_of(Path::new("a/level1.v2")),
            PathBuf::from("a/level1.v2")
        );
    }
}
