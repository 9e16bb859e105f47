//! Acceptance of the closed loop on TIME-DOMAIN data: each case of
//! studies/data/closed_loop/cases/ is simulated by `rfmlab simulate` (time-domain records,
//! Welch H1, level L1) into a temporary folder and diagnosed with the settings of
//! studies/closed_loop_td.toml (Model 4, coherence noise with the leakage channel correlation,
//! `[closed_loop]`). Per case the loop must
//! * name the injected effect first (type and location),
//! * identify its size within 15 % and within its 95 % interval,
//! * bring the adhesive's parameters back within 3 posterior sds of the truth,
//! * leave a normalised chi-square at most max(1.2, 1.1 x the clean case's), the clean case's
//!   being the leakage-limited value of time-domain data without any effect (measured here).
//!
//! The fractional-law case has no size: there the first accepted candidate must be the
//! alternative law (type "alternative_law", the fractional Zener replacing Model 4), its
//! parameters within 3 sds of the simulated law's and the chi-square criterion holds.
//! Null data (no effect): nothing accepted in at least 95 % of 20 seeds.
//!
//! The default suite runs one case (12 g at point 4, after the clean case) and one null seed.
//! Ignored tests run the rest (`cargo test --release --test suite -- --ignored NAME`):
//! * `time_domain_every_case_names_the_injected_effect`: every case of [`CASES`];
//! * `time_domain_null_data_accept_nothing_in_19_of_20_seeds`: null seeds 1-20 (with the
//!   cases, about an hour on 2 busy cores);
//! * `time_domain_mesh_error_is_explained_with_every_default_candidate`: the mesh-error case
//!   with every default candidate in the first pass (about 4 minutes);
//! * `time_domain_three_direction_masses_are_explained_at_every_point` (about 8 minutes);
//! * `time_domain_term_cases_name_the_injected_effect`: the cases whose candidates need the
//!   term ROM (opt-in in `[closed_loop] candidates`: a degraded bond strip at the block's inner
//!   end, an adherend structural loss factor), with every candidate type named.

use crate::shared_rom_cache;
use rfmlab::diagnose::{diagnose_study, params_of, DiagnoseLevel};
use std::path::{Path, PathBuf};
use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_rfmlab");

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Simulate case `name` (seed replaced by `seed` when given) in `dir` and diagnose it.
fn run_case(dir: &Path, name: &str, seed: Option<u64>) -> DiagnoseLevel {
    run_case_with(dir, name, seed, None)
}

/// [`run_case`] with the study's `[closed_loop] candidates` replaced by `candidates` (TOML).
fn run_case_with(
    dir: &Path,
    name: &str,
    seed: Option<u64>,
    candidates: Option<&str>,
) -> DiagnoseLevel {
    let (tag, study_text) = simulate_case(dir, name, seed, |e| e);
    diagnose_case(dir, &tag, &study_text, name, seed, candidates)
}

/// The first level of the diagnosis of `study_text` (the case `name` simulated under `tag`) with
/// `[closed_loop] candidates` replaced by `candidates` (TOML; `None`: the study's).
fn diagnose_case(
    dir: &Path,
    tag: &str,
    study_text: &str,
    name: &str,
    seed: Option<u64>,
    candidates: Option<&str>,
) -> DiagnoseLevel {
    let study_text = match candidates {
        Some(c) => {
            let line = study_text
                .lines()
                .find(|l| l.starts_with("candidates = "))
                .unwrap()
                .to_string();
            study_text.replacen(&line, &format!("candidates = {c}"), 1)
        }
        None => study_text.to_string(),
    };
    let study_path = dir.join(format!("{tag}_study.toml"));
    std::fs::write(&study_path, &study_text).unwrap();
    let mut study = rfmlab::study::parse_str(&study_text, &study_path).unwrap();
    study.output_dir = dir.join(format!("{tag}_out"));
    let s = diagnose(dir, &study);
    let l = s.levels.into_iter().next().unwrap();
    eprintln!(
        "{name} (seed {seed:?}): `{}` {}; chi2 {:.3} -> {:.3}; ranking {:?}; loop {:.0} s",
        l.status,
        l.conclusion,
        l.chi2_normalised_before,
        l.chi2_normalised_after,
        &l.first_ranking[..l.first_ranking.len().min(4)],
        l.loop_seconds
    );
    l
}

