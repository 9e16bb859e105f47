//! `rfmlab validate VALIDATION.toml [--shard i/n] [-o DIR] [--merge]`: the statistical
//! validation of the Bayesian layer ([`rfmlab::validate`]), one shard per process.

use super::common::{print_json, progress, spinner, Global, InputError};
use rfmlab::output::contract::{has_manifest, MANIFEST};
use rfmlab::output::shards::Shard;
use rfmlab::output::{replace_dir_as, sha256_file, Manifest};
use rfmlab::validate::write::{merge_and_summarise, run_and_write};
use rfmlab::validate::{load_validation, units, Setup, ValidationSpec};
use serde_json::json;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

#[derive(clap::Args, Debug)]
pub struct ValidateArgs {
    /// The validation file (TOML), e.g. validations/validate.toml.
    pub file: PathBuf,
    /// Run only the units k with k mod n = i (0 <= i < n), e.g. --shard 2/8.
    #[arg(long, default_value = "0/1")]
    pub shard: String,
    /// Output folder (default: the file's `validation.output_dir`, else `../results/validate`
    /// relative to the file). One process (--shard 0/1) replaces it as a whole when rfmlab
    /// wrote it; with --shard i/n (n > 1) every shard writes its parts into it and --merge
    /// completes it. A folder with other files, or a file, is refused unless --force.
    #[arg(short = 'o', long = "output", alias = "out", value_name = "DIR")]
    pub out: Option<PathBuf>,
    #[arg(long, help = super::common::FORCE_HELP)]
    pub force: bool,
    /// Do not run units: merge the parts every shard wrote and summarise.
    #[arg(long)]
    pub merge: bool,
    /// Do not draw the figure.
    #[arg(long)]
    pub no_figures: bool,
    /// Build and certify the reduced model even if a certified one of the same structure,
    /// point, band, range and tolerance is in the ROM cache (`.rom-cache/` beside the output
    /// folder, or the folder RFMLAB_ROM_CACHE names), which the shards share otherwise.
    #[arg(long)]
    pub no_cache: bool,
    /// Print a JSON summary (folder, shard, units, checks) on stdout.
    #[arg(long)]
    pub json: bool,
}

/// Progress for a log: a line per step with its time when stderr is not a terminal (a
/// terminal shows the bars instead); nothing when quiet.
struct Log {
    t0: Instant,
    on: bool,
}

impl Log {
    fn new(g: &Global) -> Log {
        Log {
            t0: Instant::now(),
            on: !g.quiet && !std::io::IsTerminal::is_terminal(&std::io::stderr()),
        }
    }
    fn say(&self, m: &str) {
        if self.on {
            eprintln!("[{:8.1} s] {m}", self.t0.elapsed().as_secs_f64());
        }
    }
}

/// Run this process's shard into `dir`, its certified ROM read from or saved to the folder
/// `rom_cache` (None: built); returns the number of units and the seconds.
fn run_shard_into(
    spec: &ValidationSpec,
    shard: Shard,
    dir: &Path,
    rom_cache: Option<&Path>,
    g: &Global,
    log: &Log,
) -> anyhow::Result<(usize, f64)> {
    let t0 = Instant::now();
    log.say("setting up the structure and its reduced model");
    let sp = spinner(g, "structure and ROM");
    let setup = Setup::with_rom_cache(spec, rom_cache)?;
    sp.finish_and_clear();
    let setup_s = t0.elapsed().as_secs_f64();
    let n = units(spec)
        .iter()
        .enumerate()
        .filter(|(k, _)| shard.owns(*k))
        .count();
    log.say(&format!(
        "setup done in {setup_s:.1} s (ROM {} vectors, {}); shard {}/{}: {n} units",
        setup.rom_basis,
        match rom_cache.filter(|_| setup.rom_from_cache) {
            Some(dir) => format!("read from {}", dir.display()),
            None => "built".into(),
        },
        shard.index,
        shard.count
    ));
    let pb = progress(
        g,
        n as u64,
        &format!("shard {}/{}", shard.index, shard.count),
    );
    let done = AtomicUsize::new(0);
    let step = n.div_ceil(10).max(1);
    let secs = run_and_write(spec, &setup, setup_s, shard, dir, &|| {
        pb.inc(1);
        let k = done.fetch_add(1, Ordering::Relaxed) + 1;
        if k.is_multiple_of(step) || k == n {
            log.say(&format!("{k} of {n} units done"));
        }
    })?;
    pb.finish_and_clear();
    Ok((n, secs))
}

