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

// ---------------------------------------------------------------------------------------------
// Posterior figures (trace, pair, bands)
// ---------------------------------------------------------------------------------------------

use rfmlab::plot::posterior::{
    pair_figure, posterior_band_figure, posterior_bands_figure, trace_figure, BandGroup,
};
use rfmlab::plot::FigureFiles;

/// Deterministic standard normals (splitmix64 + Box-Muller).
struct Normals(u64);

impl Normals {
    fn uniform(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        ((z >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }
    fn next(&mut self) -> f64 {
        let (u, v) = (self.uniform(), self.uniform());
        (-2.0 * u.ln()).sqrt() * (2.0 * std::f64::consts::PI * v).cos()
    }
}

fn files_of(stem: &Path) -> FigureFiles {
    FigureFiles {
        png: stem.with_extension("png"),
        svg: stem.with_extension("svg"),
    }
}

/// Correlated Gaussian draws `[param][draw]` with mean `mu` and covariance `L L'`.
fn gaussian_draws(mu: &[f64], l: &[Vec<f64>], n: usize, seed: u64) -> Vec<Vec<f64>> {
    let d = mu.len();
    let mut g = Normals(seed);
    let mut out = vec![Vec::with_capacity(n); d];
    for _ in 0..n {
        let z: Vec<f64> = (0..d).map(|_| g.next()).collect();
        for i in 0..d {
            out[i].push(mu[i] + (0..=i).map(|k| l[i][k] * z[k]).sum::<f64>());
        }
    }
    out
}

#[test]
fn plot_trace_figure_writes_png_and_svg() {
    let dir = out_dir("posterior_trace");
    let names: Vec<String> = ["E0 (MPa)", "h (MPa)", "E1 (MPa)", "eta1 (kPa s)"]
        .map(String::from)
        .to_vec();
    let centres = [5.52, 0.61, 3.0, 20.0];
    let scales = [0.01, 0.02, 0.15, 1.5];
    // AR(1) chains, the third chain starting away and converging.
    let mut g = Normals(7);
    let draws: Vec<Vec<Vec<f64>>> = (0..names.len())
        .map(|p| {
            (0..4)
                .map(|c| {
                    let mut x = if c == 2 { 4.0 } else { 0.0 };
                    (0..1500)
                        .map(|_| {
                            x = 0.8 * x + 0.6 * g.next();
                            centres[p] + scales[p] * x
                        })
                        .collect()
                })
                .collect()
        })
        .collect();
    let stem = dir.join("trace");
    trace_figure(
        &dir.join("trace.png"),
        &names,
        &draws,
        "Traces level 1 (Model 4)",
    )
    .unwrap();
    let files = files_of(&stem);
    let png = std::fs::read(&files.png).unwrap();
    assert_eq!(png_size(&png).0, 1000);
    assert!(png_size(&png).1 > 600);
    check_files(
        &files,
        "Traces level 1 (Model 4)",
        png_size(&png),
        &[
            "E0 (MPa)",
            "eta1 (kPa s)",
            "chain 1",
            "chain 4",
            "Draw",
            "Density",
        ],
    );
    // One parameter, one chain with a NaN and a constant chain still plot.
    trace_figure(
        &dir.join("trace_single"),
        &names[..1],
        &[vec![vec![1.0, f64::NAN, 1.2, 1.1], vec![1.05; 4]]],
        "single",
    )
    .unwrap();
    assert!(dir.join("trace_single.png").exists());
}

#[test]
fn plot_pair_figure_with_map_and_laplace() {
    let dir = out_dir("posterior_pair");
    let names: Vec<String> = ["E0 (MPa)", "h (MPa)", "E1 (MPa)", "eta1 (kPa s)"]
        .map(String::from)
        .to_vec();
    let mu = [5.52, 0.61, 3.0, 20.0];
    let l = vec![
        vec![0.01, 0.0, 0.0, 0.0],
        vec![0.012, 0.016, 0.0, 0.0],
        vec![-0.05, 0.02, 0.12, 0.0],
        vec![0.3, 0.0, -0.9, 0.8],
    ];
    let draws = gaussian_draws(&mu, &l, 4000, 11);
    // Laplace covariance L L' (exact here), MAP slightly off the mean.
    let d = mu.len();
    let mut cov = vec![0.0; d * d];
    for i in 0..d {
        for j in 0..d {
            cov[i * d + j] = (0..d).map(|k| l[i][k] * l[j][k]).sum();
        }
    }
    let map = [5.525, 0.605, 2.98, 20.2];
    pair_figure(
        &dir.join("pair.png"),
        &names,
        &draws,
        Some(&map),
        Some(&cov),
        "Posterior level 1 (Model 4)",
    )
    .unwrap();
    let files = files_of(&dir.join("pair"));
    let png = std::fs::read(&files.png).unwrap();
    let size = png_size(&png);
    assert!(size.0 >= 560 && size.1 >= 560, "{size:?}");
    check_files(
        &files,
        "Posterior level 1 (Model 4)",
        size,
        &[
            "E0 (MPa)",
            "eta1 (kPa s)",
            "MAP",
            "Laplace",
            "posterior draws",
        ],
    );
    // d = 1 without MAP/Laplace, and d = 8 with a covariance that is not positive definite in
    // one block (no ellipse there, no error).
    pair_figure(
        &dir.join("pair_d1"),
        &names[..1],
        &draws[..1],
        None,
        None,
        "d1",
    )
    .unwrap();
    let names8: Vec<String> = (1..=8).map(|k| format!("theta{k}")).collect();
    let l8: Vec<Vec<f64>> = (0..8)
        .map(|i| {
            (0..8)
                .map(|k| {
                    if k == i {
                        1.0
                    } else if k < i {
                        0.3
                    } else {
                        0.0
                    }
                })
                .collect()
        })
        .collect();
    let draws8 = gaussian_draws(&[0.0; 8], &l8, 3000, 5);
    let mut cov8 = vec![0.0; 64];
    for i in 0..8 {
        for j in 0..8 {
            cov8[i * 8 + j] = (0..8).map(|k| l8[i][k] * l8[j][k]).sum();
        }
    }
    cov8[8 + 7] = 50.0; // block (1, 7) not positive definite
    cov8[7 * 8 + 1] = 50.0;
    pair_figure(
        &dir.join("pair_d8"),
        &names8,
        &draws8,
        Some(&[0.0; 8]),
        Some(&cov8),
        "d8",
    )
    .unwrap();
    let svg = std::fs::read_to_string(dir.join("pair_d8.svg")).unwrap();
    assert!(svg.contains("theta8"));
}

fn model4(f: f64, scale: f64) -> (f64, f64) {
    let (e0, h, e1, eta1) = (5.5e6 * scale, 0.6e6 * scale, 3.0e6, 2.0e4);
    let w = 2.0 * std::f64::consts::PI * f;
    let z = rfmlab::common::C64::new(e0, h) + J * w * eta1 * e1 / (e1 + J * w * eta1);
    (z.re, z.im)
}

/// Draws `[draw][line]` of E' and E'' around Model 4 with parameter-like scatter.
fn modulus_draws(freq: &[f64], scale: f64, seed: u64) -> (Vec<Vec<f64>>, Vec<Vec<f64>>) {
    let mut g = Normals(seed);
    let (mut s, mut l) = (Vec::new(), Vec::new());
    for _ in 0..400 {
        let (a, b) = (1.0 + 0.02 * g.next(), 1.0 + 0.06 * g.next());
        s.push(freq.iter().map(|&f| a * model4(f, scale).0).collect());
        l.push(freq.iter().map(|&f| b * model4(f, scale).1).collect());
    }
    (s, l)
}

#[test]
fn plot_posterior_bands_one_and_two_levels() {
    let dir = out_dir("posterior_bands");
    let freq: Vec<f64> = (1..=100).map(|k| 5.0 * f64::from(k)).collect();
    let lines: Vec<f64> = (10..=40).chain(370..=420).map(f64::from).collect();
    let est = |scale: f64, k0: usize| {
        let (s, l): (Vec<f64>, Vec<f64>) = lines
            .iter()
            .enumerate()
            .map(|(k, &f)| {
                let r = 1.0 + 0.04 * ((((k + k0) * 31) % 9) as f64 - 4.0) / 4.0;
                let (a, b) = model4(f, scale);
                (a * r, b * r)
            })
            .unzip();
        (s, l)
    };
    let (s1, l1) = modulus_draws(&freq, 1.0, 3);
    let (e1s, e1l) = est(1.0, 0);
    let overlays1 = vec![("per-line RFM".to_string(), lines.clone(), e1s, e1l)];
    posterior_band_figure(
        &dir.join("bands_level1.png"),
        &freq,
        &s1,
        &l1,
        &overlays1,
        "E* posterior level 1",
    )
    .unwrap();
    check_files(
        &files_of(&dir.join("bands_level1")),
        "E* posterior level 1",
        (1000, 860),
        &[
            "per-line RFM",
            "posterior: median",
            "(MPa)",
            "Frequency (Hz)",
        ],
    );

    let (s2, l2) = modulus_draws(&freq, 0.8, 4);
    let (e2s, e2l) = est(0.8, 3);
    let groups = [
        BandGroup {
            label: "level 1".to_string(),
            freq_hz: freq.clone(),
            storage: s1,
            loss: l1,
        },
        BandGroup {
            label: "level 2".to_string(),
            freq_hz: freq.clone(),
            storage: s2,
            loss: l2,
        },
    ];
    let mut overlays2 = overlays1.clone();
    overlays2[0].0 = "RFM level 1".to_string();
    overlays2.push(("RFM level 2".to_string(), lines.clone(), e2s, e2l));
    posterior_bands_figure(
        &dir.join("bands_levels"),
        &groups,
        &overlays2,
        "E* posterior, two levels",
    )
    .unwrap();
    check_files(
        &files_of(&dir.join("bands_levels")),
        "E* posterior, two levels",
        (1000, 860),
        &["level 1: median", "level 2: median", "RFM level 2"],
    );
}

#[test]
fn plot_posterior_bad_inputs_are_errors_not_panics() {
    let dir = out_dir("posterior_errors");
    let p = dir.join("bad.png");
    let names = vec!["a".to_string(), "b".to_string()];
    let is_input = |e: &PlotError| matches!(e, PlotError::InvalidInput { .. });

    // Trace: zero draws, no chains, names/draws mismatch, chain count mismatch, all NaN.
    let e = trace_figure(&p, &names[..1], &[vec![vec![]]], "t").unwrap_err();
    assert!(is_input(&e) && e.to_string().contains("no draws"), "{e}");
    let e = trace_figure(&p, &names[..1], &[vec![]], "t").unwrap_err();
    assert!(is_input(&e), "{e}");
    let e = trace_figure(&p, &names, &[vec![vec![1.0]]], "t").unwrap_err();
    assert!(is_input(&e), "{e}");
    let e = trace_figure(&p, &[], &[], "t").unwrap_err();
    assert!(is_input(&e), "{e}");
    let e = trace_figure(
        &p,
        &names,
        &[vec![vec![1.0]], vec![vec![1.0], vec![2.0]]],
        "t",
    )
    .unwrap_err();
    assert!(is_input(&e), "{e}");
    let e = trace_figure(&p, &names[..1], &[vec![vec![f64::NAN]]], "t").unwrap_err();
    assert!(matches!(e, PlotError::NoFiniteData { .. }), "{e}");

    // Pair: zero draws, unequal draw counts, wrong MAP / covariance sizes.
    let e = pair_figure(&p, &names, &[vec![], vec![]], None, None, "t").unwrap_err();
    assert!(is_input(&e), "{e}");
    let e = pair_figure(&p, &names, &[vec![1.0, 2.0], vec![1.0]], None, None, "t").unwrap_err();
    assert!(is_input(&e), "{e}");
    let two = [vec![1.0, 2.0], vec![1.0, 3.0]];
    let e = pair_figure(&p, &names, &two, Some(&[1.0]), None, "t").unwrap_err();
    assert!(is_input(&e), "{e}");
    let e = pair_figure(&p, &names, &two, None, Some(&[1.0, 0.0, 0.0]), "t").unwrap_err();
    assert!(is_input(&e), "{e}");
    let e = pair_figure(&p, &[], &[], None, None, "t").unwrap_err();
    assert!(is_input(&e), "{e}");

    // Bands: zero draws, row length != frequency count, overlay lengths, no groups.
    let f = vec![1.0, 2.0, 3.0];
    let e = posterior_band_figure(&p, &f, &[], &[vec![1.0; 3]], &[], "t").unwrap_err();
    assert!(is_input(&e) && e.to_string().contains("no draws"), "{e}");
    let e = posterior_band_figure(&p, &f, &[vec![1.0; 2]], &[vec![1.0; 3]], &[], "t").unwrap_err();
    assert!(matches!(e, PlotError::LengthMismatch { .. }), "{e}");
    let bad_overlay = vec![("o".to_string(), vec![1.0, 2.0], vec![1.0], vec![1.0, 2.0])];
    let e = posterior_band_figure(&p, &f, &[vec![1.0; 3]], &[vec![1.0; 3]], &bad_overlay, "t")
        .unwrap_err();
    assert!(matches!(e, PlotError::LengthMismatch { .. }), "{e}");
    let e = posterior_band_figure(&p, &[], &[vec![]], &[vec![]], &[], "t").unwrap_err();
    assert!(matches!(e, PlotError::EmptyCurve { .. }), "{e}");
    let e = posterior_bands_figure(&p, &[], &[], "t").unwrap_err();
    assert!(matches!(e, PlotError::NoCurves { .. }), "{e}");
    let nan = vec![vec![f64::NAN; 3]];
    let e = posterior_band_figure(&p, &f, &nan, &nan, &[], "t").unwrap_err();
    assert!(matches!(e, PlotError::NoFiniteData { .. }), "{e}");
    // Nothing was written for the failures.
    assert!(!p.exists() && !dir.join("bad.svg").exists());
}
