//! The closed loop as a stage of the run (`studies/closed_loop_td.toml`: time-domain data with
//! an undeclared 12 g sensor mass at point 4, `[closed_loop]`, MAP only): in memory the loop
//! names the mass first, on the run's own engine (one ROM built), and `report::write` puts
//! its tables (the verdict among them), markdown and report section into the one results
//! folder, listed in the manifest with the ROM counter, the report's first line giving the
//! loop's status per level; no temporary or old folder is left beside it. The plan that runs
//! is the study's with its loop switched off and the loop added after planning (as Python's
//! `run(closed_loop=True)` does), so the mass at point 4, away from the drive point, is found
//! only if the run gives the loop's likelihood every measured point.

use rfmlab::pipeline::LikelihoodInputs;
use std::path::Path;

#[test]
fn the_closed_loop_runs_inside_the_run_and_is_written_in_the_same_swap() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let study = rfmlab::Study::load(root.join("studies/closed_loop_td.toml")).unwrap();
    let plan = study.plan().unwrap();
    assert!(plan.closed_loop.is_some(), "[closed_loop] makes a stage");
    assert_eq!(
        plan.likelihood_inputs(),
        Some(LikelihoodInputs::EveryMeasuredPoint),
        "the loop's candidate masses need every measured point"
    );
    // The loop added to a plan after planning, as Python's `run(closed_loop=True)` does on a
    // study whose loop is off: the run must still give the likelihood every measured point,
    // or the loop has no mass candidate away from the drive point.
    let mut off = study.clone();
    off.closed_loop.as_mut().unwrap().enabled = false;
    let mut plan = off.plan().unwrap();
    assert!(plan.closed_loop.is_none());
    assert_eq!(plan.likelihood_inputs(), Some(LikelihoodInputs::Excitation));
    plan.closed_loop = Some(rfmlab::diagnose::params_of(&study));
    assert_eq!(
        plan.likelihood_inputs(),
        Some(LikelihoodInputs::EveryMeasuredPoint)
    );
    plan.figures = false;
    // The suite's ROM cache: the ROM is a fixture here; the counters say the loop adds none.
    let mut ex = crate::shared_rom_cache::executor();
    let results = rfmlab::pipeline::run(&plan, &mut ex).unwrap();
    crate::shared_rom_cache::assert_one_rom(
        &results,
        "the loop runs on the run's ROM, built or read from the cache",
    );
    let outcome = results.closed_loop().expect("the loop ran");
    let l = &outcome.summary.levels[0];
    let (name, _, size, sd) = l.accepted.first().expect("an effect accepted");
    assert_eq!(name, "mass_pt4", "first accepted: {:?}", l.accepted);
    assert!(
        (size - 0.012).abs() < 0.15 * 0.012 && (size - 0.012).abs() < 1.96 * sd,
        "mass {size} +- {sd} kg against the 12 g simulated"
    );
    for t in [
        "closed_loop/candidates",
        "closed_loop/residuals",
        "closed_loop/verdict",
    ] {
        assert!(
            results.table(t).is_some(),
            "{t} in {:?}",
            results.table_names()
        );
    }

    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("closed_loop_td");
    // A temporary folder of an earlier run that was killed (its process is gone).
    std::fs::create_dir(
        dir.path()
            .join(format!("closed_loop_td.tmp-{}", u32::MAX - 1)),
    )
    .unwrap();
    rfmlab::report::write(&results, &out).unwrap();
    // Twice: the second write replaces the first as a whole.
    let written = rfmlab::report::write(&results, &out).unwrap();
    assert!(written
        .files
        .iter()
        .any(|f| f == "closed_loop/closed_loop.md"));
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("manifest.json")).unwrap()).unwrap();
    assert_eq!(
        manifest["counters"]["rom builds"].as_u64().unwrap()
            + manifest["counters"]["rom cache loads"].as_u64().unwrap(),
        1
    );
    let files: Vec<&str> = manifest["files"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f["name"].as_str().unwrap())
        .collect();
    assert!(
        files.contains(&"closed_loop/candidates.parquet"),
        "{files:?}"
    );
    assert!(manifest["timings"]
        .as_array()
        .unwrap()
        .iter()
        .any(|t| t["step"] == "closed loop"));
    let report = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(report.contains("## Closed loop"), "report section");
    // The report's first line gives the loop's status per level, as computed in memory.
    let first = report.lines().next().unwrap();
    assert!(
        first.contains(&format!("closed loop {} `{}`", l.level, l.status)),
        "{first}"
    );
    let verdict = results.table("closed_loop/verdict").unwrap();
    let status = verdict.column("status").unwrap().str().unwrap().get(0);
    assert_eq!(status, Some(l.status.as_str()));
    let names: Vec<String> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(
        names,
        vec!["closed_loop_td".to_string()],
        "stray: {names:?}"
    );
}