/// Every file under `dir`, relative to it, sorted.
fn files_under(dir: &Path) -> Vec<String> {
    fn walk(root: &Path, d: &Path, out: &mut Vec<String>) {
        let Ok(rd) = std::fs::read_dir(d) else {
            return;
        };
        for e in rd.flatten() {
            let p = e.path();
            if p.is_dir() {
                walk(root, &p, out);
            } else if let Ok(rel) = p.strip_prefix(root) {
                out.push(rel.to_string_lossy().into_owned());
            }
        }
    }
    let mut out = Vec::new();
    walk(dir, dir, &mut out);
    out.sort();
    out
}

/// Write `dir/manifest.json` listing every file under `dir` (with its SHA-256).
fn write_manifest(spec: &ValidationSpec, dir: &Path, note: &str) -> anyhow::Result<()> {
    let mut m = Manifest::new(&spec.file, Some(spec.seed));
    for f in files_under(dir) {
        if f != MANIFEST {
            let hash = sha256_file(dir.join(&f)).ok();
            m.add_file(f, hash);
        }
    }
    m.add_note(note.to_string());
    m.write(dir.join(MANIFEST))?;
    Ok(())
}

pub fn run(a: &ValidateArgs, g: &Global) -> anyhow::Result<()> {
    let shard = Shard::parse(&a.shard).map_err(|e| InputError(e.to_string()))?;
    let spec = load_validation(&a.file)?;
    let out = a.out.clone().unwrap_or_else(|| spec.output_dir.clone());
    // The output contract before anything is computed.
    let replace = if (a.merge || shard.count > 1) && has_manifest(&out) {
        // The shards of one run share the folder: its manifest marks it as rfmlab's, and the
        // parts the other shards wrote into it since are rfmlab's too.
        rfmlab::output::Replace::forced(a.force)
    } else {
        super::common::claim_folder(&out, a.force)?
    };
    let log = Log::new(g);
    // `.rom-cache/` beside the results (or RFMLAB_ROM_CACHE), as `rfmlab run` keeps its ROMs:
    // the shards share it
    let rom_cache = (!a.no_cache).then(|| rfmlab::stage::rom_cache_dir(&out));
    let cmd = std::env::args().collect::<Vec<_>>().join(" ");
    let mut units_run = None;
    let verdict = if !a.merge && shard.count == 1 {
        // One process: everything is written into a temporary sibling that is swapped in at
        // the end (an interrupted run leaves the earlier folder, or none).
        Some(replace_dir_as(&out, replace, |tmp| -> anyhow::Result<_> {
            units_run = Some(run_shard_into(
                &spec,
                shard,
                tmp,
                rom_cache.as_deref(),
                g,
                &log,
            )?);
            log.say("merging and summarising");
            let v = merge_and_summarise(&spec, tmp, !a.no_figures, &cmd)?;
            write_manifest(&spec, tmp, "statistical validation, one process")?;
            Ok(v)
        })?)
    } else {
        // Shards share the folder: each writes its parts; the manifest (written first, so
        // that the other shards recognise the folder as rfmlab's) is completed by --merge.
        std::fs::create_dir_all(&out)
            .map_err(|e| anyhow::anyhow!("creating {}: {e}", out.display()))?;
        if !has_manifest(&out) {
            write_manifest(
                &spec,
                &out,
                "statistical validation: parts of a sharded run",
            )?;
        }
        if !a.merge {
            units_run = Some(run_shard_into(
                &spec,
                shard,
                &out,
                rom_cache.as_deref(),
                g,
                &log,
            )?);
        }
        if a.merge || shard.count == 1 {
            log.say("merging and summarising");
            let v = merge_and_summarise(&spec, &out, !a.no_figures, &cmd)?;
            write_manifest(&spec, &out, "statistical validation: merged shards")?;
            Some(v)
        } else {
            None
        }
    };
    let failed = verdict
        .as_ref()
        .map_or(0, |v| v.checks.iter().filter(|c| !c.1).count());
    if a.json {
        return print_json(&json!({
            "file": spec.file.display().to_string(),
            "output_dir": out.display().to_string(),
            "shard": shard.index,
            "shards": shard.count,
            "units": units_run.map(|u| u.0),
            "seconds": units_run.map(|u| u.1),
            "merged": verdict.is_some(),
            "checks": verdict.as_ref().map(|v| v.checks.iter().map(|(c, ok)| json!({"check": c, "pass": ok})).collect::<Vec<_>>()),
            "failed": failed,
        }));
    }
    if !g.quiet {
        if let Some((n, secs)) = units_run {
            eprintln!(
                "shard {}/{}: {n} units in {secs:.1} s; parts in {}",
                shard.index,
                shard.count,
                out.display()
            );
        }
        if let Some(v) = &verdict {
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
