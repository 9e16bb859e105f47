//! `rfmlab design STUDY.toml`: plan the test ([`rfmlab::design`]).

use super::common::{Global, InputError};
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct DesignArgs {
    /// The study file (TOML); its optional [design] section sets the search.
    pub study: PathBuf,
    /// Response sensors per design (overrides `[design] sensors`).
    #[arg(long)]
    pub sensors: Option<usize>,
    /// Results folder, replaced as a whole when rfmlab wrote it (default: the study's output
    /// folder with `.design` appended, e.g. `results/<name>.design`); a folder with other
    /// files, or a file, is refused unless --force.
    #[arg(short = 'o', long = "output", value_name = "DIR")]
    pub output: Option<PathBuf>,
    #[arg(long, help = super::common::FORCE_HELP)]
    pub force: bool,
}

pub fn run(a: &DesignArgs, g: &Global) -> anyhow::Result<()> {
    let mut study = super::common::load_study(&a.study)?;
    if let Some(k) = a.sensors {
        study = rfmlab::design::with_sensors(&study, k)
            .map_err(|e| InputError(format!("--sensors {k}: {e}")))?;
    }
    let out = match &a.output {
        Some(o) => o.clone(),
        None => rfmlab::stage::sibling(&study.output_dir, "design"),
    };
    // The output contract before anything is computed.
    let replace = super::common::claim_folder(&out, a.force)?;
    let t0 = std::time::Instant::now();
    let quiet = g.quiet;
    let progress = move |m: &str| {
        if !quiet {
            eprintln!("[{:8.1} s] {m}", t0.elapsed().as_secs_f64());
        }
    };
    let r = rfmlab::design::design(&study, &progress).map_err(|e| match e {
        rfmlab::design::DesignError::Study(s) => anyhow::Error::new(InputError(s.to_string())),
        e => anyhow::Error::new(e),
    })?;
    rfmlab::design::write::write(&r, &study.file, study.seed, &out, replace)
        .map_err(|e| anyhow::Error::new(InputError(e.to_string())))?;
    if !g.quiet {
        eprintln!(
            "{}",
            rfmlab::design::write::markdown(&r, None)
                .to_markdown()
                .lines()
                .nth(2)
                .unwrap_or("")
        );
        eprintln!("wrote {}", out.display());
    }
    Ok(())
}