/// [`diagnose_study`] of `study` (its results folder in `dir`) on the suite's shared ROMs of
/// the study ([`crate::shared_rom_cache`]).
fn diagnose(dir: &Path, study: &rfmlab::Study) -> rfmlab::diagnose::DiagnoseSummary {
    shared_rom_cache::share(dir);
    let _one_at_a_time = shared_rom_cache::lock();
    diagnose_study(study, None, &params_of(study)).unwrap()
}

/// Simulate the case `name` (its experiment file edited by `edit`) into `dir` with
/// `rfmlab simulate`, and return the files' tag and studies/closed_loop_td.toml reading its
/// data and truth.
fn simulate_case(
    dir: &Path,
    name: &str,
    seed: Option<u64>,
    edit: impl Fn(String) -> String,
) -> (String, String) {
    let src = root().join(format!("studies/data/closed_loop/cases/td_{name}.toml"));
    let mut exp = edit(std::fs::read_to_string(&src).unwrap());
    if let Some(s) = seed {
        let line = exp
            .lines()
            .find(|l| l.starts_with("seed = "))
            .unwrap()
            .to_string();
        exp = exp.replacen(&line, &format!("seed = {s}"), 1);
    }
    let tag = format!("td_{name}_{}", seed.unwrap_or(0));
    exp = exp.replacen(
        &format!("output = \"td_{name}.uff\""),
        &format!("output = \"{tag}.uff\""),
        1,
    );
    let exp_path = dir.join(format!("{tag}.toml"));
    std::fs::write(&exp_path, exp).unwrap();
    let out = Command::new(BIN)
        .args(["--quiet", "simulate"])
        .arg(&exp_path)
        .env("CI", "1")
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "simulate {name}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let study = std::fs::read_to_string(root().join("studies/closed_loop_td.toml"))
        .unwrap()
        .replace(
            "data/closed_loop/td_mass_pt4_L1.uff",
            &dir.join(format!("{tag}_L1.uff")).display().to_string(),
        )
        .replace(
            "data/closed_loop/td_mass_pt4.truth.json",
            &dir.join(format!("{tag}.truth.json")).display().to_string(),
        );
    (tag, study)
}

/// A declared effect with matrices of its own in a run (not the loop): the study declares the
/// adherend's structural loss factor free, and `Study -> plan -> pipeline::run` infers it on the
/// term ROM of the declared effect (a run once failed here: its engine had no term for it).
/// Frequency-domain data without an estimator, so the MAP runs on the measured lines.
#[test]
fn declared_adherend_damping_is_inferred_by_the_run() {
    let dir = tempfile::tempdir().unwrap();
    let (_, text) = simulate_case(dir.path(), "beam_damping", None, |e| {
        e.replace("mode = \"time\"", "mode = \"frequency\"")
    });
    let start = text.find("[measurements.estimator]").unwrap();
    let end = start + text[start..].find("[[measurements.levels]]").unwrap();
    let text = format!("{}{}", &text[..start], &text[end..])
        .replace("[closed_loop]\nenabled = true", "[closed_loop]\nenabled = false")
        .replace("[inference.map]\nstarts = 4", "[inference.map]\nstarts = 0")
        .replace(
            "[measurements]",
            "[[structure.effects]]\ntype = \"adherend_damping\"\nvalue = 0.001\nfree = true\n\n[measurements]",
        );
    let path = dir.path().join("declared_damping.toml");
    std::fs::write(&path, &text).unwrap();
    let mut study = rfmlab::study::parse_str(&text, &path).unwrap();
    study.output_dir = dir.path().join("declared_damping_out");
    let plan = study.plan().unwrap();
    assert!(plan.declared_terms.is_some());
    let results = rfmlab::pipeline::run(&plan, &mut crate::shared_rom_cache::executor()).unwrap();
    let post = &results.level("L1").unwrap().posteriors[0];
    let k = post
        .names
        .iter()
        .position(|n| n == "adherend_damping")
        .expect("the declared effect is a parameter of the posterior");
    let (g, sd) = (post.map.map_physical[k], post.map.laplace.sd_physical()[k]);
    eprintln!("declared adherend damping: {g:.4e} +- {sd:.1e} (truth 2e-3)");
    assert!((g - 2e-3).abs() <= 0.15 * 2e-3, "{g:e}");
    assert!((g - 2e-3).abs() <= 4.0 * sd, "{g:e} +- {sd:e}");
}

