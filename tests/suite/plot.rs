//! Plot module: FRF, line and modulus figures as PNG and SVG; robustness to bad data.
//! Figures are kept in `<target>/tmp/plot_tests/` for inspection.

use std::path::{Path, PathBuf};

use rfmlab::common::{C64, J};
use rfmlab::plot::{
    frf_figure, line_figure, modulus_figure, Curve, CurveStyle, FrfCurve, PlotError,
};

fn out_dir(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join("plot_tests")
        .join(name);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Accelerance of two modes, -w^2 sum_r A_r / (w_r^2 - w^2 + j eta_r w_r^2).
fn accelerance(f_hz: f64, shift: f64) -> C64 {
    let w = 2.0 * std::f64::consts::PI * f_hz;
    let modes = [(22.26 * shift, 0.2044, 2.0), (394.0 * shift, 0.05, -1.0)];
    modes
        .iter()
        .map(|&(fr, eta, a)| {
            let wr = 2.0 * std::f64::consts::PI * fr;
            -w * w * a / (wr * wr - w * w + J * eta * wr * wr)
        })
        .sum()
}

fn png_size(bytes: &[u8]) -> (u32, u32) {
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "PNG signature");
    assert_eq!(&bytes[12..16], b"IHDR");
    let be = |s: &[u8]| u32::from_be_bytes([s[0], s[1], s[2], s[3]]);
    (be(&bytes[16..20]), be(&bytes[20..24]))
}

fn check_files(files: &rfmlab::plot::FigureFiles, title: &str, size: (u32, u32), labels: &[&str]) {
    let png = std::fs::read(&files.png).unwrap();
    assert_eq!(png_size(&png), size);
    assert!(png.len() > 20_000, "PNG only {} bytes", png.len());
    let svg = std::fs::read_to_string(&files.svg).unwrap();
    assert!(svg.starts_with("<svg"), "SVG header");
    assert!(svg.contains(title), "SVG holds the title");
    for l in labels {
        assert!(svg.contains(l), "SVG holds the legend label '{l}'");
    }
    // No temporary files left behind.
    let dir = files.png.parent().unwrap();
    for e in std::fs::read_dir(dir).unwrap() {
        let n = e.unwrap().file_name().to_string_lossy().into_owned();
        assert!(!n.contains(".tmp-"), "leftover {n}");
    }
}

#[test]
fn frf_figure_writes_png_and_svg() {
    let dir = out_dir("frf");
    let freq: Vec<f64> = (1..=500).map(f64::from).collect();
    // "Measured": model with a deterministic ripple, one NaN and one inf line.
    let mut measured: Vec<C64> = freq
        .iter()
        .enumerate()
        .map(|(k, &f)| accelerance(f, 1.0) * (1.0 + 0.03 * ((k * 7919) % 13) as f64 / 13.0))
        .collect();
    measured[100] = C64::new(f64::NAN, 0.0);
    measured[200] = C64::new(f64::INFINITY, 1.0);
    let fine: Vec<f64> = (0..=4990).map(|k| 1.0 + 0.1 * f64::from(k)).collect();
    let initial: Vec<C64> = fine.iter().map(|&f| accelerance(f, 1.08)).collect();
    let updated: Vec<C64> = fine.iter().map(|&f| accelerance(f, 1.0)).collect();
    let curves = [
        FrfCurve::new("measured", measured, CurveStyle::Points),
        FrfCurve::on_grid("initial (Model 1)", fine.clone(), initial, CurveStyle::Line),
        FrfCurve::on_grid("updated (Model 4)", fine, updated, CurveStyle::Line),
    ];
    let title = "FRF H22 level 1";
    let files = frf_figure(dir.join("frf_h22"), title, &freq, &curves).unwrap();
    assert_eq!(files.png, dir.join("frf_h22.png"));
    check_files(
        &files,
        title,
        (1000, 800),
        &["measured", "updated (Model 4)"],
    );
    // Deterministic: the same figure twice gives the same bytes.
    let again = frf_figure(dir.join("frf_h22_again"), title, &freq, &curves).unwrap();
    assert_eq!(
        std::fs::read(&files.png).unwrap(),
        std::fs::read(&again.png).unwrap()
    );
    assert_eq!(
        std::fs::read(&files.svg).unwrap(),
        std::fs::read(&again.svg).unwrap()
    );
}

#[test]
fn line_figure_linear_and_log() {
    let dir = out_dir("line");
    let f: Vec<f64> = (1..=400).map(f64::from).collect();
    let scc: Vec<f64> = f
        .iter()
        .map(|x| 1.0 - 0.3 * (x / 60.0).sin().powi(2))
        .collect();
    let acc: Vec<f64> = f
        .iter()
        .map(|x| 0.95 - 0.2 * (x / 90.0).cos().powi(2))
        .collect();
    let files = line_figure(
        dir.join("scc_acc"),
        "SCC and ACC",
        "Frequency (Hz)",
        "Correlation (-)",
        &[
            Curve::line("SCC", f.clone(), scc),
            Curve::line("ACC", f, acc),
        ],
        false,
    )
    .unwrap();
    check_files(&files, "SCC and ACC", (1000, 560), &["SCC", "ACC"]);

    let it: Vec<f64> = (0..12).map(f64::from).collect();
    let change: Vec<f64> = it.iter().map(|k| 10f64.powf(-0.8 * k)).collect();
    let mut with_zero = change.clone();
    with_zero[11] = 0.0; // skipped on a log axis
    let files = line_figure(
        dir.join("convergence"),
        "Convergence history",
        "Iteration",
        "Relative parameter change",
        &[
            Curve::new("Model 4", it.clone(), with_zero, CurveStyle::Line),
            Curve::points("Model 1", it, change.iter().map(|c| c * 3.0).collect()),
        ],
        true,
    )
    .unwrap();
    check_files(
        &files,
        "Convergence history",
        (1000, 560),
        &["Model 4", "Model 1"],
    );
}

