//! `rfmlab run` with an `[inference]` section, as a user runs it, on the bundled default data
//! (Model 4 at Level 1 over 10-60 Hz, short chains):
//! * the draws file read by ArviZ (scripts/to_arviz.py) gives R-hat, ESS and MCSE equal to
//!   rfmlab's summary table;
//! * `kill -9` in the middle of sampling, then the same command again: the draws file equals an
//!   uninterrupted run's (thread-count independence is `seed.rs`'s and `rom_joint.rs`'s);
//! * bad `[inference]` input exits 2 naming the file and the key.

use crate::python_checks::{interpreter, script};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const BIN: &str = env!("CARGO_BIN_EXE_rfmlab");

/// studies/bayes.toml cut down to seconds: band 10-60 Hz, Level 1, Model 4, 2 short chains.
fn study_text(out: &Path) -> String {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("studies");
    let s = std::fs::read_to_string(root.join("bayes.toml")).unwrap();
    let data = root.join("data");
    s.replace(
        "name = \"bayes\"",
        &format!("name = \"bayes_test\"\noutput_dir = \"{}\"", out.display()),
    )
    .replace("\"data/", &format!("\"{}/", data.display()))
    .replace("band_hz = [1.0, 500.0]", "band_hz = [10.0, 60.0]")
    .replace(
        "models = [\"model3\", \"model4\", \"model5\"]",
        "models = [\"model4\"]",
    )
    .replace("levels = [\"L1\", \"L2\"]", "levels = [\"L1\"]")
    .replace("chains = 4", "chains = 2")
    .replace("tune = 1000", "tune = 150")
    .replace("draws = 1000", "draws = 150")
    .replace("particles = 1000", "particles = 200")
    .replace("starts = 8", "starts = 2")
    .replace(
        "[solver]\nengine = \"rom\"",
        // Model 5 takes about 170 updates over 10-60 Hz: within the budget, not flagged.
        "[solver]\nengine = \"rom\"\nmax_iterations = 300\n",
    )
    .replace(
        "sensitivity = false",
        "sensitivity = false\nfigures = false",
    )
}

fn write_study(dir: &Path, name: &str) -> (PathBuf, PathBuf) {
    let out = dir.join(format!("results_{name}")).join("bayes_test");
    std::fs::create_dir_all(out.parent().unwrap()).unwrap();
    let file = dir.join(format!("{name}.toml"));
    std::fs::write(&file, study_text(&out)).unwrap();
    (file, out)
}