/// Check one case against the acceptance criteria; returns the failures (empty: passed).
pub(crate) fn judge(
    l: &DiagnoseLevel,
    expected: &str,
    kind_only: bool,
    size: Option<f64>,
    chi2_limit: f64,
) -> Vec<String> {
    let mut f = Vec::new();
    match l.accepted.first() {
        None => f.push("nothing accepted".to_string()),
        Some((n, k, v, sd)) => {
            let named = if kind_only {
                k == expected
            } else {
                n == expected
            };
            if !named {
                f.push(format!("first accepted {n} ({k}), expected {expected}"));
            } else if let Some(t) = size {
                if (v - t).abs() > 0.15 * t.abs() {
                    f.push(format!("size {v:.4e} not within 15 % of {t:.4e}"));
                }
                if (v - t).abs() > 1.96 * sd {
                    f.push(format!(
                        "size {v:.4e} +- {sd:.2e}: truth {t:.4e} outside its 95 % interval"
                    ));
                }
            }
        }
    }
    for p in &l.parameters {
        if let Some(t) = p.truth {
            if (p.after - t).abs() > 3.0 * p.after_sd {
                f.push(format!(
                    "{}: {:.4e} +- {:.2e}, truth {t:.4e} (> 3 sd)",
                    p.name, p.after, p.after_sd
                ));
            }
        }
    }
    if !(l.chi2_normalised_after <= chi2_limit) {
        f.push(format!(
            "normalised chi-square after {:.3} > {chi2_limit:.3}",
            l.chi2_normalised_after
        ));
    }
    f
}

/// A time-domain case: (case, expected name or type, by type only, injected size).
type Case = (&'static str, &'static str, bool, Option<f64>);

/// Every case of studies/data/closed_loop/cases/ with an effect of the default candidates; the
/// default suite runs the first.
const CASES: [Case; 10] = [
    ("mass_pt4", "mass_pt4", false, Some(0.012)),
    ("mass_pt1", "mass_pt1", false, Some(0.012)),
    ("mass_pt2", "mass_pt2", false, Some(0.012)),
    ("mass_pt3", "mass_pt3", false, Some(0.012)),
    ("mass6g_pt3", "mass_pt3", false, Some(0.006)),
    ("beam4", "beam_modulus", false, Some(0.04)),
    ("gain_ch3", "gain_ch3", false, Some(0.04)),
    ("delay_ch4", "delay_ch4", false, Some(50e-6)),
    ("shaker", "shaker_mass", false, Some(0.02)),
    ("fractional", "alternative_law", true, None),
];

/// The clean case accepts nothing and sets the chi-square limit; each of `cases` must then
/// meet the acceptance criteria ([`judge`]).
fn cases_name_the_injected_effect(cases: &[Case]) {
    let dir = tempfile::tempdir().unwrap();
    let clean = run_case(dir.path(), "clean", None);
    assert!(
        clean.accepted.is_empty(),
        "clean data: accepted {:?}",
        clean.accepted
    );
    let limit = 1.2f64.max(1.1 * clean.chi2_normalised_after);
    let mut failures = Vec::new();
    for (case, expected, kind_only, size) in cases {
        let l = run_case(dir.path(), case, None);
        for m in judge(&l, expected, *kind_only, *size, limit) {
            failures.push(format!("{case}: {m}"));
        }
    }
    assert!(failures.is_empty(), "failures:\n{}", failures.join("\n"));
}

