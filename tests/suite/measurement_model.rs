//! The identification's measurement model against an independent reference: rfmlab's expected
//! Welch H1 (`experiment::leakage_bias` on the chain a study's `[measurements.estimator]`
//! declares, `study::Estimator::chain`) against a Monte Carlo of scipy's Welch H1
//! (scripts/welch_h1_mc.py: white force band-limited to (0, 500] Hz by zeroing FFT bins of
//! 100.5 s records, exact circular filtering, `scipy.signal.csd / welch` with the periodic
//! Hann, 2048-sample blocks at 2048 Hz, 50 % overlap, 200 segments, 40 replicate records), and
//! against the same script's exact expectation (the kernel sum over every record bin).
//!
//! The plant is the script's: accelerance `-w^2 sum_r c_ir / (w_r^2 (1 + j eta_r) - w^2)`, a
//! heavily damped mode (22 Hz, eta 0.2) and a lighter one (390 Hz, eta 0.08), two channels.

use crate::python_checks::{python_for_scipy, run_script};
use rfmlab::common::C64;
use rfmlab::experiment::{ExperimentError, Plant, Window};
use rfmlab::forward::{EstimatorSpec, MeasurementModel, MeasurementParams};
use rfmlab::study::Estimator;
use std::f64::consts::PI;

struct ModalPlant {
    /// (f_r Hz, eta_r, modal constant per channel 1/kg)
    modes: Vec<(f64, f64, Vec<f64>)>,
}

impl Plant for ModalPlant {
    fn n_channels(&self) -> usize {
        self.modes[0].2.len()
    }
    fn drive_channel(&self) -> usize {
        0
    }
    fn accelerance(&self, freq_hz: &[f64]) -> Result<Vec<Vec<C64>>, ExperimentError> {
        Ok((0..self.n_channels())
            .map(|i| {
                freq_hz
                    .iter()
                    .map(|&f| {
                        let w2 = (2.0 * PI * f).powi(2);
                        self.modes
                            .iter()
                            .map(|(fr, eta, c)| {
                                let wr2 = (2.0 * PI * fr).powi(2);
                                -w2 * c[i] / C64::new(wr2 - w2, wr2 * eta)
                            })
                            .sum()
                    })
                    .collect()
            })
            .collect())
    }
}

/// One channel of the reference: MC mean, its standard errors, the exact expectation.
struct RefChannel {
    mean: Vec<C64>,
    se: Vec<(f64, f64)>,
    expected: Vec<C64>,
    exact: Vec<C64>,
}

struct Reference {
    plant: ModalPlant,
    lines_hz: Vec<f64>,
    channels: Vec<RefChannel>,
}

fn run_mc(test: &str) -> Option<Reference> {
    let py = python_for_scipy(test)?;
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("mc.json");
    run_script(
        &py,
        "welch_h1_mc.py",
        &[std::ffi::OsStr::new("--out"), out.as_os_str()],
        &[],
    );
    let j: serde_json::Value = serde_json::from_slice(&std::fs::read(&out).unwrap()).unwrap();
    let v = |x: &serde_json::Value| -> Vec<f64> {
        x.as_array()
            .unwrap()
            .iter()
            .map(|e| e.as_f64().unwrap())
            .collect()
    };
    let cv = |c: &serde_json::Value, name: &str| -> Vec<C64> {
        v(&c[format!("{name}_re")])
            .into_iter()
            .zip(v(&c[format!("{name}_im")]))
            .map(|(re, im)| C64::new(re, im))
            .collect()
    };
    // The chain the reference simulates is the one this test declares below.
    assert_eq!(j["force_band_hz"], serde_json::json!([0.0, 500.0]));
    assert_eq!(j["nperseg"], 2048);
    assert_eq!(j["noverlap"], 1024);
    let modes = j["modes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| {
            (
                m["f_hz"].as_f64().unwrap(),
                m["eta"].as_f64().unwrap(),
                v(&m["c"]),
            )
        })
        .collect();
    let channels = j["channels"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| RefChannel {
            mean: cv(c, "mean"),
            se: v(&c["se_re"]).into_iter().zip(v(&c["se_im"])).collect(),
            expected: cv(c, "expected"),
            exact: cv(c, "exact"),
        })
        .collect();
    Some(Reference {
        plant: ModalPlant { modes },
        lines_hz: v(&j["lines_hz"]),
        channels,
    })
}