#[test]
fn modulus_figure_shows_estimates_and_models() {
    let dir = out_dir("modulus");
    // Model 4 of the paper: E0 + j h + j w eta1 E1 / (E1 + j w eta1) (values in Pa).
    let (e0, h, e1, eta1) = (5.5e6, 0.6e6, 3.0e6, 2.0e4);
    let model = |f: f64| {
        let w = 2.0 * std::f64::consts::PI * f;
        e0 + J * h + J * w * eta1 * e1 / (e1 + J * w * eta1)
    };
    let fine: Vec<f64> = (1..=500).map(f64::from).collect();
    let lines: Vec<f64> = (10..=40).chain(370..=420).map(f64::from).collect();
    let est: Vec<C64> = lines
        .iter()
        .enumerate()
        .map(|(k, &f)| model(f) * (1.0 + 0.04 * (((k * 31) % 9) as f64 - 4.0) / 4.0))
        .collect();
    let storage = [
        Curve::points(
            "per-line RFM",
            lines.clone(),
            est.iter().map(|z| z.re).collect(),
        ),
        Curve::line(
            "Model 4",
            fine.clone(),
            fine.iter().map(|&f| model(f).re).collect(),
        ),
    ];
    let loss = [
        Curve::points("per-line RFM", lines, est.iter().map(|z| z.im).collect()),
        Curve::line(
            "Model 4",
            fine.clone(),
            fine.iter().map(|&f| model(f).im).collect(),
        ),
    ];
    let files = modulus_figure(dir.join("modulus_level1"), "E* level 1", &storage, &loss).unwrap();
    check_files(
        &files,
        "E* level 1",
        (1000, 800),
        &["per-line RFM", "Model 4", "(MPa)"],
    );
}

#[test]
fn bad_inputs_are_errors_not_panics() {
    let dir = out_dir("errors");
    let stem = dir.join("bad");
    let e = line_figure(&stem, "t", "x", "y", &[], false).unwrap_err();
    assert!(matches!(e, PlotError::NoCurves { .. }), "{e}");
    let e = line_figure(
        &stem,
        "t",
        "x",
        "y",
        &[Curve::line("c", vec![], vec![])],
        false,
    )
    .unwrap_err();
    assert!(matches!(e, PlotError::EmptyCurve { .. }), "{e}");
    let e = line_figure(
        &stem,
        "t",
        "x",
        "y",
        &[Curve::line("c", vec![1.0], vec![])],
        false,
    )
    .unwrap_err();
    assert!(e.to_string().contains("1 x values but 0 y values"), "{e}");
    let nan = Curve::line("c", vec![1.0, 2.0], vec![f64::NAN, f64::INFINITY]);
    let e = line_figure(&stem, "t", "x", "y", &[nan], false).unwrap_err();
    assert!(matches!(e, PlotError::NoFiniteData { .. }), "{e}");
    let neg = Curve::line("c", vec![1.0, 2.0], vec![-1.0, 0.0]);
    let e = line_figure(&stem, "t", "x", "y", &[neg], true).unwrap_err();
    assert!(e.to_string().contains("not positive on a log axis"), "{e}");
    let e = frf_figure(
        &stem,
        "t",
        &[1.0, 2.0],
        &[FrfCurve::new("h", vec![], CurveStyle::Line)],
    )
    .unwrap_err();
    assert!(matches!(e, PlotError::LengthMismatch { .. }), "{e}");
    let e = modulus_figure(&stem, "t", &[], &[]).unwrap_err();
    assert!(matches!(e, PlotError::NoCurves { .. }), "{e}");
    let ok = Curve::line("c", vec![1.0, 2.0], vec![1.0, 2.0]);
    let e = line_figure(
        dir.join("missing/fig"),
        "t",
        "x",
        "y",
        std::slice::from_ref(&ok),
        false,
    )
    .unwrap_err();
    assert!(e.to_string().contains("folder does not exist"), "{e}");
    assert!(!stem.with_extension("png").exists());
    // A single point and a constant curve still plot (degenerate ranges are widened).
    line_figure(
        dir.join("single"),
        "single",
        "x",
        "y",
        &[Curve::points("p", vec![3.0], vec![5.0])],
        true,
    )
    .unwrap();
    line_figure(
        dir.join("flat"),
        "flat",
        "x",
        "y",
        &[Curve::line("c", vec![1.0, 2.0], vec![0.0, 0.0])],
        false,
    )
    .unwrap();
}