/// The clean case and the 12 g mass at point 4 (the first of [`CASES`]). The suite runs the
/// same path (a measured-direction mass, then the three-direction pass) on the independent
/// `mass3d_td` data (`closed_loop_verdict.rs`) and the mass example inside a run
/// (`pipeline_closed_loop.rs`).
#[test]
#[ignore = "slow: 80 s in the test profile; the suite runs the same path on independent data; run with --ignored"]
fn time_domain_mass_pt4_case_names_the_injected_effect() {
    cases_name_the_injected_effect(&CASES[..1]);
}

/// Every case of [`CASES`]: masses at each point, a 6 g mass, the beam modulus, a gain, a
/// delay, the shaker and the fractional law.
#[test]
#[ignore = "slow: the clean case and 10 time-domain cases, each simulated and diagnosed; not measured alone (with the 20 null seeds about an hour on 2 busy cores); run with --ignored"]
fn time_domain_every_case_names_the_injected_effect() {
    cases_name_the_injected_effect(&CASES);
}

/// A mass on a spring at the drive point (20 g on 2e5 N/m), simulated as one more DOF of the
/// FE model: the loop names `resonator_pt2` first, within 15 % and its interval, and the
/// adhesive's parameters hold the truth.
/// The suite names a resonator at the drive point on the dense chain
/// (`resonator::the_loop_names_the_resonator_at_the_drive_point`).
#[test]
#[ignore = "slow: 57 s in the test profile; the suite names the drive-point resonator on the dense chain; run with --ignored"]
fn time_domain_resonator_at_the_drive_point_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let l = run_case(dir.path(), "resonator_pt2", None);
    for (n, _, v, sd) in &l.accepted {
        eprintln!("accepted {n} = {v:.5e} +- {sd:.1e}");
    }
    eprintln!("status {}; confounded {:?}", l.status, l.confounded);
    let failures = judge(&l, "resonator_pt2", false, Some(0.020), 1.2);
    assert!(failures.is_empty(), "failures:\n{}", failures.join("\n"));
    assert_eq!(l.accepted.len(), 1, "accepted {:?}", l.accepted);
    assert_eq!(l.status, "explained", "{}", l.conclusion);
}

/// The meshes of a discretisation case: the study's element size and the data's, which is
/// the study's refined twice per direction (the discretisation candidate's refined mesh).
#[derive(Clone, Copy)]
struct Meshes {
    study_m: f64,
    data_m: f64,
}

/// The acceptance case: the study's 5 mm mesh, data from 2.5 mm (`mesh_2p5mm`).
const MESHES_5_MM: Meshes = Meshes {
    study_m: 0.005,
    data_m: 0.0025,
};
/// The same case one refinement coarser: a 10 mm study, data from 5 mm.
const MESHES_10_MM: Meshes = Meshes {
    study_m: 0.010,
    data_m: 0.005,
};

/// `text` with its `element_size = ` line set to `h` (m).
fn with_element_size(text: &str, h: f64) -> String {
    let line = text
        .lines()
        .find(|l| l.starts_with("element_size = "))
        .expect("an element_size line")
        .to_string();
    text.replacen(&line, &format!("element_size = {h}"), 1)
}

/// The FE model's own discretisation error: data simulated on a mesh refined twice per
/// direction, identified on the study's coarser mesh (on 5 mm against 2.5 mm the modes sit
/// about 1.6 % high). No effect of the library takes that shape: the first pass ends
/// `unexplained`, then the discretisation candidate re-evaluates the model on the mesh refined
/// twice per direction. The level must end `explained` with `discretisation` the only accepted
/// effect (sized by the refined element size), the adhesive's parameters within 3 sd of the
/// truth, and the comparison in `mesh.parquet`. Here the first pass offers only the gains (the
/// refined mesh is tried the same way after any unexplained end); the ignored
/// `time_domain_mesh_error_is_explained_with_every_default_candidate` offers every default
/// candidate.
///
/// The mesh allowance runs after it in the same folder, so that the two meshes' reduced bases
/// are built once. The suite runs both on a 10 mm study against 5 mm data (the refined mesh's
/// ROM is the 5 mm joint's, 10 248 DOFs); the ignored `..._on_the_5_mm_study` runs the
/// acceptance case itself, a 5 mm study against 2.5 mm data (67 224 DOFs: its two ROMs take
/// about 2 minutes).
#[test]
fn time_domain_mesh_error_is_explained_and_the_mesh_allowance_widens_the_sds() {
    mesh_error_then_allowance(MESHES_10_MM);
}

