//! `rfmlab run STUDY.toml` and `rfmlab check STUDY.toml` ([`rfmlab::pipeline`] and [`rfmlab::report`]).

use super::common::{print_json, Global, InputError};
use rfmlab::pipeline::{self, Event, Executor, RunError};
use rfmlab::report::RunSummary;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};

#[derive(clap::Args, Debug)]
pub struct RunArgs {
    /// The study file (TOML).
    pub study: PathBuf,
    /// Results folder, replaced as a whole when rfmlab wrote it (default: the study's
    /// `output_dir`, else `results/<study name>`, relative to the current directory); a folder
    /// with other files, or a file, is refused unless --force.
    #[arg(short = 'o', long = "output", value_name = "DIR")]
    pub output: Option<PathBuf>,
    #[arg(long, help = super::common::FORCE_HELP)]
    pub force: bool,
    /// Print a JSON summary (identified parameters, FRACs, files) on stdout.
    #[arg(long)]
    pub json: bool,
    /// Do not draw figures (faster).
    #[arg(long)]
    pub no_figures: bool,
    /// Build and certify the ROM even if a certified ROM of the same model, points, band,
    /// range and tolerance is in the cache (`.rom-cache/` beside the results folder, or the
    /// folder RFMLAB_ROM_CACHE names).
    #[arg(long)]
    pub no_cache: bool,
}

#[derive(clap::Args, Debug)]
pub struct CheckArgs {
    /// The study file (TOML).
    pub study: PathBuf,
    /// The results folder `rfmlab run` would write (default: the study's `output_dir`): checked
    /// to be writable and replaceable under the output contract; nothing is written.
    #[arg(short = 'o', long = "output", value_name = "DIR")]
    pub output: Option<PathBuf>,
    /// Check the folder as `rfmlab run --force` would use it.
    #[arg(long)]
    pub force: bool,
    /// Print a JSON summary on stdout.
    #[arg(long)]
    pub json: bool,
}

/// Input errors (study file, data) become [`InputError`] so that the exit code is 2.
fn wrap(e: RunError) -> anyhow::Error {
    if e.is_input() {
        anyhow::Error::new(InputError(e.to_string()))
    } else {
        anyhow::Error::new(e)
    }
}

