//! The closed loop's verdict (src/closed_loop/verdict.rs, null.rs, conclude.rs): a status per
//! level that cannot be wrong quietly.
//!
//! On the dense chain (rfmlab's own simulator, relative noise of known variance, the null
//! level from the noise model's own errors):
//! * null data: `nothing_missing`, the null level near 1 (the variances are exact);
//! * a 12 g mass at point 4: `explained`, the mass named and sized within 15 %;
//! * a beam modulus 4 % high with only channel candidates (gains and delays) offered: never
//!   `explained`; `unexplained` with the residual's excess, the accepted gains tentative and
//!   the law's parameters carrying a warning.
//!
//! On data made by INDEPENDENT code (../shared/data/virtual, Welch H1 of a scikit-fem model,
//! diagnosed with studies/closed_loop_virtual_td.toml; the null level from replicate Welch
//! experiments of the fitted model):
//! * model4_td (null): `nothing_missing` at both levels (L1 is also checked by default in
//!   tests/suite/closed_loop_independent.rs);
//! * support_td (a compliant base the study does not declare) with a candidates list without
//!   base springs: `unexplained`, never `explained` with a wrong effect (in the default suite);
//!   with the default candidates the loop runs again with the springs and ends `confounded`
//!   around the truth (ignored: minutes);
//! * mass3d_td (a 9 g mass at point 3 acting in x, y and z), default candidates: the
//!   measured-direction mass is found first and the loop runs again with the points' x, y and z
//!   directions; `explained` by `mass3_pt3` alone, sized within 15 % and its interval, every
//!   Model 4 parameter within 3 sd of the truth (in the default suite).
//!
//! The other independent cases are ignored tests, minutes each on 2 busy cores (`cargo test
//! --release --test suite -- --ignored closed_loop_verdict::independent`).

use crate::closed_loop::{lines, posterior, simulate, TRUTH};
use crate::common_data::data;
use crate::shared_rom_cache;
use crate::spring_model::measured_engine;
use rfmlab::closed_loop::conclude::conclude;
use rfmlab::closed_loop::null::{calibrate, Chain, NullParams};
use rfmlab::closed_loop::verdict::{Status, VerdictParams};
use rfmlab::closed_loop::{default_candidates, run_closed_loop, ClosedLoopParams};
use rfmlab::diagnose::{diagnose_study, params_of, DiagnoseLevel};
use rfmlab::forward::Effect;
use std::f64::consts::TAU;
use std::path::{Path, PathBuf};

/// Loop, null level (the noise model's own errors) and verdict on dense-chain data.
fn dense_verdict(
    effect: Option<(Effect, f64)>,
    candidates: &[Effect],
    seed: u64,
) -> (
    rfmlab::closed_loop::ClosedLoopResult,
    rfmlab::closed_loop::verdict::Verdict,
) {
    let eng = measured_engine();
    let (x, v) = simulate(&eng, effect, seed);
    let mut post = posterior(&eng, x, v);
    let start = post.unconstrained(&[TRUTH[0] * 1.2, TRUTH[1] * 0.8, TRUTH[2] * 1.2]);
    let params = ClosedLoopParams::default();
    let res = run_closed_loop(&mut post, &start, candidates, &params).unwrap();
    let null = calibrate(
        &post,
        &res.after.values,
        &Chain::NoiseModel,
        &[1, 2, 3, 4],
        &NullParams::default(),
    )
    .unwrap();
    let freq: Vec<f64> = lines().iter().map(|w| w / TAU).collect();
    let (res, v) = conclude(
        &mut post,
        res,
        &null,
        &freq,
        &[1, 2, 3, 4],
        &params,
        &VerdictParams::default(),
    )
    .unwrap();
    eprintln!(
        "{:?}: {} | null {:.3} +- {:.3}, threshold {:.3}",
        v.status, v.sentence, null.mean, null.sd, null.threshold
    );
    (res, v)
}

fn all_candidates() -> Vec<Effect> {
    default_candidates(&[1, 2, 3, 4], &[(0, 1), (1, 2), (2, 3), (3, 4)])
}

#[test]
fn dense_null_data_are_nothing_missing() {
    let (res, v) = dense_verdict(None, &all_candidates(), 7);
    assert_eq!(v.status, Status::NothingMissing, "{}", v.sentence);
    assert!(res.accepted.is_empty());
    // Exact variances: the null level of the normalised chi-square is 1 within its scatter
    // (sd sqrt(2 / 1280) = 0.04 per replicate, over 20 replicates 0.01).
    assert!(
        (v.null_mean - 1.0).abs() < 0.03,
        "null mean {}",
        v.null_mean
    );
    assert!(v.threshold > v.null_mean && v.threshold < 1.2);
    assert!(v.warning.is_none());
}