/// rfmlab's expected H1 `[channel][line]` with `force_band_hz` declared or not (default): the
/// forward model's measurement operator (the one every fit and the likelihood use) applied to
/// the plant's accelerance on its fine grid.
fn predicted(r: &Reference, force_band_hz: Option<(f64, f64)>) -> Vec<Vec<C64>> {
    let est = Estimator {
        window: Window::Hann,
        block_s: 1.0,
        fs_hz: 2048.0,
        shaker: None,
        force_band_hz,
    };
    let data_band = (r.lines_hz[0], *r.lines_hz.last().unwrap());
    let m = MeasurementModel::new(
        EstimatorSpec {
            window: est.window,
            block_s: est.block_s,
            fs_hz: est.fs_hz,
            force_band_hz: est.force_band(data_band),
            shaker: None,
        },
        &r.lines_hz,
        &MeasurementParams::default(),
    )
    .unwrap();
    let fine = r.plant.accelerance(&m.fine_hz).unwrap();
    fine.iter()
        .map(|h| MeasurementModel::apply(&m.rows, h, 1))
        .collect()
}

/// Largest deviation from the MC mean in standard errors (max over re, im) per line, and the
/// relative deviation from the exact expectation, `|pred - E| / |E|`, per line, per channel.
fn deviations(r: &Reference, pred: &[Vec<C64>]) -> Vec<(Vec<f64>, Vec<f64>)> {
    r.channels
        .iter()
        .zip(pred)
        .map(|(c, p)| {
            let z = p
                .iter()
                .zip(&c.mean)
                .zip(&c.se)
                .map(|((p, m), (sr, si))| {
                    ((p.re - m.re) / sr).abs().max(((p.im - m.im) / si).abs())
                })
                .collect();
            let rel = p
                .iter()
                .zip(&c.expected)
                .map(|(p, e)| (p - e).norm() / e.norm())
                .collect();
            (z, rel)
        })
        .collect()
}

#[test]
fn expected_h1_matches_scipy_welch_monte_carlo() {
    let Some(r) = run_mc("expected_h1_matches_scipy_welch_monte_carlo") else {
        return;
    };
    // The MC itself: its mean and the exact expectation agree (the reference is consistent).
    for c in &r.channels {
        let zmax = c
            .mean
            .iter()
            .zip(&c.expected)
            .zip(&c.se)
            .map(|((m, e), (sr, si))| ((m.re - e.re) / sr).abs().max(((m.im - e.im) / si).abs()))
            .fold(0.0, f64::max);
        assert!(zmax < 5.0, "MC mean vs exact expectation: {zmax} SE");
        // The leakage is real here: 6 % at the 22 Hz peak, 34 % at 1 Hz.
        let bias = |k: usize| (c.expected[k] - c.exact[k]).norm() / c.exact[k].norm();
        assert!(bias(21) > 0.05 && bias(0) > 0.3, "{} {}", bias(21), bias(0));
    }

    // rfmlab with the study's default force band (baseband: (0, last line]).
    let new = deviations(&r, &predicted(&r, None));
    for (ch, (z, rel)) in new.iter().enumerate() {
        let (kz, zmax) = z
            .iter()
            .enumerate()
            .fold((0, 0.0), |a, (k, &v)| if v > a.1 { (k, v) } else { a });
        let (kr, rmax) = rel
            .iter()
            .enumerate()
            .fold((0, 0.0), |a, (k, &v)| if v > a.1 { (k, v) } else { a });
        eprintln!(
            "channel {ch}: max {zmax:.2} SE from the MC mean at {} Hz; max {rmax:.2e} from the exact expectation at {} Hz; first lines {:?} SE",
            r.lines_hz[kz],
            r.lines_hz[kr],
            &z[..4]
        );
        assert!(
            zmax < 5.0,
            "channel {ch}: {zmax} SE at {} Hz",
            r.lines_hz[kz]
        );
        // Against the exact expectation: 4e-6 (channel 0), 1.1e-5 (channel 1, near its
        // anti-resonance) from 2 Hz up (measured); 1.7e-3 at 1 Hz, where
        // the reference's finite record (100.5 s) has no force within half a record bin
        // (0.005 Hz) of DC on either side, `2 * 0.005 Hz * |W(1)|^2 / int |W|^2`, which rfmlab's
        // continuous force spectrum has: a property of the reference, gone as the record grows.
        assert!(rel[0] < 2.5e-3, "channel {ch}: {} at 1 Hz", rel[0]);
        let rmax2 = rel[1..].iter().fold(0.0, |a: f64, &b| a.max(b));
        assert!(rmax2 < 5e-5, "channel {ch}: {rmax2} from 2 Hz up");
    }

    // The old assumption (force only from the first data line, (1, 500]) fails at the lowest
    // lines: the force below 1 Hz and its mirror are missing from the kernel average.
    let old = deviations(&r, &predicted(&r, Some((1.0, 500.0))));
    for (ch, (z, rel)) in old.iter().enumerate() {
        eprintln!(
            "old band (1, 500]: channel {ch}: lines 1-4 Hz {:?} SE, {:?} relative",
            &z[..4],
            &rel[..4]
        );
        assert!(z[0] > 20.0 && rel[0] > 0.05, "channel {ch}: {} SE", z[0]);
    }
}

