//! `rfmlab diagnose STUDY.toml`: the closed loop ([`rfmlab::diagnose`]).

use super::common::{print_json, Global, InputError};
use rfmlab::closed_loop::ClosedLoopParams;
use rfmlab::stage::RunError;
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct DiagnoseArgs {
    /// The study file (TOML); it needs an [inference] section.
    pub study: PathBuf,
    /// The model to diagnose (default: the first of `[inference] models`).
    #[arg(long)]
    pub model: Option<String>,
    /// Laplace log-evidence gain (nats) an effect needs to be accepted (default: the study's
    /// `[closed_loop] evidence_threshold`, else 5).
    #[arg(long, allow_negative_numbers = true)]
    pub threshold_nats: Option<f64>,
    /// Results folder of the loop, replaced as a whole when rfmlab wrote it (default: the
    /// study's output folder with `.diagnose` appended, e.g. `results/<name>.diagnose`, relative
    /// to the current directory); a folder with other files, or a file, is refused unless
    /// --force.
    #[arg(short = 'o', long = "output", value_name = "DIR")]
    pub output: Option<PathBuf>,
    #[arg(long, help = super::common::FORCE_HELP)]
    pub force: bool,
    /// Do not draw the residual figures.
    #[arg(long)]
    pub no_figures: bool,
    /// Build and certify the reduced models even if certified ones are in the cache
    /// (`.rom-cache/` beside the results folder, or the folder RFMLAB_ROM_CACHE names).
    #[arg(long)]
    pub no_cache: bool,
    /// Print a JSON summary on stdout.
    #[arg(long)]
    pub json: bool,
}

fn wrap(e: RunError) -> anyhow::Error {
    if e.is_input() {
        anyhow::Error::new(InputError(e.to_string()))
    } else {
        anyhow::Error::new(e)
    }
}

pub fn run(a: &DiagnoseArgs, g: &Global) -> anyhow::Result<()> {
    if let Some(t) = a.threshold_nats {
        if !(t.is_finite() && t >= 0.0) {
            return Err(anyhow::Error::new(InputError(format!(
                "--threshold-nats {t}: the evidence an effect needs is zero or more nats, e.g. --threshold-nats 5 (the default)"
            ))));
        }
    }
    let mut study = super::common::load_study(&a.study)?;
    if let Some(m) = &a.model {
        if !study.models.iter().any(|s| s.name.eq_ignore_ascii_case(m)) {
            let names: Vec<&str> = study.models.iter().map(|s| s.name.as_str()).collect();
            return Err(anyhow::Error::new(InputError(format!(
                "--model {m}: {} has no model {m}; give one of its [[models]]: {} (or leave --model out to diagnose the first of [inference] models)",
                a.study.display(),
                names.join(", ")
            ))));
        }
    }
    let out = match &a.output {
        Some(o) => o.clone(),
        None => rfmlab::stage::sibling(&study.output_dir, "diagnose"),
    };
    let parent = out
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(std::path::Path::new("."))
        .to_path_buf();
    let name = out
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .ok_or_else(|| InputError(format!("-o {}: give a folder name", out.display())))?;
    // The output contract before anything is computed.
    let replace = super::common::claim_folder(&out, a.force)?;
    if a.output.is_some() {
        // The ROM cache follows the results folder: `.rom-cache/` beside it.
        study.output_dir = out.clone();
    }
    // Without the cache: a fresh, empty cache folder of this process, removed at the end.
    let _fresh_cache = if a.no_cache {
        let dir = FreshCache::new()?;
        study.output_dir = dir.0.join("diagnose");
        // The library reads the cache folder from the environment first. No other thread
        // runs yet (the spinner and the thread pool start below).
        std::env::remove_var(rfmlab::stage::ROM_CACHE_ENV);
        Some(dir)
    } else {
        None
    };
    let sp = super::common::spinner(g, "closing the loop");
    let from_study = rfmlab::diagnose::params_of(&study);
    let shown = sp.clone();
    let params = ClosedLoopParams {
        threshold_nats: a.threshold_nats.unwrap_or(from_study.threshold_nats),
        // On a terminal the spinner shows the step; in a log, a line per step with its time.
        progress: if g.quiet {
            rfmlab::closed_loop::Progress::default()
        } else if std::io::IsTerminal::is_terminal(&std::io::stderr()) {
            rfmlab::closed_loop::Progress::new(move |m| {
                shown.set_message(format!("closing the loop: {m}"))
            })
        } else {
            let t0 = std::time::Instant::now();
            rfmlab::closed_loop::Progress::new(move |m| {
                eprintln!("[{:8.1} s] {m}", t0.elapsed().as_secs_f64())
            })
        },
        ..from_study
    };
    let summary = rfmlab::diagnose::diagnose_into_as(
        &study,
        a.model.as_deref(),
        &params,
        &parent,
        &name,
        !a.no_figures,
        replace,
    )
    .map_err(wrap)?;
    sp.finish_and_clear();
    if a.json {
        print_json(&serde_json::to_value(&summary)?)?;
    } else if !g.quiet {
        for l in &summary.levels {
            eprintln!(
                "{} {}: {}; normalised chi-square {:.3} -> {:.3}",
                l.level,
                summary.model,
                l.conclusion,
                l.chi2_normalised_before,
                l.chi2_normalised_after
            );
        }
        eprintln!(
            "results in {} ({:.1} s); see closed_loop.md",
            summary.output_dir.display(),
            summary.seconds
        );
    }
    Ok(())
}

/// An empty ROM cache folder of this process under the system's temporary folder (for
/// `--no-cache`: every reduced model is built and certified), removed when dropped.
struct FreshCache(PathBuf);

impl FreshCache {
    fn new() -> anyhow::Result<FreshCache> {
        let dir = std::env::temp_dir().join(format!(
            "rfmlab-no-cache-{}-{}",
            std::process::id(),
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_nanos())
        ));
        std::fs::create_dir_all(&dir)
            .map_err(|e| anyhow::anyhow!("cannot create {}: {e}", dir.display()))?;
        Ok(FreshCache(dir))
    }
}

impl Drop for FreshCache {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}