/// The false-alarm rate over noise seeds: null data must read `nothing_missing` in at least
/// 19 of 20 seeds (the threshold is calibrated for 1 %), with nothing accepted in any.
#[test]
fn dense_null_data_are_nothing_missing_in_19_of_20_seeds() {
    let mut statuses = Vec::new();
    for seed in 100..120 {
        let (res, v) = dense_verdict(None, &all_candidates(), seed);
        statuses.push((
            seed,
            v.status,
            res.accepted.len(),
            v.chi2_after,
            v.threshold,
        ));
    }
    let clean = statuses
        .iter()
        .filter(|(_, s, n, _, _)| *s == Status::NothingMissing && *n == 0)
        .count();
    eprintln!("nothing_missing in {clean} of 20 seeds: {statuses:?}");
    assert!(clean >= 19, "{statuses:?}");
}

#[test]
fn dense_mass_is_explained() {
    let (res, v) = dense_verdict(
        Some((Effect::PointMass { point: 3, id: 4 }, 0.012)),
        &all_candidates(),
        11,
    );
    assert_eq!(v.status, Status::Explained, "{}", v.sentence);
    assert_eq!(res.accepted.len(), 1, "{:?}", res.accepted);
    let (e, m, _) = &res.accepted[0];
    assert_eq!(e.name(), "mass_pt4");
    assert!((m - 0.012).abs() < 0.15 * 0.012, "mass {m}");
    assert!(v.chi2_after <= v.threshold);
}

#[test]
fn dense_effect_outside_the_candidates_is_unexplained() {
    // A beam 4 % stiffer shifts every beam mode; no gain or delay can reproduce it.
    let channel_only: Vec<Effect> = all_candidates()
        .into_iter()
        .filter(|e| matches!(e, Effect::Gain { .. } | Effect::Delay { .. }))
        .collect();
    let (res, v) = dense_verdict(Some((Effect::BeamModulus, 0.04)), &channel_only, 13);
    assert_eq!(v.status, Status::Unexplained, "{}", v.sentence);
    assert!(v.excess > 1.5, "excess {}", v.excess);
    assert!(v.warning.is_some());
    assert!(!v.bands.is_empty() && !v.channels.is_empty());
    // Whatever survived the drop-one check is tentative, and says so.
    assert_eq!(v.tentative.len(), res.accepted.len());
    assert!(v.sentence.starts_with("unexplained"));
}

/// Diagnose `level` of the independent case `case` (a folder of ../shared/data/virtual) with
/// studies/closed_loop_virtual_td.toml.
fn run_independent(dir: &Path, case: &str, level: &str) -> DiagnoseLevel {
    run_independent_with(dir, case, level, "\"all\"")
}

/// [`run_independent`] with `[closed_loop] candidates = <candidates>` (TOML).
fn run_independent_with(dir: &Path, case: &str, level: &str, candidates: &str) -> DiagnoseLevel {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    // The repository's own independent data first (studies/data/virtual), then the shared.
    let own = root.join(format!("studies/data/virtual/{case}"));
    let folder = if own.is_dir() {
        own
    } else {
        data(&format!("virtual/{case}"))
    };
    let text = std::fs::read_to_string(root.join("studies/closed_loop_virtual_td.toml"))
        .unwrap()
        .replace(
            "levels = [\"L1\", \"L2\"]",
            &format!("levels = [\"{level}\"]"),
        )
        .replace(
            "\"data/virtual/model4_td/",
            &format!("\"{}/", folder.display()),
        )
        .replace(
            "candidates = \"all\"",
            &format!("candidates = {candidates}"),
        );
    let path = dir.join(format!("{case}_{level}.toml"));
    std::fs::write(&path, &text).unwrap();
    let mut study = rfmlab::study::parse_str(&text, &path).unwrap();
    study.output_dir = dir.join(format!("{case}_{level}_out"));
    // The suite's shared ROMs of the study (crate::shared_rom_cache).
    shared_rom_cache::share(dir);
    let s = {
        let _one_at_a_time = shared_rom_cache::lock();
        diagnose_study(&study, None, &params_of(&study)).unwrap()
    };
    let l = s.levels.into_iter().next().unwrap();
    eprintln!(
        "{case} {level}: {} | {} | loop {:.0} s, null {:.1} s",
        l.status, l.verdict.sentence, l.loop_seconds, l.null.seconds
    );
    for p in &l.parameters {
        eprintln!(
            "  {}: {:.5e} +- {:.2e} (truth {:?})",
            p.name, p.after, p.after_sd, p.truth
        );
    }
    // The status is in the parquet output and in the report's first line.
    let md = std::fs::read_to_string(s.output_dir.join("closed_loop.md")).unwrap();
    let first = md.lines().next().unwrap();
    assert!(first.contains(&format!("`{}`", l.status)), "{first}");
    assert!(s.output_dir.join("verdict.parquet").is_file());
    l
}