/// The grid is chosen by convergence, and what is chosen is converged: on the spring chain
/// (modes from 20 Hz) a lossy adhesive (E'' = 0.3 E') needs fewer points per line than a
/// nearly elastic one (E'' = 0.01 E', sharp resonances), and the chosen grid's E[H1] agrees
/// with a 32-point reference to the tolerance (per line, relative to |H|) within a factor 2
/// (the doubling check estimates the error of the coarser grid).
#[test]
fn measurement_grid_is_chosen_by_convergence() {
    use rfmlab::forward::{Observation, GRID_TOLERANCE};
    let engine = crate::spring_model::measured_engine();
    let lines: Vec<f64> = (1..=200).map(|k| k as f64).collect();
    let omega: Vec<f64> = lines.iter().map(|f| 2.0 * PI * f).collect();
    let spec = EstimatorSpec {
        window: Window::Hann,
        block_s: 1.0,
        fs_hz: 2048.0,
        force_band_hz: (0.0, 200.0),
        shaker: None,
    };
    let obs = Observation::new(&engine, &omega, 1, &[0, 1, 2, 3], None).unwrap();
    let choose = |loss: f64| {
        let modulus = move |_w: f64| C64::new(5e6, loss * 5e6);
        let (m, choice) = obs
            .converged_measurement(spec, &modulus, GRID_TOLERANCE)
            .unwrap();
        // Against 32 points per line.
        let reference = MeasurementModel::new(
            spec,
            &lines,
            &MeasurementParams {
                points_per_line: 32,
                ..MeasurementParams::default()
            },
        )
        .unwrap();
        let bias = |mm: MeasurementModel| {
            Observation::new(&engine, &omega, 1, &[0, 1, 2, 3], Some(mm))
                .unwrap()
                .bias_for_modulus(&modulus)
                .unwrap()
        };
        let le: Vec<C64> = omega.iter().map(|&w| modulus(w)).collect();
        let (exact, _) = obs.accelerance_with(&omega, &le, false).unwrap();
        let err = bias(m)
            .iter()
            .zip(bias(reference))
            .zip(&exact)
            .map(|((a, b), h)| (a - b).norm() / h.norm())
            .fold(0.0, f64::max);
        eprintln!("loss factor {loss}: {choice:?}, error vs 32 points {err:.2e}");
        (choice, err)
    };
    let (lossy, e_lossy) = choose(0.3);
    let (sharp, e_sharp) = choose(0.01);
    assert!(
        lossy.converged && e_lossy < 2.0 * GRID_TOLERANCE,
        "{lossy:?} {e_lossy}"
    );
    assert!(
        sharp.points_per_line > lossy.points_per_line,
        "a nearly elastic adhesive needs a finer grid: {sharp:?} vs {lossy:?}"
    );
    assert!(
        !sharp.converged || e_sharp < 2.0 * GRID_TOLERANCE,
        "{sharp:?} {e_sharp}"
    );
}
