//! `rfmlab material STUDY.toml`: the material-level loop on measured E'(w), E''(w)
//! ([`rfmlab::report::material`]).

use super::common::{print_json, Global};
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct MaterialArgs {
    /// The material study file (TOML with a [material_data] section).
    pub study: PathBuf,
    /// Results folder, replaced as a whole when rfmlab wrote it (default: the study's
    /// `output_dir`, else `results/<name>`, relative to the current directory); a folder with
    /// other files, or a file, is refused unless --force.
    #[arg(short = 'o', long = "output", value_name = "DIR")]
    pub output: Option<PathBuf>,
    #[arg(long, help = super::common::FORCE_HELP)]
    pub force: bool,
    /// Do not draw figures.
    #[arg(long)]
    pub no_figures: bool,
    /// Print a JSON summary on stdout.
    #[arg(long)]
    pub json: bool,
}

pub fn run(a: &MaterialArgs, g: &Global) -> anyhow::Result<()> {
    let mut study = rfmlab::study::material::load_material(&a.study)?;
    if let Some(o) = &a.output {
        study.output_dir = o.clone();
    }
    study.figures &= !a.no_figures;
    // The output contract before anything is computed.
    let replace = super::common::claim_folder(&study.output_dir, a.force)?;
    let sp = super::common::spinner(g, "material loop");
    let summary = rfmlab::report::material::run_material_as(&study, replace)?;
    sp.finish_and_clear();
    if a.json {
        print_json(&serde_json::to_value(&summary)?)?;
    } else if !g.quiet {
        eprintln!(
            "{}: {} -> {} ({} parameters); RMS log10 error E' {:.4} -> {:.4}, E'' {:.4} -> {:.4}; stop: {}",
            study.name,
            summary.path.first().cloned().unwrap_or_default(),
            summary.final_law,
            summary.final_n_params,
            summary.first_rms_log10_storage,
            summary.final_rms_log10_storage,
            summary.first_rms_log10_loss,
            summary.final_rms_log10_loss,
            summary.stop_reason
        );
        eprintln!(
            "results in {} ({:.1} s); see report.md",
            summary.output_dir.display(),
            summary.seconds
        );
    }
    Ok(())
}
