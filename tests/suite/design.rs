//! `rfmlab design` (src/design): the predicted posterior of a planned test against the Laplace
//! posterior rfmlab then fits, the expected coherence against the virtual experiment's truth,
//! a sensor's mass in the prediction, and the `[design]` section's errors.

use crate::runner_common::rfmlab_cli;
use rfmlab::common::C64;
use rfmlab::experiment::{ChainParams, Mode, NoiseLevel, Plant};
use std::path::{Path, PathBuf};

/// `studies/bayes.toml` with its data paths made absolute, `extra` appended and the lines
/// `replace` swapped, written to `dir/name.toml`.
fn bayes_variant(dir: &Path, name: &str, replace: &[(&str, &str)], extra: &str) -> PathBuf {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("studies");
    let mut s = std::fs::read_to_string(root.join("bayes.toml")).unwrap();
    s = s.replace("\"data/", &format!("\"{}/data/", root.display()));
    s = s.replace("name = \"bayes\"", &format!("name = \"{name}\""));
    for (a, b) in replace {
        assert!(s.contains(a), "{a} not in bayes.toml");
        s = s.replace(a, b);
    }
    s.push_str(extra);
    let f = dir.join(format!("{name}.toml"));
    std::fs::write(&f, s).unwrap();
    f
}