/// Both levels of the independent null data (L1 alone runs in the default suite, in
/// tests/suite/closed_loop_independent.rs).
#[test]
#[ignore = "slow: the closed loop at both levels of the independent null data (minutes); run with --ignored"]
fn independent_null_data_are_nothing_missing() {
    let dir = tempfile::tempdir().unwrap();
    for level in ["L1", "L2"] {
        let l = run_independent(dir.path(), "model4_td", level);
        assert_eq!(
            l.status, "nothing_missing",
            "{level}: {}",
            l.verdict.sentence
        );
        assert!(l.null.threshold.is_finite() && l.null.false_alarm > 0.0);
        for p in &l.parameters {
            let t = p.truth.expect("truth read");
            assert!(
                (p.after - t).abs() <= 3.0 * p.after_sd,
                "{level} {}: {:.4e} +- {:.2e}, truth {t:.4e}",
                p.name,
                p.after,
                p.after_sd
            );
        }
    }
}

/// Whether `l` is `explained` with an effect other than `expected` (kind prefix of the name).
fn explained_wrongly(l: &DiagnoseLevel, expected: &[&str]) -> bool {
    l.status == "explained"
        && l.accepted
            .iter()
            .any(|(n, _, _, _)| !expected.iter().any(|e| n.starts_with(e)))
}

/// The independent compliant base (equal normal and tangential springs) with the default
/// candidates, base springs among them: both spring shapes are tried, the equal springs are
/// accepted and sized within their interval of the truth, and the level ends `confounded` with
/// every adhesive parameter's truth inside the reported range. Minutes (the two-shape term ROM,
/// built once and cached, and the loop on it): `cargo test --release --test suite -- --ignored
/// independent_compliant_base_with_base_springs`.
#[test]
#[ignore = "slow: the two-shape term ROM and the closed loop on it, 122 s in release with the term ROM cached; run with --ignored"]
fn independent_compliant_base_with_base_springs_is_confounded_around_the_truth() {
    let dir = tempfile::tempdir().unwrap();
    let l = run_independent_with(dir.path(), "support_td", "L1", "\"all\"");
    assert!(
        !explained_wrongly(&l, &["base_springs"]),
        "{}",
        l.verdict.sentence
    );
    assert_eq!(l.status, "confounded", "{}", l.verdict.sentence);
    // The truth's springs: 3.0e10 N/m^3 normal and tangential (the data's README).
    let truth = 1.0 / 3.0e10;
    let (name, _, size, sd) = &l.accepted[0];
    assert_eq!(name, "base_springs_iso");
    assert!((size - truth).abs() < 2.0 * sd, "{size:e} +- {sd:e}");
    let c = &l.verdict.confounded[0];
    assert!(
        c.size_range.0 <= truth && truth <= c.size_range.1,
        "{:?}",
        c.size_range
    );
    for (p, lo, hi) in &c.ranges {
        let t = l
            .parameters
            .iter()
            .find(|q| &q.name == p)
            .and_then(|q| q.truth)
            .unwrap();
        assert!(
            *lo <= t && t <= *hi,
            "{p}: truth {t:e} outside [{lo:e}, {hi:e}]"
        );
    }
}

/// Asserts that `l` ends `confounded` or `explained` with every truth inside what it reports:
/// each law parameter's truth inside its range over the confounded effect's plausible sizes
/// (else its size +- 2 sd), and each of `effects` (name, truth) accepted with its truth inside
/// the confounded effect's plausible sizes, its range over them, else its size +- 2 sd.
pub(crate) fn assert_every_truth_inside(l: &DiagnoseLevel, effects: &[(&str, f64)]) {
    assert!(
        l.status == "confounded" || l.status == "explained",
        "{}: {}",
        l.status,
        l.verdict.sentence
    );
    let confounded = l.verdict.confounded.first();
    let inside = |name: &str, t: f64, lo: f64, hi: f64| {
        assert!(
            lo <= t && t <= hi,
            "{name}: truth {t:e} outside [{lo:e}, {hi:e}] ({})",
            l.verdict.sentence
        );
    };
    for p in l.parameters.iter().filter(|p| p.truth.is_some()) {
        let t = p.truth.unwrap();
        let (lo, hi) = confounded
            .and_then(|c| c.ranges.iter().find(|r| r.0 == p.name))
            .map(|r| (r.1, r.2))
            .unwrap_or((p.after - 2.0 * p.after_sd, p.after + 2.0 * p.after_sd));
        inside(&p.name, t, lo, hi);
    }
    for &(name, t) in effects {
        let (_, _, size, sd) = l
            .accepted
            .iter()
            .find(|a| a.0 == name)
            .unwrap_or_else(|| panic!("{name} not accepted: {:?}", l.accepted));
        let (lo, hi) = match confounded {
            Some(c) if c.effect == name => c.size_range,
            Some(c) => c
                .effects
                .iter()
                .find(|r| r.0 == name)
                .map_or((size - 2.0 * sd, size + 2.0 * sd), |r| (r.1, r.2)),
            None => (size - 2.0 * sd, size + 2.0 * sd),
        };
        inside(name, t, lo, hi);
    }
}

