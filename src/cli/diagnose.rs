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
    #[arg(long)]
    pub threshold_nats: Option<f64>,
    /// Results folder of the loop (default: the study's output folder with `.diagnose`
    /// appended, e.g. `results/<name>.diagnose`, relative to the current directory).
    #[arg(short = 'o', long = "output", value_name = "DIR")]
    pub output: Option<PathBuf>,
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
                "--threshold-nats {t} must be a non-negative number of nats (default 5)"
            ))));
        }
    }
    let study = super::common::load_study(&a.study)?;
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
    let summary = match &a.output {
        None => rfmlab::diagnose::diagnose_study(&study, a.model.as_deref(), &params),
        Some(o) => {
            let parent = o
                .parent()
                .filter(|p| !p.as_os_str().is_empty())
                .unwrap_or(std::path::Path::new("."));
            let name = o
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .ok_or_else(|| InputError(format!("-o {}: give a folder name", o.display())))?;
            rfmlab::diagnose::diagnose_into(
                &study,
                a.model.as_deref(),
                &params,
                parent,
                &name,
                true,
            )
        }
    }
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
