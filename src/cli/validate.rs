//! `rfmlab validate VALIDATION.toml [--shard i/n] [--out DIR] [--merge]`: the statistical
//! validation of the Bayesian layer ([`rfmlab::validate`]), one shard per process.

use super::common::{progress, spinner, Global, InputError};
use rfmlab::output::shards::Shard;
use rfmlab::validate::write::{merge_and_summarise, run_and_write};
use rfmlab::validate::{load_validation, units, Setup};
use std::path::PathBuf;
use std::time::Instant;

#[derive(clap::Args, Debug)]
pub struct ValidateArgs {
    /// The validation file (TOML), e.g. validations/validate.toml.
    pub file: PathBuf,
    /// Run only the units k with k mod n = i (0 <= i < n), e.g. --shard 2/8.
    #[arg(long, default_value = "0/1")]
    pub shard: String,
    /// Output folder (default: the file's `validation.output_dir`, else
    /// `results/<name>`, relative to the current directory).
    #[arg(short = 'o', long = "output", alias = "out", value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Do not run units: merge the parts every shard wrote and summarise.
    #[arg(long)]
    pub merge: bool,
    /// Do not draw the figure.
    #[arg(long)]
    pub no_figures: bool,
}

pub fn run(a: &ValidateArgs, g: &Global) -> anyhow::Result<()> {
    let shard = Shard::parse(&a.shard).map_err(|e| InputError(e.to_string()))?;
    let spec = load_validation(&a.file)?;
    let out = a.out.clone().unwrap_or_else(|| spec.output_dir.clone());
    std::fs::create_dir_all(&out)
        .map_err(|e| anyhow::anyhow!("creating {}: {e}", out.display()))?;
    if !a.merge {
        let t0 = Instant::now();
        let sp = spinner(g, "structure and ROM");
        let setup = Setup::new(&spec)?;
        sp.finish_and_clear();
        let setup_s = t0.elapsed().as_secs_f64();
        let n = units(&spec)
            .iter()
            .enumerate()
            .filter(|(k, _)| shard.owns(*k))
            .count();
        let pb = progress(
            g,
            n as u64,
            &format!("shard {}/{}", shard.index, shard.count),
        );
        let secs = run_and_write(&spec, &setup, setup_s, shard, &out, &|| pb.inc(1))?;
        pb.finish_and_clear();
        if !g.quiet {
            eprintln!(
                "shard {}/{}: {n} units in {secs:.1} s (setup {setup_s:.1} s, ROM {} vectors); parts in {}",
                shard.index,
                shard.count,
                setup.rom_basis,
                out.display()
            );
        }
    }
    if a.merge || shard.count == 1 {
        let cmd = std::env::args().collect::<Vec<_>>().join(" ");
        let v = merge_and_summarise(&spec, &out, !a.no_figures, &cmd)?;
        let failed = v.checks.iter().filter(|c| !c.1).count();
        if !g.quiet {
            eprintln!(
                "{} of {} checks pass; summary in {}",
                v.checks.len() - failed,
                v.checks.len(),
                out.join("summary.md").display()
            );
        }
    }
    Ok(())
}