/// `rfmlab <command> <study> -o <out>` exits 0 (its stderr shown when not).
fn succeeds(command: &str, study: &Path, out: &Path) {
    let (code, _, err) = rfmlab_cli(&[
        command,
        study.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, Some(0), "{err}");
}

fn column(path: &Path, name: &str) -> Vec<f64> {
    let t = rfmlab::output::Table::read_parquet(path).unwrap();
    t.column(name).and_then(|c| c.as_f64()).unwrap().to_vec()
}

fn strings(path: &Path, name: &str) -> Vec<String> {
    let t = rfmlab::output::Table::read_parquet(path).unwrap();
    match t.column(name) {
        Some(rfmlab::output::ColumnData::Str(v)) => v.clone(),
        _ => panic!("no column {name}"),
    }
}

const DESIGN: &str = "
[design]
sensors = 4
candidates = \"points\"
directions = [\"y\"]
models = [\"model4\"]
force_noise = 0.002       # the bundled data's rig
response_noise = 0.002
n_averages = 200
";

/// The design's prediction for the study's own sensors, at the posterior of a run on the
/// bundled data (its MAP per level), against that run's Laplace sds: the same likelihood, but
/// the noise scales predicted from the measurement chain instead of read from the data's
/// coherence. Measured: within 0.4 % for every parameter at both levels; at the initial values
/// instead of the posterior (before any measurement) within 8-42 %, the second level's adhesive
/// being softer than believed.
#[test]
fn predicted_sds_of_model4_match_the_laplace_sds_of_the_bayes_study() {
    let dir = tempfile::tempdir().unwrap();
    let study = bayes_variant(
        dir.path(),
        "bayes_laplace",
        &[("samplers = [\"nuts\", \"stepping_stone\"]", "samplers = []")],
        "",
    );
    let run_dir = dir.path().join("run");
    succeeds("run", &study, &run_dir);
    let plan = bayes_variant(
        dir.path(),
        "plan",
        &[],
        &format!("{DESIGN}draws = 0\nposterior = \"{}\"\n", run_dir.display()),
    );
    let out = dir.path().join("plan.design");
    succeeds("design", &plan, &out);
    let lap = run_dir.join("laplace.parquet");
    let (lv, mo, pa) = (
        strings(&lap, "level"),
        strings(&lap, "model"),
        strings(&lap, "parameter"),
    );
    let (map, sd) = (column(&lap, "map"), column(&lap, "sd"));
    let des = out.join("design.parquet");
    let (kind, dlv) = (strings(&des, "design"), strings(&des, "level"));
    let mut checked = 0;
    for i in 0..lv.len() {
        if mo[i] != "model4" {
            continue;
        }
        let row = (0..kind.len())
            .find(|&r| kind[r] == "current" && dlv[r] == lv[i])
            .expect("the study's design at the level");
        let predicted = column(&des, &format!("sd_rel_{}", pa[i].to_ascii_lowercase()))[row];
        let laplace = sd[i] / map[i];
        let ratio = predicted / laplace;
        assert!(
            (ratio - 1.0).abs() < 0.25,
            "{} {}: predicted {predicted:.3e}, Laplace {laplace:.3e} (ratio {ratio:.3})",
            lv[i],
            pa[i]
        );
        checked += 1;
    }
    assert_eq!(checked, 8);
}

/// A sensor's 10 g in x, y and z at each of the four points changes the predicted sds (the
/// masses lower the modes and the FRFs the likelihood sees), and the report says so.
#[test]
fn a_sensor_mass_changes_the_predicted_sds() {
    let dir = tempfile::tempdir().unwrap();
    let mut sds = Vec::new();
    for mass in [0.0, 0.010] {
        let plan = bayes_variant(
            dir.path(),
            &format!("plan{}", (mass * 1e3) as u32),
            &[],
            &format!("{DESIGN}draws = 0\nsensor_mass = {mass}\n"),
        );
        let out = dir.path().join(format!("out{}", (mass * 1e3) as u32));
        succeeds("design", &plan, &out);
        let des = out.join("design.parquet");
        let kind = strings(&des, "design");
        let row = kind.iter().position(|k| k == "current").unwrap();
        sds.push(column(&des, "sd_rel_e0")[row]);
        let report = std::fs::read_to_string(out.join("report.md")).unwrap();
        assert_eq!(
            report.contains("10.0 g acts in x, y and z"),
            mass > 0.0,
            "{report}"
        );
    }
    let change = (sds[1] / sds[0] - 1.0).abs();
    assert!(
        change > 1e-3,
        "E0's predicted sd moved by {change:.2e} only: {sds:?}"
    );
}

/// Two channels of a lightly damped oscillator (a drive point and a transfer at a quarter of its
/// amplitude, which makes the noise matter differently), seen through the simulator's chain.
struct Oscillator;

impl Plant for Oscillator {
    fn n_channels(&self) -> usize {
        2
    }
    fn drive_channel(&self) -> usize {
        0
    }
    fn accelerance(&self, f: &[f64]) -> Result<Vec<Vec<C64>>, rfmlab::experiment::ExperimentError> {
        let h = |f: f64, f0: f64, eta: f64| {
            let (w, w0) = (std::f64::consts::TAU * f, std::f64::consts::TAU * f0);
            -w * w / C64::new(w0 * w0 - w * w, eta * w0 * w0)
        };
        Ok(vec![
            f.iter().map(|&f| h(f, 42.3, 0.02)).collect(),
            f.iter()
                .map(|&f| 0.25 * h(f, 42.3, 0.02) + 0.1 * h(f, 160.7, 0.05))
                .collect(),
        ])
    }
}

/// The design's expected coherence is the virtual experiment's truth record (the same force
/// spectrum, window kernel and noise), to rounding, at every line, with noise as a fraction of
/// the signal and as an absolute level.
#[test]
fn expected_coherence_is_the_simulators_truth() {
    for noise in [NoiseLevel::FractionOfSignalRms(0.01), NoiseLevel::Rms(0.05)] {
        let chain = ChainParams {
            band_hz: (1.0, 200.0),
            lines_hz: (5..=200).map(|k| k as f64).collect(),
            n_averages: 4,
            force_noise: NoiseLevel::FractionOfSignalRms(0.003),
            response_noise: vec![noise],
            mode: Mode::FrequencyDomain,
            ..ChainParams::default()
        };
        let want = rfmlab::experiment::simulate_level(&Oscillator, &chain).unwrap();
        let got = rfmlab::experiment::expected_coherence(&Oscillator, &chain).unwrap();
        let mut low: f64 = 1.0;
        for (c, g) in want.truth.channels.iter().zip(&got) {
            for (a, b) in c.expected_coherence.iter().zip(g) {
                assert!((a - b).abs() < 1e-12, "{a} against {b}");
                low = low.min(*b);
            }
        }
        // the check is not on coherences that are all one
        assert!(low < 0.9, "lowest expected coherence {low}");
    }
}

/// `[design]` errors name the key and the fix.
#[test]
fn design_section_errors_name_the_key() {
    let dir = tempfile::tempdir().unwrap();
    for (extra, key) in [
        ("[design]\ndrives = [9]\n", "design.drives"),
        ("[design]\ndirections = [\"w\"]\n", "design.directions[0]"),
        ("[design]\nsensors = 0\n", "design.sensors"),
        ("[design]\nmodels = [\"model9\"]\n", "design.models"),
        (
            "[design]\nresponse_noise = 0.01\nresponse_noise_rms = 0.01\n",
            "design.response_noise_rms",
        ),
    ] {
        let plan = bayes_variant(dir.path(), "bad", &[], extra);
        let (code, _, err) = rfmlab_cli(&[
            "design",
            plan.to_str().unwrap(),
            "-o",
            dir.path().join("o").to_str().unwrap(),
        ]);
        assert_eq!(code, Some(2), "{extra}: {err}");
        assert!(err.contains(key), "{extra}: {err}");
    }
}

/// On the light lap joint (two 20 g strips), a 10 g sensor in x, y and z changes what the
/// design recommends: the study's own design's worst predicted sd drops (2.16 % to 1.29 % on
/// this grid: the masses move the modes) and the best four sensors are not the same places as
/// without the mass.
/// The suite checks the sensor mass's effect on the design on the paper's joint
/// (`a_sensor_mass_changes_the_predicted_sds`).
#[test]
#[ignore = "slow: 86 s in the test profile; the suite checks a sensor mass's effect on the design on the paper's joint; run with --ignored"]
fn a_sensor_mass_moves_the_recommended_sensors_on_a_light_lap_joint() {
    let dir = tempfile::tempdir().unwrap();
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("studies");
    let base = std::fs::read_to_string(root.join("design_lap1.toml"))
        .unwrap()
        .replace("\"data/", &format!("\"{}/data/", root.display()))
        .replace("drives = [3, 5, 6]", "drives = [5]");
    let mut best = Vec::new();
    let mut current = Vec::new();
    for mass in [0.0, 0.010] {
        let name = format!("lap{}", (mass * 1e3) as u32);
        let f = dir.path().join(format!("{name}.toml"));
        std::fs::write(
            &f,
            base.replace(
                "\ndraws = 0\n",
                &format!("\ndraws = 0\nsensor_mass = {mass}\nspacing = 0.0146\n"),
            ),
        )
        .unwrap();
        let out = dir.path().join(&name);
        succeeds("design", &f, &out);
        let des = out.join("design.parquet");
        let (kind, sensors) = (strings(&des, "design"), strings(&des, "sensors"));
        let worst = column(&des, "worst_sd_rel");
        let b = kind.iter().position(|k| k == "best").unwrap();
        let c = kind.iter().position(|k| k == "current").unwrap();
        let mut s: Vec<String> = sensors[b].split(", ").map(String::from).collect();
        s.sort();
        best.push(s);
        current.push(worst[c]);
    }
    assert_ne!(
        best[0], best[1],
        "the same places with and without the mass"
    );
    assert!(
        current[1] < 0.8 * current[0],
        "the study's design: worst sd {:.3e} without, {:.3e} with the masses",
        current[0],
        current[1]
    );
}