/// `rfmlab run file` with its certified ROM read from (or saved to) the folder `cache`.
fn run(file: &Path, cache: &Path) -> (i32, String) {
    let o = command(file, cache).output().unwrap();
    (
        o.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

fn command(file: &Path, cache: &Path) -> Command {
    let mut c = Command::new(BIN);
    c.args(["run", file.to_str().unwrap()])
        .env("CI", "1")
        .env("RFMLAB_ROM_CACHE", cache);
    c
}

fn python() -> Option<PathBuf> {
    let py = interpreter();
    if py.exists() {
        return Some(py);
    }
    assert!(
        std::env::var_os("CI").is_none(),
        "CI is set but no Python with ArviZ was found"
    );
    eprintln!("SKIP: no Python (set RFMLAB_PYTHON or create .venv with arviz)");
    None
}

/// Python: do two parquet tables hold the same rows (exactly)?
fn same_table(py: &Path, a: &Path, b: &Path) -> bool {
    let code = "import sys, pandas as pd; a = pd.read_parquet(sys.argv[1]); b = pd.read_parquet(sys.argv[2]); print('SAME' if a.equals(b) else 'DIFF')";
    let o = Command::new(py)
        .args(["-c", code])
        .arg(a)
        .arg(b)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8_lossy(&o.stdout).contains("SAME")
}

#[test]
fn draws_read_by_arviz_give_rfmlab_s_diagnostics_and_a_killed_run_resumes_to_the_same_draws() {
    let Some(py) = python() else { return };
    let dir = tempfile::tempdir().unwrap();
    // Uninterrupted reference; its certified ROM is saved for the interrupted run (the ROM
    // build is most of a run's time) in the suite's cache, where the seed test's runs of the
    // same cut study find it as well.
    let cache = crate::shared_rom_cache::runs_folder();
    let (fa, outa) = write_study(dir.path(), "a");
    let (code, err) = run(&fa, &cache);
    assert_eq!(code, 0, "{err}");
    for t in ["draws", "summary", "starts", "laplace", "sampler_runs"] {
        assert!(
            outa.join(format!("{t}.parquet")).is_file(),
            "{t}.parquet missing"
        );
    }
    // ArviZ on the same draws.
    let o = Command::new(&py)
        .arg(script("to_arviz.py"))
        .arg(&outa)
        .args(["--sampler", "nuts", "--json"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let az: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let group = &az["L1/model4/nuts"];
    let code = "import sys, json, pandas as pd; s = pd.read_parquet(sys.argv[1]); s = s[s.sampler == 'nuts']; print(json.dumps({r.parameter: {c: float(getattr(r, c)) for c in ['r_hat', 'ess_bulk', 'ess_tail', 'mcse_mean']} for r in s.itertuples()}))";
    let o = Command::new(&py)
        .args(["-c", code])
        .arg(outa.join("summary.parquet"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let ours: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let mut n = 0;
    for (p, vals) in ours.as_object().unwrap() {
        for c in ["r_hat", "ess_bulk", "ess_tail", "mcse_mean"] {
            let a = vals[c].as_f64().unwrap();
            // draws.parquet names its columns in snake case (E0 -> e0).
            let b = group[p.to_ascii_lowercase()][c]
                .as_f64()
                .unwrap_or_else(|| panic!("ArviZ has no {p}.{c}: {group}"));
            assert!(
                (a - b).abs() <= 1e-8 * b.abs().max(1e-300),
                "{p} {c}: rfmlab {a} vs ArviZ {b}"
            );
            n += 1;
        }
    }
    assert!(n >= 16, "compared {n} values");

    // Interrupted run: kill -9 once sampling has checkpointed something, then run again.
    let (fb, outb) = write_study(dir.path(), "b");
    let ckpt = outb.parent().unwrap().join(".checkpoints");
    let mut child = command(&fb, &cache)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let t0 = Instant::now();
    let mut killed = false;
    while t0.elapsed() < Duration::from_secs(600) {
        let n_files = walk(&ckpt);
        if n_files >= 1 {
            child.kill().unwrap(); // SIGKILL
            killed = true;
            break;
        }
        if let Ok(Some(_)) = child.try_wait() {
            break;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let _ = child.wait();
    assert!(killed, "the run ended before any checkpoint was written");
    assert!(
        !outb.join("draws.parquet").exists(),
        "killed before the results were written"
    );
    let (code, err) = run(&fb, &cache);
    assert_eq!(code, 0, "{err}");
    // The reference run builds the ROM or finds it built by the seed test's runs.
    assert!(
        rom_builds(&outa) <= 1,
        "the reference run builds one ROM at most"
    );
    assert_eq!(rom_builds(&outb), 0, "the resumed run reads the cached ROM");
    assert!(
        same_table(
            &py,
            &outa.join("draws.parquet"),
            &outb.join("draws.parquet")
        ),
        "draws after kill -9 and rerun differ from the uninterrupted run"
    );
    // The same draws whatever the thread count: `seed.rs` runs the pipeline with 1 and 2
    // threads, `rom_joint.rs` builds the basis and the certificate with each.
}

/// The manifest's count of ROM builds of the run written to `out`.
fn rom_builds(out: &Path) -> u64 {
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("manifest.json")).unwrap()).unwrap();
    m["counters"]["rom builds"].as_u64().unwrap_or(0)
}

/// Number of files below `dir` (0 when it does not exist).
fn walk(dir: &Path) -> usize {
    let Ok(rd) = std::fs::read_dir(dir) else {
        return 0;
    };
    rd.flatten()
        .map(|e| {
            let p = e.path();
            if p.is_dir() {
                walk(&p)
            } else if p.extension().is_some_and(|x| x == "tmp") {
                0
            } else {
                1
            }
        })
        .sum()
}

#[test]
fn bad_inference_input_exits_2_naming_the_key() {
    let dir = tempfile::tempdir().unwrap();
    let (f, _) = write_study(dir.path(), "bad");
    let good = std::fs::read_to_string(&f).unwrap();
    let cases: [(&str, &str, &str); 9] = [
        (
            "# Priors: log-uniform",
            "[inference.priors.model4]\nE0 = { family = \"beta\", lo = 1e6, hi = 1e8 }\n# Priors: log-uniform",
            "inference.priors.model4.E0.family",
        ),
        (
            "# Priors: log-uniform",
            "[inference.priors.model4]\nE1 = { family = \"log_uniform\", lo = 1e7, hi = 1e8 }\n# Priors: log-uniform",
            "inference.priors.model4.E1",
        ),
        ("n_averages = 189.5", "n_averages = -3", "inference.noise.n_averages"),
        ("chains = 2", "chains = 0", "inference.nuts.chains"),
        ("[inference.nuts]", "[inference.nuts]\ntarget_accept = 1.5", "inference.nuts.target_accept"),
        ("samplers = [\"nuts\", \"stepping_stone\"]", "samplers = [\"gibbs\"]", "inference.samplers[0]"),
        ("path = \"reference\"", "path = \"bridge\"", "inference.stepping_stone.path"),
        ("replicas = 8", "replicas = 8\nwiden = 0.5", "inference.stepping_stone.widen"),
        ("model = \"coherence\"", "model = \"laplace\"", "inference.noise.model"),
    ];
    for (from, to, key) in cases {
        assert!(good.contains(from), "{from}");
        let text = good.replacen(from, to, 1);
        let file = dir.path().join("case.toml");
        std::fs::write(&file, text).unwrap();
        let o = Command::new(BIN)
            .args(["check", file.to_str().unwrap()])
            .env("CI", "1")
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{key}: {err}");
        assert!(err.contains(key), "{key} not named in: {err}");
        assert!(err.contains("case.toml"), "file not named in: {err}");
    }
}
