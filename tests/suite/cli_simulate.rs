//! `rfmlab simulate` end to end with the options the default data does not use: frequency-domain
//! mode, binary UFF, a Model 3 truth, a sensor mass, a channel gain; and bad experiment files.

use std::path::Path;
use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_rfmlab");

fn experiment(mode_law: &str, gain: f64) -> String {
    let structure = crate::runner_common::structure();
    format!(
        r#"
[experiment]
name = "options"
description = "simulate options test (SIMULATED)"
{mode_law}
seed = 7
output = "opt.uff"
binary = true
engine = "full"

{structure}
[chain]
band_hz = [1.0, 25.0]
lines_hz = [1.0, 25.0, 1.0]
fs_hz = 512.0
block_s = 1.0
overlap = 0.5
averages = 50
window = "hann"
force_noise_fraction = 0.002
response_noise_fraction = 0.002

[[sensors]]
point = 3
mass = 0.005

[[channels]]
point = 4
gain = {gain}
"#
    )
}

fn run(dir: &Path, name: &str, text: &str) -> std::process::Output {
    let f = dir.join(name);
    std::fs::write(&f, text).unwrap();
    Command::new(BIN)
        .args(["simulate", f.to_str().unwrap(), "--quiet", "--out"])
        .arg(dir.join(format!("{name}.uff")))
        .output()
        .unwrap()
}

const LEVEL: &str = r#"
[[levels]]
name = "L1"
force_rms_n = 3.3
law = "model3"
params = { E0 = 6.0e6, E1 = 3.0e6, eta1 = 4.0e3 }
"#;

fn frfs(dir: &Path) -> Vec<(u32, Vec<rfmlab::common::C64>)> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_some_and(|x| x == "uff") {
            let bytes = std::fs::read(&p).unwrap();
            let text = String::from_utf8_lossy(&bytes);
            assert!(text.contains("58b"), "{} is not binary UFF", p.display());
            assert!(
                text.contains("SIMULATED"),
                "{} is not labelled",
                p.display()
            );
            let set = rfmlab::data::uff_frf::frf_set_from_uff(
                &[(p.clone(), String::new())],
                &Default::default(),
            )
            .unwrap();
            for c in &set.levels[0].channels {
                out.push((c.response_id, c.values.clone()));
            }
        }
    }
    out.sort_by_key(|c| c.0);
    out
}

#[test]
fn frequency_mode_binary_model3_sensor_mass_and_gain() {
    let a = tempfile::tempdir().unwrap();
    let b = tempfile::tempdir().unwrap();
    let mode = "mode = \"frequency\"";
    let oa = run(a.path(), "a.toml", &(experiment(mode, 1.0) + LEVEL));
    assert!(
        oa.status.success(),
        "{}",
        String::from_utf8_lossy(&oa.stderr)
    );
    let ob = run(b.path(), "b.toml", &(experiment(mode, 2.0) + LEVEL));
    assert!(
        ob.status.success(),
        "{}",
        String::from_utf8_lossy(&ob.stderr)
    );
    let (fa, fb) = (frfs(a.path()), frfs(b.path()));
    assert_eq!(fa.len(), 4);
    assert_eq!(fa.len(), fb.len());
    for ((ia, va), (ib, vb)) in fa.iter().zip(&fb) {
        assert_eq!(ia, ib);
        assert_eq!(va.len(), 25);
        // same seed: channel 4 carries the gain of 2, the others are unchanged
        let want = if *ia == 4 { 2.0 } else { 1.0 };
        for (x, y) in va.iter().zip(vb) {
            assert!(
                (y - x * want).norm() <= 1e-6 * (x * want).norm(),
                "point {ia}: {x} {y}"
            );
        }
    }
    // the truth sidecar names the law
    let truth: Vec<_> = std::fs::read_dir(a.path())
        .unwrap()
        .filter_map(|e| {
            let p = e.unwrap().path();
            p.to_str()
                .is_some_and(|s| s.ends_with(".json"))
                .then_some(p)
        })
        .collect();
    assert_eq!(truth.len(), 1, "{truth:?}");
    let t = std::fs::read_to_string(&truth[0]).unwrap();
    assert!(
        t.contains("model3") && t.contains("\"simulated\": true"),
        "{t}"
    );
}

#[test]
fn bad_experiment_files_exit_2_naming_the_key() {
    let d = tempfile::tempdir().unwrap();
    let cases = [
        (
            experiment("mode = \"fast\"", 1.0) + LEVEL,
            "experiment.mode",
        ),
        (
            experiment("mode = \"time\"", 1.0) + &LEVEL.replace("model3", "model9"),
            "law",
        ),
        (
            experiment("mode = \"time\"", 1.0).replace("mass = 0.005", "mass = -1.0") + LEVEL,
            "sensors[0].mass",
        ),
        (experiment("mode = \"time\"", 1.0), "levels"),
    ];
    for (k, (text, key)) in cases.iter().enumerate() {
        let o = run(d.path(), &format!("bad{k}.toml"), text);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "case {k}: {err}");
        assert!(err.contains(&format!("bad{k}.toml")), "case {k}: {err}");
        assert!(err.contains(key), "case {k}: {err}");
    }
}