/// [`time_domain_mesh_error_is_explained_and_the_mesh_allowance_widens_the_sds`] on the study's
/// own 5 mm mesh, against data from 2.5 mm.
#[test]
#[ignore = "slow: the 5 mm study against 2.5 mm data, 160-188 s alone in the test profile (two ROMs of the 67 224-DOF mesh); the suite runs the case one refinement coarser; run with --ignored"]
fn time_domain_mesh_error_is_explained_and_the_mesh_allowance_widens_the_sds_on_the_5_mm_study() {
    mesh_error_then_allowance(MESHES_5_MM);
}

/// The mesh-error case on `meshes` with the gains and the refined mesh as candidates, then the
/// mesh allowance on null data in the same folder (its reduced bases built once).
fn mesh_error_then_allowance(meshes: Meshes) {
    let dir = tempfile::tempdir().unwrap();
    mesh_error_is_explained_by_the_refined_mesh(
        dir.path(),
        meshes,
        Some("[\"gain\", \"discretisation\"]"),
    );
    mesh_allowance_widens_the_adhesive_sds_by_the_mesh_change(dir.path(), meshes);
}

/// The mesh error with every default candidate in the first pass (the study's `"all"`; about 4
/// minutes: the first pass accepts a delay, a beam factor and a gain on the way).
#[test]
#[ignore = "slow: the mesh-error case with every default candidate, 135 s in release; run with --ignored"]
fn time_domain_mesh_error_is_explained_with_every_default_candidate() {
    let dir = tempfile::tempdir().unwrap();
    mesh_error_is_explained_by_the_refined_mesh(dir.path(), MESHES_5_MM, None);
}

/// The `mesh_2p5mm` case with its data mesh and the study's from `meshes` and
/// `[closed_loop] candidates` replaced by `candidates` (TOML; `None`: the study's, every
/// default candidate).
fn mesh_error_is_explained_by_the_refined_mesh(
    dir: &Path,
    meshes: Meshes,
    candidates: Option<&str>,
) {
    let (tag, text) = simulate_case(dir, "mesh_2p5mm", None, |e| {
        with_element_size(&e, meshes.data_m)
    });
    let text = with_element_size(&text, meshes.study_m);
    let l = diagnose_case(dir, &tag, &text, "mesh_2p5mm", None, candidates);
    eprintln!("status {}: {}", l.status, l.verdict.sentence);
    assert_eq!(l.status, "explained", "{}", l.conclusion);
    let names: Vec<&str> = l.accepted.iter().map(|a| a.0.as_str()).collect();
    assert_eq!(names, ["discretisation"], "{}", l.conclusion);
    let failures = judge(&l, "discretisation", false, Some(meshes.data_m), 1.2);
    assert!(failures.is_empty(), "failures:\n{}", failures.join("\n"));
    let mesh = dir.join(format!("{tag}_out.diagnose/mesh.parquet"));
    assert!(mesh.is_file(), "{} missing", mesh.display());
}

