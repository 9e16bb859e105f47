//! Writing a run's [`Results`] to a folder: every table as parquet (units in the file
//! metadata, see [`crate::output`]), the figures when the plan asks for them, `report.md` and
//! `manifest.json` (written last, with every file's SHA-256, the timings and counters).
//!
//! The folder is replaced as a whole ([`crate::output::replace_dir`]), and only when rfmlab
//! wrote it, it is empty or absent, or the caller forces it ([`crate::output::contract`]):
//! everything is written into a temporary sibling `<dir>.tmp-<pid>` that is then swapped with
//! `dir`. A failed or
//! killed write leaves the previous results intact; a temporary folder left by a killed run is
//! deleted by the next write to the same folder.
//!
//! What is written comes from `tables` (every parquet table, its columns and units),
//! `figures` (the PNG and SVG figures) and `markdown` (the sections of report.md).
//! [`run_study`] runs a study and writes its results in one call.

mod figures;
mod markdown;
pub mod material;

use crate::diagnose;
use crate::output::{Manifest, Replace, ResultsDir};
use crate::pipeline::results::{Results, LOOP_DIR};
use crate::pipeline::{Executor, ModelSummary};
use crate::stage::{Event, RunError};
use crate::study::Study;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Options of a run (beyond the study file).
#[derive(Clone, Debug, Default)]
pub struct RunOptions {
    /// Skip figures even when the study asks for them (tests, benchmarks). Default false.
    pub no_figures: bool,
    /// Override the study's output folder. Default None (use `study.output_dir`).
    pub output_dir: Option<PathBuf>,
    /// Folder of certified ROMs reused across runs (keyed by model, points, band, range and
    /// tolerance; see [`crate::rom::cache`]). Default None: build and certify every run.
    pub rom_cache: Option<PathBuf>,
}

/// What a run produced (also printed by `rfmlab run --json`).
#[derive(Clone, Debug, serde::Serialize)]
pub struct RunSummary {
    pub study: String,
    pub output_dir: PathBuf,
    pub files: Vec<String>,
    /// Per level and model: identified parameters (SI), stop reason, status and FRAC per FRF.
    pub models: Vec<ModelSummary>,
    /// The fits that are not results (global RFM and MAP), with their reasons: `rfmlab run`
    /// exits with code 3 when this is not empty.
    pub flagged: Vec<crate::pipeline::FlaggedFit>,
    /// The pre-flight's warnings that bear on the results (the mesh's remaining error, the
    /// first mode far from the data's peak, channels flipped, ...), as the report's first
    /// lines give them.
    pub warnings: Vec<String>,
    pub seconds: f64,
}

/// What [`write()`] wrote.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Written {
    /// The results folder.
    pub dir: PathBuf,
    /// Files written, relative to `dir` (`manifest.json` last).
    pub files: Vec<String>,
    /// Seconds spent writing.
    pub seconds: f64,
}

/// Write `results` into `dir`, replacing its previous contents atomically (module doc).
pub fn write(results: &Results, dir: impl AsRef<Path>) -> Result<Written, RunError> {
    write_with(results, dir, &|_| {})
}

/// [`write()`] with a progress callback.
pub fn write_with(
    results: &Results,
    dir: impl AsRef<Path>,
    progress: &(dyn Fn(Event) + Sync),
) -> Result<Written, RunError> {
    write_as(results, dir, Replace::IfOurs, progress)
}

/// [`write_with`] under the output contract's choice `replace` ([`crate::output::contract`]):
/// [`Replace::IfOurs`] refuses a folder rfmlab did not write, [`Replace::Force`] replaces it.
pub fn write_as(
    results: &Results,
    dir: impl AsRef<Path>,
    replace: Replace,
    progress: &(dyn Fn(Event) + Sync),
) -> Result<Written, RunError> {
    let dir = dir.as_ref();
    let t0 = Instant::now();
    let files =
        crate::output::replace_dir_as(dir, replace, |tmp| fill(tmp, results, t0, progress))?;
    Ok(Written {
        dir: dir.to_path_buf(),
        files,
        seconds: t0.elapsed().as_secs_f64(),
    })
}

/// Run a study: identification, correlation, tables, figures, report and manifest in
/// `study.output_dir` (or `opts.output_dir`), replaced atomically as a whole (module doc).
/// The same path as [`crate::pipeline::run`] then [`write()`].
pub fn run_study(
    study: &Study,
    opts: &RunOptions,
    progress: &(dyn Fn(Event) + Sync),
) -> Result<RunSummary, RunError> {
    let mut plan = study.plan()?;
    if let Some(d) = &opts.output_dir {
        plan.output_dir = d.clone();
    }
    plan.figures &= !opts.no_figures;
    let mut ex = Executor::new();
    if let Some(d) = &opts.rom_cache {
        ex = ex.rom_cache(d.clone());
    }
    let results = crate::pipeline::run_with(&plan, &mut ex, progress)?;
    let written = write_with(&results, &plan.output_dir, progress)?;
    Ok(RunSummary {
        study: study.name.clone(),
        output_dir: plan.output_dir.clone(),
        files: written.files,
        models: results.model_summaries(),
        flagged: results.flagged(),
        warnings: results.preflight_warnings().to_vec(),
        seconds: results.seconds() + written.seconds,
    })
}

/// Write every result file of `results` into the (new, empty) folder `dir`: tables, figures
/// when asked for, report.md, and manifest.json last. Returns the files written.
fn fill(
    dir: &Path,
    results: &Results,
    t0: Instant,
    progress: &(dyn Fn(Event) + Sync),
) -> Result<Vec<String>, RunError> {
    let parent = dir.parent().map(Path::to_path_buf).unwrap_or_default();
    let name = dir
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let mut out = ResultsDir::create(&parent, &name)?;
    let study = results.study();
    progress(Event::Start {
        step: "writing results".into(),
        total: 0,
    });
    for table in results.top_tables() {
        out.write_table(table)?;
    }
    let figs = if results.figures {
        let f = figures::draw(out.path(), results)?;
        for (png, _) in &f {
            out.record(png);
            out.record(png.replace(".png", ".svg"));
        }
        f
    } else {
        Vec::new()
    };
    let mut report = markdown::build(results, &figs);
    if let Some(o) = results.closed_loop() {
        let sub = LOOP_DIR;
        let mut d = ResultsDir::create(out.path(), sub)?;
        diagnose::write_loop(&mut d, o, &study.name, results.figures)?;
        for f in d.written() {
            out.record(format!("{sub}/{f}"));
        }
        report.paragraph(&diagnose::report_section(&o.markdown, sub));
    }
    out.write_report(&report)?;
    let mut manifest = Manifest::new(&study.file, Some(study.seed));
    for (step, secs) in results.timings() {
        manifest.add_timing(step.clone(), *secs);
    }
    manifest.add_timing("total", results.seconds() + t0.elapsed().as_secs_f64());
    for (name, n) in results.counters() {
        manifest.add_count(name.clone(), *n);
    }
    manifest.add_note(results.engine_note().to_string());
    manifest.add_note(
        "results written into a temporary folder and swapped into place at the end".to_string(),
    );
    out.write_manifest(&mut manifest)?;
    progress(Event::Finish);
    let mut files = out.written().to_vec();
    files.push("manifest.json".into());
    Ok(files)
}
