//! Wall time of the closed loop for one level (candidates ranked by the score test, the top
//! three refitted, the winner confirmed by evidence, then a second round that accepts
//! nothing) on `studies/closed_loop_mass.toml` (the default rig, ROM engine, 12 g undeclared
//! mass at point 4): median of a few runs of [`rfmlab::diagnose::diagnose_study`],
//! the loop alone (`loop_seconds`) and the whole command (engine build included). The old path
//! (every refit a full multistart search) runs side by side when RFMLAB_BENCH_OLD=1, and the
//! loop without the score-predicted gate on refits when RFMLAB_BENCH_NO_GATE=1.
//! Run with `cargo bench --bench closed_loop`; RFMLAB_BENCH_RUNS sets the runs (default 3).
//! RFMLAB_BENCH_STUDY names another study (relative to the package), e.g.
//! `studies/closed_loop_virtual_springs.toml`: the independent compliant base with base springs
//! among the candidates (its term ROM is built on the first run and cached in
//! `results/.rom-cache`; the loop time excludes it, the command time of the first run includes it).

use rfmlab::closed_loop::ClosedLoopParams;
use std::path::Path;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let file = match std::env::var("RFMLAB_BENCH_STUDY") {
        Ok(s) => root.join(s),
        Err(_) => {
            if !root
                .join("studies/data/closed_loop/mass_pt4_L1.uff")
                .is_file()
            {
                eprintln!(
                    "closed_loop: studies/data/closed_loop/mass_pt4_L1.uff is missing (skipped)"
                );
                return;
            }
            root.join("studies/closed_loop_mass.toml")
        }
    };
    let runs: usize = std::env::var("RFMLAB_BENCH_RUNS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(3);
    let mut study = rfmlab::study::load(&file).expect("study");
    let tmp = std::env::temp_dir().join(format!("rfmlab-bench-closed-loop-{}", std::process::id()));
    study.output_dir = tmp.join("out");
    let d = ClosedLoopParams::default();
    let mut paths = vec![("warm refits (default)", d.clone())];
    if std::env::var("RFMLAB_BENCH_NO_GATE").is_ok_and(|v| v == "1") {
        paths.push((
            "no score-predicted gate",
            ClosedLoopParams {
                predicted_gain_margin: f64::INFINITY,
                ..d.clone()
            },
        ));
    }
    if std::env::var("RFMLAB_BENCH_OLD").is_ok_and(|v| v == "1") {
        paths.push((
            "multistart refits (old)",
            ClosedLoopParams {
                warm_refits: false,
                ..d.clone()
            },
        ));
    }
    println!(
        "closed loop, {} ({} thread(s)), {runs} run(s):",
        file.display(),
        rayon::current_num_threads()
    );
    for (label, params) in paths {
        let (mut loop_s, mut total_s) = (Vec::new(), Vec::new());
        let mut per_level: Vec<(String, Vec<f64>)> = Vec::new();
        let mut conclusion = String::new();
        for _ in 0..runs {
            let s = rfmlab::diagnose::diagnose_study(&study, None, &params).expect("diagnose");
            loop_s.push(s.levels.iter().map(|l| l.loop_seconds).sum::<f64>());
            total_s.push(s.seconds);
            for l in &s.levels {
                match per_level.iter_mut().find(|(n, _)| *n == l.level) {
                    Some((_, v)) => v.push(l.loop_seconds),
                    None => per_level.push((l.level.clone(), vec![l.loop_seconds])),
                }
            }
            conclusion = s
                .levels
                .iter()
                .map(|l| format!("{}: {}", l.level, l.conclusion))
                .collect::<Vec<_>>()
                .join("; ");
        }
        println!(
            "  {label:<28} loop median {:7.1} s, command median {:7.1} s  ({conclusion})",
            median(loop_s),
            median(total_s)
        );
        for (level, v) in per_level {
            println!("    {level}: loop median {:7.1} s", median(v));
        }
    }
    let _ = std::fs::remove_dir_all(&tmp);
}