/// `[closed_loop] mesh_allowance = true` on null data: the level stays `nothing_missing`, the
/// refined mesh is compared but not taken (nothing to explain), and every Model 4 parameter's
/// reported sd is its posterior sd widened by the Richardson estimate of its discretisation
/// error on the study's mesh, `sqrt(sd^2 + b^2)` with `b = |d| 4/3` (`d` the change between the two
/// meshes' starting fits, read from `mesh.parquet`), which covers the truth of a model that
/// converges with the mesh.
fn mesh_allowance_widens_the_adhesive_sds_by_the_mesh_change(dir: &Path, meshes: Meshes) {
    let (tag, text) = simulate_case(dir, "clean", None, |e| {
        with_element_size(&e, meshes.study_m)
    });
    let text = with_element_size(&text, meshes.study_m).replace(
        "candidates = \"all\"",
        "candidates = [\"gain\"]\nmesh_allowance = true",
    );
    assert!(text.contains("mesh_allowance = true"));
    let path = dir.join(format!("{tag}_study.toml"));
    std::fs::write(&path, &text).unwrap();
    let mut study = rfmlab::study::parse_str(&text, &path).unwrap();
    study.output_dir = dir.join(format!("{tag}_out"));
    let s = diagnose(dir, &study);
    let l = &s.levels[0];
    assert_eq!(l.status, "nothing_missing", "{}", l.conclusion);
    let md = std::fs::read_to_string(s.output_dir.join("closed_loop.md")).unwrap();
    assert!(md.contains("### Mesh allowance"), "{md}");
    use rfmlab::output::ColumnData;
    let mesh = rfmlab::output::Table::read_parquet(s.output_dir.join("mesh.parquet")).unwrap();
    let f = |n: &str| -> Vec<f64> {
        match mesh.column(n) {
            Some(ColumnData::F64(v)) => v.clone(),
            Some(ColumnData::OptF64(v)) => v.iter().map(|x| x.unwrap_or(f64::NAN)).collect(),
            other => panic!("{n}: {other:?}"),
        }
    };
    let Some(ColumnData::Str(q)) = mesh.column("quantity") else {
        panic!("quantity column");
    };
    let (a, b, sd_a) = (f("study_mesh"), f("refined_mesh"), f("study_mesh_sd"));
    for i in 0..mesh.n_rows() {
        let name = &q[i];
        let Some(p) = l.parameters.iter().find(|p| p.name == *name) else {
            continue;
        };
        let d = b[i] - a[i];
        let expected = sd_a[i].hypot(d.abs() * 4.0 / 3.0);
        eprintln!(
            "{name}: {:.5e} +- {:.2e} (posterior {:.2e}, mesh change {d:+.3e}), truth {:?}",
            p.after, p.after_sd, sd_a[i], p.truth
        );
        assert!(
            (p.after_sd - expected).abs() <= 1e-9 * expected,
            "{name}: sd {:e}, expected {expected:e}",
            p.after_sd
        );
        assert!(p.after_sd > 2.0 * sd_a[i], "{name}: not widened");
    }
}

/// A 12 g sensor whose inertia acts in x, y and z (`[[sensors]] directions = "xyz"`), at each
/// point in turn, with the default candidates: the first pass finds the measured-direction
/// mass, the second (every point's three directions in the model) must name `mass3_ptN` alone,
/// within 15 % and its interval, and end `explained` with the adhesive within 3 sd. Only with
/// `--ignored` (about 2 minutes per point in a release build; the default suite runs the
/// same path on the independent `mass3d_td` data, `closed_loop_verdict.rs`).
#[test]
#[ignore = "slow: about 2 minutes per point in a release build (8 minutes); run with --ignored"]
fn time_domain_three_direction_masses_are_explained_at_every_point() {
    let dir = tempfile::tempdir().unwrap();
    let mut failures = Vec::new();
    for k in 1..=4 {
        let case = format!("mass3_pt{k}");
        let l = run_case(dir.path(), &case, None);
        if l.status != "explained" {
            failures.push(format!("{case}: status {}: {}", l.status, l.conclusion));
        }
        if l.accepted.len() != 1 {
            failures.push(format!("{case}: accepted {:?}", l.accepted));
        }
        for m in judge(&l, &case, false, Some(0.012), 1.2) {
            failures.push(format!("{case}: {m}"));
        }
    }
    assert!(failures.is_empty(), "failures:\n{}", failures.join("\n"));
}