pub fn run(a: &RunArgs, g: &Global) -> anyhow::Result<()> {
    let mut study = super::common::load_study(&a.study)?;
    if let Some(o) = &a.output {
        study.output_dir = o.clone();
    }
    // The output contract before anything is computed.
    let replace = super::common::claim_folder(&study.output_dir, a.force)?;
    let mut plan = study.plan().map_err(wrap)?;
    plan.figures &= !a.no_figures;
    if let Some(o) = &a.output {
        plan.output_dir = o.clone();
    }
    let bar: Arc<Mutex<Option<indicatif::ProgressBar>>> = Arc::new(Mutex::new(None));
    let on_event = {
        let bar = bar.clone();
        let g = g.clone();
        Arc::new(move |ev: &Event| match ev {
            Event::Start { step, total } => {
                let pb = if *total > 0 {
                    super::common::progress(&g, *total, step)
                } else {
                    super::common::spinner(&g, step)
                };
                if let Some(old) = bar.lock().unwrap_or_else(|e| e.into_inner()).replace(pb) {
                    old.finish_and_clear();
                }
            }
            Event::Advance => {
                if let Some(pb) = bar.lock().unwrap_or_else(|e| e.into_inner()).as_ref() {
                    pb.inc(1);
                }
            }
            Event::Finish => {
                if let Some(pb) = bar.lock().unwrap_or_else(|e| e.into_inner()).take() {
                    pb.finish_and_clear();
                }
            }
        })
    };
    let mut ex = {
        let on_event = on_event.clone();
        Executor::new().observer(move |e| on_event(e))
    };
    if !a.no_cache {
        // Beside the results folder (-o included), or where RFMLAB_ROM_CACHE says.
        ex = ex.rom_cache(rfmlab::stage::rom_cache_dir(&plan.output_dir));
    }
    let results = pipeline::run(&plan, &mut ex).map_err(wrap)?;
    if !g.quiet && !a.json {
        if let Some(d) = results.discretisation() {
            if let Some(line) = rfmlab::stage::mesh_error::describe(d).first() {
                eprintln!("{line}");
            }
        }
    }
    // The pre-flight's warnings bear on the results: shown even with --quiet.
    for w in results.preflight_warnings() {
        eprintln!("warning: {w}");
    }
    let written = rfmlab::report::write_as(&results, &plan.output_dir, replace, &|e| on_event(&e))
        .map_err(wrap)?;
    let files = written.files;
    if let Some(pb) = bar.lock().unwrap_or_else(|e| e.into_inner()).take() {
        pb.finish_and_clear();
    }
    let summary = RunSummary {
        study: study.name.clone(),
        output_dir: plan.output_dir.clone(),
        files,
        models: results.model_summaries(),
        flagged: results.flagged(),
        warnings: results.preflight_warnings().to_vec(),
        seconds: results.seconds() + written.seconds,
    };
    if a.json {
        print_json(&serde_json::to_value(&summary)?)?;
    } else if !g.quiet {
        for m in &summary.models {
            let fr: Vec<String> = m.frac.iter().map(|f| format!("{f:.4}")).collect();
            eprintln!(
                "{} {}: {} iterations, {}; FRAC {}{}",
                m.level,
                m.model,
                m.iterations,
                m.stop_reason,
                fr.join(" "),
                if m.status_reason.is_empty() {
                    String::new()
                } else {
                    format!("; FLAGGED: {}", m.status_reason)
                }
            );
        }
        eprintln!(
            "results in {} ({:.1} s); see report.md",
            summary.output_dir.display(),
            summary.seconds
        );
    }
    super::common::flagged_exit(&summary.flagged)
}

pub fn check(a: &CheckArgs, g: &Global) -> anyhow::Result<()> {
    let mut study = super::common::load_study(&a.study)?;
    if let Some(o) = &a.output {
        study.output_dir = o.clone();
    }
    super::common::claim_folder(&study.output_dir, a.force)?;
    let quiet = g.quiet || a.json;
    let summary = rfmlab::pipeline::check_study_with(&study, &|line| {
        if !quiet {
            eprintln!("  {line}");
        }
    })
    .map_err(wrap)?;
    if a.json {
        print_json(&serde_json::to_value(&summary)?)?;
    } else if !g.quiet {
        let pf = &summary.preflight;
        eprintln!(
            "{}: OK ({} DOFs, {} levels, {} models, initial values evaluated at {} lines); `rfmlab run` writes its results to {} (change with -o/--output)",
            a.study.display(),
            summary.n_dof,
            summary.levels.len(),
            summary.models.len(),
            summary.lines_checked,
            study.output_dir.display()
        );
        if let Some(c) = &pf.cost {
            eprintln!(
                "  engine: about {} of memory ({} available), {} per factorisation",
                rfmlab::fe::cost::format_bytes(c.memory_bytes),
                rfmlab::fe::cost::format_bytes(c.available_memory_bytes),
                rfmlab::fe::cost::format_seconds(c.factor_seconds)
            );
        }
        if let (Some(m), Some(p)) = (pf.first_mode_hz, pf.first_peak_hz) {
            eprintln!(
                "  first y mode at the initial values {m:.2} Hz, data's first peak {p:.2} Hz"
            );
        }
        if let Some(d) = &pf.mesh {
            for line in rfmlab::stage::mesh_error::describe(d) {
                eprintln!("  {line}");
            }
        }
    }
    // The warnings bear on what a run would give: shown even with --quiet or --json.
    for w in &summary.preflight.warnings {
        eprintln!("warning: {w}");
    }
    Ok(())
}
