//! Declared effects (`[[structure.effects]]`) and `[closed_loop]` (src/study/effects.rs):
//! good declarations parse into the study; bad ones (an unknown effect name, a point id that
//! does not exist, a negative mass, a bad candidate or threshold) make `rfmlab diagnose FILE`
//! exit with code 2 and an error naming the file, the key and the fix, never a panic.

use rfmlab::study::effects::DeclaredKind;
use std::path::{Path, PathBuf};
use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_rfmlab");

fn base() -> String {
    std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("studies/paper_geometry.toml"),
    )
    .expect("studies/paper_geometry.toml")
}

fn write(dir: &Path, name: &str, extra: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, format!("{}\n{extra}\n", base())).unwrap();
    p
}

#[test]
fn declared_effects_and_closed_loop_parse() {
    let dir = tempfile::tempdir().unwrap();
    let f = write(
        dir.path(),
        "good.toml",
        r#"
[[structure.effects]]
type = "point_mass"
point = 4
value = 0.012

[[structure.effects]]
type = "gain"
channel = 3
free = true
prior = { family = "uniform", lo = -0.1, hi = 0.1 }

[[structure.effects]]
type = "maxwell_branch"
tau = 1.6e-3
value = 2.0e6

[[structure.effects]]
type = "resonator"
point = 2
stiffness = 1.5e5
value = 0.02

[closed_loop]
candidates = ["point_mass", "delay_ch2", "resonator"]
resonator_stiffness = 3e5
max_effects = 2
evidence_threshold = 6.0
p_threshold = 0.05
"#,
    );
    let s = rfmlab::study::load(&f).unwrap();
    assert_eq!(s.declared_effects.len(), 4);
    assert_eq!(
        s.declared_effects[0].kind,
        DeclaredKind::PointMass { point: 4 }
    );
    assert_eq!(s.declared_effects[0].value, 0.012);
    assert!(!s.declared_effects[0].free);
    assert_eq!(
        s.declared_effects[1].kind,
        DeclaredKind::Gain { channel: 3 }
    );
    assert!(s.declared_effects[1].free && s.declared_effects[1].prior.is_some());
    assert_eq!(
        s.declared_effects[2].kind,
        DeclaredKind::MaxwellBranch { tau_s: 1.6e-3 }
    );
    assert_eq!(
        s.declared_effects[3].kind,
        DeclaredKind::Resonator {
            point: 2,
            stiffness_n_m: 1.5e5
        }
    );
    assert_eq!(s.declared_effects[3].value, 0.02);
    let cl = s.closed_loop.unwrap();
    assert!(cl.enabled);
    assert!(cl.admits("resonator", "resonator_pt3"));
    assert_eq!(cl.resonator_stiffness_n_m, 3e5);
    assert!(cl.admits("point_mass", "mass_pt1"));
    assert!(cl.admits("delay", "delay_ch2"));
    assert!(!cl.admits("delay", "delay_ch3"));
    assert_eq!(
        (cl.max_effects, cl.evidence_threshold_nats, cl.p_threshold),
        (2, 6.0, 0.05)
    );
    let p = rfmlab::diagnose::params_of(&rfmlab::study::load(&f).unwrap());
    assert_eq!(
        (p.threshold_nats, p.p_threshold, p.max_rounds),
        (6.0, 0.05, 3)
    );
}

#[test]
fn bad_declared_effects_exit_2_naming_file_and_key() {
    let dir = tempfile::tempdir().unwrap();
    let cases: [(&str, &str, &[&str]); 8] = [
        (
            "unknown.toml",
            "[[structure.effects]]\ntype = \"sensor_mass\"\npoint = 4\nvalue = 0.012",
            &[
                "structure.effects[0].type",
                "unknown effect \"sensor_mass\"",
                "point_mass",
            ],
        ),
        (
            "nopoint.toml",
            "[[structure.effects]]\ntype = \"point_mass\"\npoint = 9\nvalue = 0.012",
            &["structure.effects[0].point", "point id 9 does not exist"],
        ),
        (
            "negative.toml",
            "[[structure.effects]]\ntype = \"point_mass\"\npoint = 4\nvalue = -0.012",
            &["structure.effects[0].value", "cannot be negative"],
        ),
        (
            "nochannel.toml",
            "[[structure.effects]]\ntype = \"delay\"\nchannel = 7\nvalue = 5e-5",
            &["structure.effects[0].channel", "point id 7 does not exist"],
        ),
        (
            "candidate.toml",
            "[closed_loop]\ncandidates = [\"shaker_spring\"]",
            &["closed_loop.candidates[0]", "unknown candidate"],
        ),
        (
            "springless.toml",
            "[[structure.effects]]\ntype = \"resonator\"\npoint = 2\nstiffness = -1e5\nvalue = 0.02",
            &["structure.effects[0].stiffness", "positive number in N/m"],
        ),
        (
            "loopspring.toml",
            "[closed_loop]\nresonator_stiffness = 0.0",
            &["closed_loop.resonator_stiffness", "positive number in N/m"],
        ),
        (
            "pthreshold.toml",
            "[closed_loop]\np_threshold = 0.0",
            &["closed_loop.p_threshold", "(0, 1]"],
        ),
    ];
    for (name, extra, needles) in cases {
        let f = write(dir.path(), name, extra);
        let out = Command::new(BIN)
            .args(["--quiet", "diagnose"])
            .arg(&f)
            .env("CI", "1")
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{name}: {err}");
        assert!(!err.contains("panicked"), "{name}: {err}");
        assert!(
            err.contains(name),
            "{name}: error does not name the file: {err}"
        );
        for n in needles {
            assert!(err.contains(n), "{name}: error lacks `{n}`: {err}");
        }
    }
}
