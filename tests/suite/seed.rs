//! The seed lives in the plan: `[study] seed` reaches the samplers, the MAP searches and the
//! closed loop's multistart searches and replicate experiments through [`rfmlab::pipeline::Plan`]
//! (the loop's searches were seeded with 0 whatever the study said). The same seed gives the
//! same results whatever the thread count; another seed gives other random streams.

use crate::inference_samplers::Gauss;
use rfmlab::inference::map::{find_map, MapResult};
use std::path::Path;

/// studies/closed_loop_td.toml (inference + closed loop) with `seed`, parsed, not run.
fn closed_loop_study(seed: u64) -> rfmlab::Study {
    let file = Path::new(env!("CARGO_MANIFEST_DIR")).join("studies/closed_loop_td.toml");
    let text =
        std::fs::read_to_string(&file)
            .unwrap()
            .replacen("seed = 1", &format!("seed = {seed}"), 1);
    rfmlab::study::parse_str(&text, &file).unwrap()
}

#[test]
fn the_plan_carries_the_study_seed_to_the_closed_loop() {
    for seed in [7, 8] {
        let study = closed_loop_study(seed);
        let plan = study.plan().unwrap();
        assert_eq!(plan.seed, seed);
        let cl = plan
            .closed_loop
            .as_ref()
            .expect("the study runs the closed loop");
        assert_eq!(cl.map.seed, seed, "the loop's multistart searches");
        let stage = plan.closed_loop_stage.as_ref().unwrap();
        assert_eq!(stage.null.seed, seed, "the loop's replicate experiments");
        // `rfmlab diagnose` makes the loop's settings the same way.
        assert_eq!(rfmlab::diagnose::params_of(&study).map.seed, seed);
    }
}

/// A 2-D Gaussian posterior: prior N(0, 2^2 I), likelihood N(x; (1, -1), I).
fn toy() -> Gauss {
    Gauss::new(
        vec![0.0, 0.0],
        vec![4.0, 0.0, 0.0, 4.0],
        vec![1.0, -1.0],
        vec![1.0, 0.0, 0.0, 1.0],
    )
}

fn in_pool<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> T {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
        .install(f)
}

fn design_starts(r: &MapResult) -> Vec<Vec<u64>> {
    r.starts
        .iter()
        .filter(|s| s.kind == "design")
        .map(|s| s.start_x.iter().map(|v| v.to_bits()).collect())
        .collect()
}

#[test]
fn the_loop_s_multistart_follows_the_seed_not_the_thread_count() {
    let search = |seed: u64, threads: usize| {
        let plan = closed_loop_study(seed).plan().unwrap();
        let map = plan.closed_loop.unwrap().map;
        assert!(
            map.n_starts > 0,
            "the loop's searches have space-filling starts"
        );
        in_pool(threads, || {
            find_map(&toy(), Some(&[0.0, 0.0]), &map, &|| ())
        })
        .unwrap()
    };
    let (one, two) = (search(7, 1), search(7, 2));
    assert_eq!(design_starts(&one), design_starts(&two));
    assert_eq!(
        one.map_x.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
        two.map_x.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
    );
    let other = search(8, 1);
    assert_ne!(
        design_starts(&one),
        design_starts(&other),
        "another seed, other starts"
    );
}

/// studies/bayes.toml cut to seconds: Model 4 at Level 1 over 10-60 Hz, NUTS only with two
/// short chains, one space-filling MAP start, with `seed`.
fn bayes_study(seed: u64) -> rfmlab::Study {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("studies");
    let file = root.join("bayes.toml");
    let text = std::fs::read_to_string(&file)
        .unwrap()
        .replace("band_hz = [1.0, 500.0]", "band_hz = [10.0, 60.0]")
        .replace(
            "models = [\"model3\", \"model4\", \"model5\"]",
            "models = [\"model4\"]",
        )
        .replace("levels = [\"L1\", \"L2\"]", "levels = [\"L1\"]")
        .replace(
            "samplers = [\"nuts\", \"stepping_stone\"]",
            "samplers = [\"nuts\"]",
        )
        .replace("chains = 4", "chains = 2")
        .replace("tune = 1000", "tune = 40")
        .replace("draws = 1000", "draws = 20")
        .replace("starts = 8", "starts = 1")
        .replacen("seed = 1", &format!("seed = {seed}"), 1);
    rfmlab::study::parse_str(&text, &file).unwrap()
}

#[test]
fn the_samplers_follow_the_plan_s_seed_not_the_thread_count() {
    let dir = tempfile::tempdir().unwrap();
    let run = |seed: u64, threads: usize| {
        let mut plan = bayes_study(seed).plan().unwrap();
        plan.figures = false;
        plan.engine.threads = Some(threads);
        plan.output_dir = dir.path().join(format!("out_{seed}_{threads}"));
        let mut ex = crate::shared_rom_cache::executor();
        let r = rfmlab::pipeline::run(&plan, &mut ex).unwrap();
        let (_, draws) = r.draws("L1", "model4", Some("nuts")).expect("NUTS draws");
        let bits: Vec<Vec<u64>> = draws
            .values
            .iter()
            .map(|v| v.iter().map(|x| x.to_bits()).collect())
            .collect();
        let starts = design_starts(&r.posterior("L1", "model4").unwrap().map);
        (bits, starts)
    };
    let (one, two) = (run(1, 1), run(1, 2));
    assert!(!one.0[0].is_empty());
    assert_eq!(
        one, two,
        "same seed, same draws and MAP starts on 1 and 2 threads"
    );
    let other = run(2, 2);
    assert_ne!(one.0, other.0, "another seed, other draws");
    assert_ne!(one.1, other.1, "another seed, other MAP starts");
}
