//! The closed loop on data made by INDEPENDENT code: studies/data/virtual/model4_td
//! (Welch H1 of a Python/scikit-fem model of the joint with its own mesh, reduced basis and
//! measurement chain; Model 4 truth in its truth.json), diagnosed with
//! studies/closed_loop_virtual_td.toml.
//!
//! * Null: the data carry nothing beyond the study, so the loop must accept nothing, the Model 4
//!   parameters must lie within 3 posterior sds of the independent truth and the normalised
//!   chi-square must be at most 1.2. A model-form difference between the two FE models would
//!   show here as a "missing effect".
//! * Measurement effects applied exactly to the independent H1 (a channel gain multiplies H1 by
//!   1 + g; a channel delay multiplies it by exp(-j w tau), exact for tau much shorter than the
//!   1 s Welch block; neither changes the coherence): the loop must name the effect first,
//!   identify its size within 15 % and within its 95 % interval, and meet the null's criteria.
//!
//! The verdict: `nothing_missing` on the null, `explained` with the injected effect.
//!
//! The default suite runs level L1 (null and a 4 % gain on channel 3). Ignored tests
//! (`cargo test --release --test suite -- --ignored NAME`) run the full sets:
//! `independent_null_data_at_both_levels_accept_nothing_and_recover_the_truth` (L1 and L2) and
//! `independent_data_with_each_channel_error_name_it` (the gain and a 50 us delay on channel 4
//! at L1).

use crate::closed_loop_td::judge;
use crate::shared_rom_cache;
use rfmlab::common::C64;
use rfmlab::data::uff58::{read_uff, write_uff, Ordinate};
use rfmlab::diagnose::{diagnose_study, params_of, DiagnoseLevel};
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// What to apply to response channel `id`'s H1 before the loop sees it.
enum Inject {
    Nothing,
    Gain { id: i64, g: f64 },
    Delay { id: i64, tau_s: f64 },
}

/// Diagnose `level` ("L1" or "L2") of the independent data with `inject` applied.
fn run(dir: &Path, level: &str, inject: Inject) -> DiagnoseLevel {
    let study_src = root().join("studies/closed_loop_virtual_td.toml");
    let mut text = std::fs::read_to_string(&study_src).unwrap().replace(
        "levels = [\"L1\", \"L2\"]",
        &format!("levels = [\"{level}\"]"),
    );
    let k = &level[1..];
    let original = root().join(format!("studies/data/virtual/model4_td/level{k}.uff"));
    let tag = match &inject {
        Inject::Nothing => "null".to_string(),
        Inject::Gain { id, .. } => format!("gain_ch{id}"),
        Inject::Delay { id, .. } => format!("delay_ch{id}"),
    };
    let data = dir.join(format!("{tag}_{level}.uff"));
    let mut uff = read_uff(&original).unwrap();
    let mut touched = 0;
    for d in uff.datasets.iter_mut() {
        // func type 4: the FRFs (6: coherences, unchanged by a gain or a delay).
        let factor = |f: f64| match inject {
            Inject::Gain { id, g } if d.rsp_node == id => Some(C64::new(1.0 + g, 0.0)),
            Inject::Delay { id, tau_s } if d.rsp_node == id => Some(C64::from_polar(
                1.0,
                -2.0 * std::f64::consts::PI * f * tau_s,
            )),
            _ => None,
        };
        if d.func_type != 4 {
            continue;
        }
        let x = d.x.clone();
        let rsp = d.rsp_node;
        let scaled: Option<Vec<C64>> = match &d.values {
            Ordinate::Complex(v) => x
                .iter()
                .zip(v)
                .map(|(&f, &h)| factor(f).map(|c| c * h))
                .collect(),
            Ordinate::Real(_) => panic!("channel {rsp}: the FRF is not complex"),
        };
        if let Some(v) = scaled {
            d.values = Ordinate::Complex(v);
            touched += 1;
        }
    }
    let expected = usize::from(!matches!(inject, Inject::Nothing));
    assert_eq!(touched, expected, "{tag}: FRF datasets changed");
    write_uff(&data, &uff.datasets, false).unwrap();
    // The level's data are the copy; the other level's file and the truth stay where they are.
    text = text
        .replace(
            &format!("\"data/virtual/model4_td/level{k}.uff\""),
            &format!("\"{}\"", data.display()),
        )
        .replace(
            "\"data/virtual/",
            &format!("\"{}/", root().join("studies/data/virtual").display()),
        );
    let study_path = dir.join(format!("{tag}_{level}.toml"));
    std::fs::write(&study_path, &text).unwrap();
    let mut study = rfmlab::study::parse_str(&text, &study_path).unwrap();
    study.output_dir = dir.join(format!("{tag}_{level}_out"));
    // The suite's shared ROMs of the study (crate::shared_rom_cache).
    shared_rom_cache::share(dir);
    let s = {
        let _one_at_a_time = shared_rom_cache::lock();
        diagnose_study(&study, None, &params_of(&study)).unwrap()
    };
    let l = s.levels.into_iter().next().unwrap();
    eprintln!(
        "independent {tag} {level}: {}; chi2 {:.3} -> {:.3}; ranking {:?}; loop {:.0} s",
        l.conclusion,
        l.chi2_normalised_before,
        l.chi2_normalised_after,
        &l.first_ranking[..l.first_ranking.len().min(4)],
        l.loop_seconds
    );
    for p in &l.parameters {
        eprintln!(
            "  {}: {:.6e} +- {:.2e} (truth {:?})",
            p.name, p.after, p.after_sd, p.truth
        );
    }
    l
}