/// The simulator's compliant base (springs of 3.0e10 N/m^3 normal and tangential) with a 12 g
/// sensor acting in x, y and z at point 4 (`td_springs_mass3_pt4`, the joint of the
/// independent `springs_mass3_td`), default candidates: the first pass accepts the
/// measured-direction mass and the springs, the second the three-direction mass (a term of the
/// springs' term ROM) and the springs, and the level ends `confounded` or `explained` with
/// every truth inside what is reported. Only with `--ignored` (the independent data's twin is
/// `closed_loop_verdict::independent_compliant_base_with_a_three_direction_sensor_covers_the_truth`).
#[test]
#[ignore = "slow: both passes of the loop on the term ROMs of the springs (and of the sensor), 1291 s in release beside another loop and a build; run with --ignored"]
fn time_domain_compliant_base_with_a_three_direction_sensor_covers_the_truth() {
    let dir = tempfile::tempdir().unwrap();
    let l = run_case(dir.path(), "springs_mass3_pt4", None);
    crate::closed_loop_verdict::assert_every_truth_inside(
        &l,
        &[("mass3_pt4", 0.012), ("base_springs_iso", 1.0 / 3.0e10)],
    );
}

/// Null data (the clean case) at each of `seeds`: effects accepted on at most 5 % of them.
fn null_data_accept_nothing(seeds: &[u64]) {
    let dir = tempfile::tempdir().unwrap();
    let accepted = seeds
        .iter()
        .filter(|&&s| !run_case(dir.path(), "clean", Some(s)).accepted.is_empty())
        .count();
    assert!(
        (accepted as f64) <= 0.05 * seeds.len() as f64,
        "effects accepted on {accepted} of {} null seeds",
        seeds.len()
    );
}

/// Null data at seed 7: nothing accepted. Only with `--ignored`: the suite runs the loop on the
/// independent time-domain null data with the same candidates
/// (`closed_loop_independent::independent_null_data_at_l1_accept_nothing_and_recover_the_truth`)
/// and on this simulator's dense null data (`closed_loop_verdict::dense_null_data_are_nothing_missing`).
#[test]
#[ignore = "slow: 62 s alone (94 CPU-s) in the test profile; the suite runs the null case on the independent time-domain data; run with --ignored"]
fn time_domain_null_data_accept_nothing() {
    null_data_accept_nothing(&[7]);
}

/// Null data at seeds 1-20: nothing accepted on at least 19.
#[test]
#[ignore = "slow: 20 null seeds, each simulated and diagnosed with the default candidates; not measured alone (with every case about an hour on 2 busy cores); run with --ignored"]
fn time_domain_null_data_accept_nothing_in_19_of_20_seeds() {
    null_data_accept_nothing(&(1..=20).collect::<Vec<u64>>());
}

/// The cases whose candidates need the term ROM (src/diagnose/terms.rs): a 10 mm strip at the
/// block's inner end (x = 40-50 mm) at 5 % modulus, and an adherend structural loss factor
/// g = 0.002, each with the default candidate types and its own opt-in type named (each
/// evaluation with a term is a dense LU of the term ROM per fine line). Only with `--ignored`; the chi-square limit is 1.2 (the clean case's 0.669 x 1.1
/// is below it).
#[test]
#[ignore = "slow: a dense LU of the term ROM per fine line per evaluation, 695 s in release beside other work; run with --ignored"]
fn time_domain_term_cases_name_the_injected_effect() {
    let dir = tempfile::tempdir().unwrap();
    let defaults =
        "\"point_mass\", \"gain\", \"delay\", \"beam_modulus\", \"shaker\", \"maxwell_branch\"";
    let mut failures = Vec::new();
    for (case, extra, expected, size) in [
        ("bond_end", "degraded_bond", "bond_x40.0mm_w10.0mm", 0.95),
        (
            "beam_damping",
            "adherend_damping",
            "adherend_damping",
            0.002,
        ),
    ] {
        let candidates = format!("[{defaults}, \"{extra}\"]");
        let l = run_case_with(dir.path(), case, None, Some(&candidates));
        if let Some(f) = l.term_box_factor {
            eprintln!("{case}: MAP modulus vs the term ROM's box: factor {f:.3}");
        }
        for m in judge(&l, expected, false, Some(size), 1.2) {
            failures.push(format!("{case}: {m}"));
        }
    }
    assert!(failures.is_empty(), "failures:\n{}", failures.join("\n"));
}
