//! Wall time of `rfmlab run studies/default.toml` (the README's first command): median of a
//! few runs of the built binary, cold (ROM built and certified) and warm (ROM from the cache).
//! Run with `cargo build --release && cargo bench --bench default_study`.
//! RFMLAB_BENCH_RUNS sets the number of runs (default 3). Needs studies/data/ (skips without it).

use std::path::Path;
use std::process::Command;
use std::time::Instant;

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let study = root.join("studies/default.toml");
    if !root.join("studies/data/paper_virtual_L1.uff").is_file() {
        eprintln!("default_study: studies/data/paper_virtual_L1.uff is missing; generate the default data first (skipped)");
        return;
    }
    let exe = root.join("target/release/rfmlab");
    if !exe.is_file() {
        eprintln!(
            "default_study: {} is missing; run `cargo build --release` first (skipped)",
            exe.display()
        );
        return;
    }
    let runs: usize = std::env::var("RFMLAB_BENCH_RUNS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(3);
    // Cold: the ROM is built and certified (--no-cache); warm: it comes from the cache that
    // the cold runs left in results/.rom-cache.
    for (label, extra) in [
        ("cold (--no-cache)", Some("--no-cache")),
        ("warm (ROM cache)", None),
    ] {
        let mut times = Vec::new();
        for k in 0..runs {
            let t = Instant::now();
            let mut cmd = Command::new(&exe);
            cmd.args(["--quiet", "run"]).arg(&study).current_dir(root);
            if let Some(x) = extra {
                cmd.arg(x);
            }
            let status = cmd.status().expect("run rfmlab");
            let s = t.elapsed().as_secs_f64();
            assert!(status.success(), "rfmlab run failed (exit {status})");
            eprintln!("{label} run {}: {s:.2} s", k + 1);
            times.push(s);
        }
        times.sort_by(f64::total_cmp);
        println!(
            "rfmlab run studies/default.toml, {label}: median {:.2} s over {} runs (min {:.2} s, max {:.2} s)",
            times[times.len() / 2],
            runs,
            times[0],
            times[times.len() - 1]
        );
    }
}
