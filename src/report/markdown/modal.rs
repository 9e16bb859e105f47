//! report.md's modal sections: Table 2 (circle-fit modal analysis per level, band and
//! response: frequency and loss factor) and Table 3 (E' and E'' in MPa of the IEM and of
//! Model 1 fitted over each 10 Hz band), beside the paper's values and, for simulated data,
//! the truth curve with the estimates' relative errors.

use super::f4;
use crate::common::C64;
use crate::output::Report;
use crate::pipeline::LevelResults;
use crate::stage::LevelData;

const TWO_PI: f64 = 2.0 * std::f64::consts::PI;

/// Paper Table 2 / 3 reference values: (level, approx centre) -> (f, eta, E' MPa, E'' MPa).
fn paper_mode(level: &str, center_hz: f64) -> Option<(f64, f64, f64, f64)> {
    let low = center_hz < 150.0;
    match (level, low) {
        ("L1", true) => Some((22.26, 0.2044, 6.9740, 1.4827)),
        ("L1", false) => Some((394.45, 0.0720, 9.6404, 1.6085)),
        ("L2", true) => Some((19.28, 0.2202, 5.1831, 1.1757)),
        ("L2", false) => Some((387.33, 0.1121, 8.7146, 2.1234)),
        _ => None,
    }
}

/// Tables 2 and 3: circle fit, IEM and Model 1 over bands.
pub(super) fn modal_tables(rep: &mut Report, levels: &[LevelData], results: &[LevelResults]) {
    let mut t2 = Vec::new();
    let mut t3 = Vec::new();
    let has_truth = levels.iter().any(|l| l.truth.is_some());
    // (what, E' error, E'' error) against the truth curve, for the summary under Table 3.
    let mut truth_errors: Vec<(String, f64, f64)> = Vec::new();
    for (ld, r) in levels.iter().zip(results) {
        // Truth E*(f) (MPa columns) and the errors of `e` against it.
        let truth_at = |f: f64| ld.truth.as_ref().map(|t| t.modulus(TWO_PI * f));
        for m in &r.iem {
            let p = paper_mode(&r.level, m.center_hz);
            t2.push(vec![
                r.level.clone(),
                format!("{:.0}", m.center_hz),
                format!("{}", m.response_id),
                format!("{:.2}", m.circle.freq_hz),
                f4(m.circle.loss_factor),
                p.map(|p| format!("{:.2}", p.0))
                    .unwrap_or_else(|| "-".into()),
                p.map(|p| f4(p.1)).unwrap_or_else(|| "-".into()),
            ]);
            let band = r
                .band_constant
                .iter()
                .find(|b| (b.center_hz - m.center_hz).abs() <= m.width_hz);
            t3.push(vec![
                r.level.clone(),
                format!("{:.0}", m.center_hz),
                m.iem
                    .as_ref()
                    .map(|i| f4(i.modulus.re * 1e-6))
                    .unwrap_or_else(|_| "failed".into()),
                m.iem
                    .as_ref()
                    .map(|i| f4(i.modulus.im * 1e-6))
                    .unwrap_or_else(|_| "failed".into()),
                band.map(|b| f4(b.result.modulus.re * 1e-6))
                    .unwrap_or_else(|| "-".into()),
                band.map(|b| f4(b.result.modulus.im * 1e-6))
                    .unwrap_or_else(|| "-".into()),
                p.map(|p| f4(p.2)).unwrap_or_else(|| "-".into()),
                p.map(|p| f4(p.3)).unwrap_or_else(|| "-".into()),
            ]);
            if has_truth {
                // At the mode: the IEM's analytical frequency, else the circle fit's.
                let f = m
                    .iem
                    .as_ref()
                    .map(|i| i.freq_hz)
                    .unwrap_or(m.circle.freq_hz);
                let t = truth_at(f);
                let row = t3.last_mut().expect("row just pushed");
                row.insert(2, format!("{f:.2}"));
                row.insert(7, t.map(|t| f4(t.re * 1e-6)).unwrap_or_else(|| "-".into()));
                row.insert(8, t.map(|t| f4(t.im * 1e-6)).unwrap_or_else(|| "-".into()));
                if let Some(t) = t {
                    let err = |e: C64| ((e.re - t.re) / t.re, (e.im - t.im) / t.im);
                    if let Ok(i) = &m.iem {
                        let (a, b) = err(i.modulus);
                        truth_errors.push((format!("{} IEM at {f:.1} Hz", r.level), a, b));
                    }
                    if let Some(b) = band {
                        let (x, y) = err(b.result.modulus);
                        truth_errors.push((format!("{} Model 1 band at {f:.1} Hz", r.level), x, y));
                    }
                }
            }
        }
        for b in &r.band_constant {
            if r.iem
                .iter()
                .any(|m| (b.center_hz - m.center_hz).abs() <= m.width_hz)
            {
                continue;
            }
            let p = paper_mode(&r.level, b.center_hz);
            t3.push(vec![
                r.level.clone(),
                format!("{:.0}", b.center_hz),
                "-".into(),
                "-".into(),
                f4(b.result.modulus.re * 1e-6),
                f4(b.result.modulus.im * 1e-6),
                p.map(|p| f4(p.2)).unwrap_or_else(|| "-".into()),
                p.map(|p| f4(p.3)).unwrap_or_else(|| "-".into()),
            ]);
            if has_truth {
                let t = truth_at(b.center_hz);
                let row = t3.last_mut().expect("row just pushed");
                row.insert(2, format!("{:.2}", b.center_hz));
                row.insert(7, t.map(|t| f4(t.re * 1e-6)).unwrap_or_else(|| "-".into()));
                row.insert(8, t.map(|t| f4(t.im * 1e-6)).unwrap_or_else(|| "-".into()));
            }
        }
    }
    if !t2.is_empty() {
        rep.heading(2, "Table 2: circle-fit modal analysis");
        rep.table(
            &[
                "Level",
                "Band centre (Hz)",
                "FRF (response)",
                "f (Hz)",
                "eta",
                "paper f (Hz)",
                "paper eta",
            ],
            &t2,
        );
    }
    let failures: Vec<String> = results
        .iter()
        .flat_map(|r| {
            r.iem
                .iter()
                .filter_map(|m| m.iem.as_ref().err().map(|e| e.to_string()))
        })
        .collect();
    if !t3.is_empty() {
        rep.heading(2, "Table 3: IEM and Model 1 RFM over 10 Hz bands (MPa)");
        for f in &failures {
            rep.paragraph(&format!("**Warning:** {f}"));
        }
        let mut h3 = vec![
            "Level",
            "Band centre (Hz)",
            "IEM E'",
            "IEM E''",
            "RFM Model 1 E'",
            "RFM Model 1 E''",
            "paper IEM E'",
            "paper IEM E''",
        ];
        if has_truth {
            h3.insert(2, "f (Hz)");
            h3.insert(7, "truth E'");
            h3.insert(8, "truth E''");
        }
        rep.table(&h3, &t3);
        if !truth_errors.is_empty() {
            rep.paragraph(
                "Against the truth curve of the simulated data (`measurements.truth`), at f:",
            );
            let rows: Vec<Vec<String>> = truth_errors
                .iter()
                .map(|(w, a, b)| {
                    vec![
                        w.clone(),
                        format!("{:+.2} %", 100.0 * a),
                        format!("{:+.2} %", 100.0 * b),
                    ]
                })
                .collect();
            rep.table(&["Estimate", "E' error", "E'' error"], &rows);
        }
    }
}