/// The null criteria: nothing accepted, every parameter's truth read and within 3 sds,
/// chi-square at most 1.2.
fn null_failures(l: &DiagnoseLevel) -> Vec<String> {
    let mut f = Vec::new();
    if !l.accepted.is_empty() {
        f.push(format!("accepted {:?}", l.accepted));
    }
    if l.status != "nothing_missing" {
        f.push(format!("status {}: {}", l.status, l.verdict.sentence));
    }
    if l.parameters.len() != 4 || l.parameters.iter().any(|p| p.truth.is_none()) {
        f.push("the independent truth.json was not read for all four parameters".into());
    }
    f.extend(
        judge(l, "", false, None, 1.2)
            .into_iter()
            .filter(|m| m != "nothing accepted"),
    );
    f
}

#[test]
fn independent_null_data_at_l1_accept_nothing_and_recover_the_truth() {
    null_data_accept_nothing_at(&["L1"]);
}

#[test]
#[ignore = "slow: the closed loop on the independent null data at L1 and L2, 52 s in release; run with --ignored"]
fn independent_null_data_at_both_levels_accept_nothing_and_recover_the_truth() {
    null_data_accept_nothing_at(&["L1", "L2"]);
}

/// The null criteria ([`null_failures`]) at each of `levels`.
fn null_data_accept_nothing_at(levels: &[&str]) {
    let dir = tempfile::tempdir().unwrap();
    let mut failures = Vec::new();
    for level in levels {
        let l = run(dir.path(), level, Inject::Nothing);
        failures.extend(
            null_failures(&l)
                .into_iter()
                .map(|m| format!("{level}: {m}")),
        );
    }
    assert!(failures.is_empty(), "failures:\n{}", failures.join("\n"));
}

/// A 4 % gain on channel 3.
#[test]
fn independent_data_with_a_channel_error_name_it() {
    channel_errors_are_named(vec![(Inject::Gain { id: 3, g: 0.04 }, "gain_ch3", 0.04)]);
}

/// The gain and a 50 us delay on channel 4.
#[test]
#[ignore = "slow: the closed loop on the independent L1 data twice, with a gain and with a delay, 70 s in release; run with --ignored"]
fn independent_data_with_each_channel_error_name_it() {
    channel_errors_are_named(vec![
        (Inject::Gain { id: 3, g: 0.04 }, "gain_ch3", 0.04),
        (
            Inject::Delay {
                id: 4,
                tau_s: 50e-6,
            },
            "delay_ch4",
            50e-6,
        ),
    ]);
}

/// Each of `cases` (injection, expected name, size) applied to the L1 data: `explained` with
/// the injected effect named first and sized ([`judge`]).
fn channel_errors_are_named(cases: Vec<(Inject, &str, f64)>) {
    let dir = tempfile::tempdir().unwrap();
    let mut failures = Vec::new();
    for (inject, name, size) in cases {
        let l = run(dir.path(), "L1", inject);
        if l.parameters.iter().take(4).any(|p| p.truth.is_none()) {
            failures.push(format!("{name}: the truth was not read"));
        }
        if l.status != "explained" {
            failures.push(format!(
                "{name}: status {}: {}",
                l.status, l.verdict.sentence
            ));
        }
        failures.extend(
            judge(&l, name, false, Some(size), 1.2)
                .into_iter()
                .map(|m| format!("{name}: {m}")),
        );
    }
    assert!(failures.is_empty(), "failures:\n{}", failures.join("\n"));
}
