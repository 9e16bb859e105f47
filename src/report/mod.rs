//! Writing a run's [`Results`] to a folder: every table as parquet (units in the file
//! metadata, see [`crate::output`]), the figures when the plan asks for them, `report.md` and
//! `manifest.json` (written last, with every file's SHA-256, the timings and counters).
//!
//! The folder is replaced as a whole ([`crate::output::replace_dir`]): everything is written
//! into a temporary sibling `<dir>.tmp-<pid>` that is then swapped with `dir`. A failed or
//! killed write leaves the previous results intact; a temporary folder left by a killed run is
//! deleted by the next write to the same folder.

use crate::output::{Manifest, ResultsDir};
use crate::pipeline::results::{Results, LOOP_DIR};
use crate::runner::preflight::ModeDiscretisation;
use crate::runner::{closed_loop, write, write_bayes, write_compare, write_levels};
use crate::runner::{Event, RunError};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// What [`write`] wrote.
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

/// [`write`] with a progress callback.
pub fn write_with(
    results: &Results,
    dir: impl AsRef<Path>,
    progress: &(dyn Fn(Event) + Sync),
) -> Result<Written, RunError> {
    let dir = dir.as_ref();
    let t0 = Instant::now();
    let files = crate::output::replace_dir(dir, |tmp| fill(tmp, results, t0, progress))?;
    Ok(Written {
        dir: dir.to_path_buf(),
        files,
        seconds: t0.elapsed().as_secs_f64(),
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
    let levels = results.levels();
    let level_results = results.level_results();
    progress(Event::Start {
        step: "writing results".into(),
        total: 0,
    });
    for table in results.top_tables() {
        out.write_table(table)?;
    }
    let posts: Vec<&crate::bayes::PosteriorResult> = results.posteriors().collect();
    let figs = if results.figures {
        let mut f = write::draw_figures(out.path(), levels, level_results)?;
        f.extend(write_bayes::figures(out.path(), &posts)?);
        f.extend(write_levels::figures(out.path(), level_results)?);
        for (png, _) in &f {
            out.record(png);
            out.record(png.replace(".png", ".svg"));
        }
        f
    } else {
        Vec::new()
    };
    let engine_note = results.engine_note();
    let loop_status = results
        .closed_loop()
        .map(|o| closed_loop::status_line(&o.summary.levels));
    let mut report = write::build_report(
        study,
        levels,
        level_results,
        &figs,
        engine_note,
        loop_status.as_deref(),
    );
    mesh_error_section(&mut report, results.mesh_error());
    write_bayes::report(&mut report, levels, &posts, &figs);
    write_compare::report(&mut report, &posts);
    write_levels::report(&mut report, level_results, &figs);
    if let Some(o) = results.closed_loop() {
        let sub = LOOP_DIR;
        let mut d = ResultsDir::create(out.path(), sub)?;
        closed_loop::write_loop(&mut d, o, &study.name, results.figures)?;
        for f in d.written() {
            out.record(format!("{sub}/{f}"));
        }
        report.paragraph(&closed_loop::report_section(&o.markdown, sub));
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
    manifest.add_note(engine_note.to_string());
    manifest.add_note(
        "results written into a temporary folder and swapped into place at the end".to_string(),
    );
    out.write_manifest(&mut manifest)?;
    progress(Event::Finish);
    let mut files = out.written().to_vec();
    files.push("manifest.json".into());
    Ok(files)
}

/// The mesh's discretisation error per low mode (`[analyses] mesh_error`), with the warnings
/// `rfmlab check` gives.
fn mesh_error_section(report: &mut crate::output::Report, modes: &[ModeDiscretisation]) {
    let Some(first) = modes.first() else {
        return;
    };
    report.heading(2, "Mesh discretisation error");
    report.paragraph(&format!(
        "Richardson extrapolation from the study's mesh and the mesh refined twice per direction (order {}), real modes at the first model's initial storage modulus. The posterior's intervals do not include this error.",
        first.order
    ));
    let rows: Vec<Vec<String>> = modes
        .iter()
        .map(|d| {
            vec![
                d.mode.to_string(),
                format!("{:.4}", d.freq_hz),
                format!("{:.4}", d.freq_refined_hz),
                format!("{:+.3e}", d.error_hz),
                format!("{:+.3}", 100.0 * d.rel_error),
            ]
        })
        .collect();
    report.table(
        &[
            "mode",
            "f, study mesh (Hz)",
            "f, refined (Hz)",
            "estimated error (Hz)",
            "error (%)",
        ],
        &rows,
    );
    for w in crate::runner::preflight::mesh_error_warnings(modes) {
        report.paragraph(&format!("**Warning**: {w}"));
    }
}