/// The independent compliant base with a 12 g sensor acting in x, y and z at point 4
/// (`springs_mass3_td`, made by scikit-fem on the study's own mesh), default candidates: the
/// first pass accepts the measured-direction mass and the springs; the second tries the
/// three-direction mass as a term of the springs' term ROM in its place, accepts it and the
/// equal springs, and the level ends `confounded` with every truth inside what is reported
/// (the adhesive's parameters, the springs' compliance 1 / 3.0e10 m^3/N and the 12 g).
#[test]
#[ignore = "slow: both passes of the loop on the term ROMs of the springs (and of the sensor), about 5 minutes in release with the ROMs cached; run with --ignored"]
fn independent_compliant_base_with_a_three_direction_sensor_covers_the_truth() {
    let dir = tempfile::tempdir().unwrap();
    let l = run_independent_with(dir.path(), "springs_mass3_td", "L2", "\"all\"");
    assert_every_truth_inside(
        &l,
        &[("mass3_pt4", 0.012), ("base_springs_iso", 1.0 / 3.0e10)],
    );
}

/// Without base springs among the candidates (a list that leaves them out) the loop cannot explain the independent
/// compliant base's residual: it must say so (`unexplained`, with the excess over the null
/// level, where it is and a warning on the adhesive's parameters) rather than end `explained`
/// or `nothing_missing`.
#[test]
fn independent_compliant_base_is_unexplained_without_base_springs() {
    let dir = tempfile::tempdir().unwrap();
    let l = run_independent_with(
        dir.path(),
        "support_td",
        "L1",
        "[\"point_mass\", \"resonator\", \"gain\", \"delay\", \"beam_modulus\", \"shaker\", \"maxwell_branch\", \"alternative_law\"]",
    );
    assert!(
        !explained_wrongly(&l, &["base_springs"]),
        "explained with a wrong effect: {}",
        l.verdict.sentence
    );
    assert_eq!(l.status, "unexplained", "{}", l.verdict.sentence);
    assert!(l.verdict.excess > 1.5, "excess {}", l.verdict.excess);
    assert!(l.verdict.warning.is_some());
    assert!(!l.verdict.bands.is_empty() && !l.verdict.channels.is_empty());
    // The null level of Welch data of a correct model sits well below 1 (not a fixed
    // chi-square): the residual here is above the threshold, not above 1.
    assert!(l.null.mean < 1.0 && l.null.threshold < l.chi2_normalised_after);
}

#[test]
fn independent_three_direction_mass_is_explained_with_the_adhesive_at_its_truth() {
    let dir = tempfile::tempdir().unwrap();
    let l = run_independent_with(
        dir.path(),
        "mass3d_td",
        "L1",
        // the default candidates: the measured-direction mass is accepted first, and the loop
        // then runs again with every point's x, y and z directions
        "\"all\"",
    );
    assert_eq!(l.status, "explained", "{}", l.verdict.sentence);
    // the three-direction mass at point 3 alone, within 15 % of the 9 g and its interval
    assert_eq!(l.accepted.len(), 1, "{:?}", l.accepted);
    let (name, _, size, sd) = &l.accepted[0];
    assert_eq!(name, "mass3_pt3", "{}", l.verdict.sentence);
    assert!(
        (size - 0.009).abs() <= 0.15 * 0.009 && (size - 0.009).abs() <= 3.0 * sd,
        "mass3_pt3 = {size} +- {sd} kg (truth 9 g)"
    );
    // with the x and z inertia in the model, the adhesive's parameters are back at the truth
    // (the measured-direction mass alone leaves E0 and h 5-9 sd off)
    let law: Vec<_> = l.parameters.iter().filter(|p| p.truth.is_some()).collect();
    assert_eq!(law.len(), 4, "the four Model 4 truths are read");
    for p in law {
        let t = p.truth.unwrap();
        assert!(
            (p.after - t).abs() <= 3.0 * p.after_sd,
            "{}: {} +- {} (truth {t})",
            p.name,
            p.after,
            p.after_sd
        );
    }
}
