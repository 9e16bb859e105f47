//! Writing a shard's parts and merging the parts of all shards: `DIR/<table>/shard=<i>/
//! part.parquet` per table (hive-style, [`crate::output::shards`]), `DIR/runs/shard=<i>.json`
//! with the shard's unit count and run time; the merge writes `DIR/<table>.parquet`, the
//! summary tables, `sbc_ranks.png/svg` and `summary.md`.

use super::summary::{summarise, Verdict};
use super::{run_shard, Setup, ValidateError, ValidationSpec, TABLES};
use crate::output::shards::{merge_parts, write_part, Shard};
use crate::output::{write_atomic_bytes, OutputError, Table};
use serde_json::json;
use std::path::Path;

fn io(path: &Path, e: std::io::Error) -> ValidateError {
    ValidateError::Setup(format!("{}: {e}", path.display()))
}

/// Run `shard`'s units and write its parts and run record. Returns the shard's run time (s).
pub fn run_and_write(
    spec: &ValidationSpec,
    setup: &Setup,
    setup_seconds: f64,
    shard: Shard,
    dir: &Path,
    progress: &(dyn Fn() + Sync),
) -> Result<f64, ValidateError> {
    let r = run_shard(spec, setup, shard, progress)?;
    for t in &r.tables {
        write_part(dir, t, shard)?;
    }
    let runs = dir.join("runs");
    std::fs::create_dir_all(&runs).map_err(|e| io(&runs, e))?;
    let rec = json!({
        "validation": spec.name,
        "file": spec.file.display().to_string(),
        "shard": shard.index,
        "shards": shard.count,
        "units": r.units,
        "setup_seconds": setup_seconds,
        "seconds": r.seconds,
        "threads": rayon::current_num_threads(),
        "rom_basis": setup.rom_basis,
        "rom_certified_error": setup.rom_error,
        "rom_from_cache": setup.rom_from_cache,
    });
    let p = runs.join(format!("shard={}.json", shard.index));
    write_atomic_bytes(&p, &serde_json::to_vec_pretty(&rec).unwrap_or_default())?;
    Ok(r.seconds)
}

/// Merge the parts of every shard under `dir` (all shards of one count must be there), write
/// the merged and summary tables, the figure and `summary.md`.
pub fn merge_and_summarise(
    spec: &ValidationSpec,
    dir: &Path,
    figures: bool,
    command: &str,
) -> Result<Verdict, ValidateError> {
    let runs = dir.join("runs");
    let mut recs: Vec<serde_json::Value> = Vec::new();
    if let Ok(rd) = std::fs::read_dir(&runs) {
        for e in rd.flatten() {
            let p = e.path();
            if p.extension().is_some_and(|x| x == "json") {
                let b = std::fs::read(&p).map_err(|e| io(&p, e))?;
                recs.push(serde_json::from_slice(&b).map_err(|e| {
                    ValidateError::Output(OutputError::Json {
                        path: p.clone(),
                        source: e,
                    })
                })?);
            }
        }
    }
    let count = recs.first().and_then(|r| r["shards"].as_u64()).unwrap_or(0) as usize;
    if count == 0 {
        return Err(ValidateError::Setup(format!(
            "no shard records in {}: run `rfmlab validate {} --shard i/n --out {}` for every i first",
            runs.display(),
            spec.file.display(),
            dir.display()
        )));
    }
    let mut seen = vec![false; count];
    for r in &recs {
        let n = r["shards"].as_u64().unwrap_or(0) as usize;
        let i = r["shard"].as_u64().unwrap_or(u64::MAX) as usize;
        if n != count || i >= count {
            return Err(ValidateError::Setup(format!(
                "{} holds records of runs with {count} and {n} shards: empty the folder and rerun all shards",
                runs.display()
            )));
        }
        seen[i] = true;
    }
    if let Some(i) = seen.iter().position(|s| !s) {
        return Err(ValidateError::Setup(format!(
            "shard {i} of {count} has not run: run `rfmlab validate {} --shard {i}/{count} --out {}`",
            spec.file.display(),
            dir.display()
        )));
    }
    let merged: Vec<Table> = TABLES
        .iter()
        .map(|t| merge_parts(dir, t))
        .collect::<Result<_, _>>()?;
    for t in &merged {
        t.write_parquet(dir.join(format!("{}.parquet", t.name())))?;
    }
    let secs: Vec<f64> = recs
        .iter()
        .map(|r| r["seconds"].as_f64().unwrap_or(0.0))
        .collect();
    let setup_s = recs
        .iter()
        .map(|r| r["setup_seconds"].as_f64().unwrap_or(0.0))
        .fold(0.0, f64::max);
    let threads = recs
        .first()
        .and_then(|r| r["threads"].as_u64())
        .unwrap_or(0);
    let basis = recs
        .first()
        .and_then(|r| r["rom_basis"].as_u64())
        .unwrap_or(0);
    let header = format!(
        "# Statistical validation: {}\n\nCommand: `{command}`\n\nRun time: {} shard(s), {:.1} s of units in total (slowest shard {:.1} s) plus {:.1} s setup (structure and ROM, {basis} vectors) per shard, {threads} threads.\n\n\
Data: {}, from the frequency-domain virtual experiment of `{}`, level {} ({} N RMS). Posteriors: MAP and Laplace approximation (Gaussian in the log parameters) with log-normal priors of width sigma_ln around the generating truth; evidence: Laplace (and stepping-stone where listed). Evidence depends on the priors' widths (see the validation file).\n\n",
        spec.name,
        count,
        secs.iter().sum::<f64>(),
        secs.iter().copied().fold(0.0, f64::max),
        setup_s,
        match spec.data {
            super::DataSource::NoiseModel => "the likelihood's own generative model (E[H1] at the drawn parameters plus Gaussian noise with the noise model's variances, inferred with those variances; the coherence that sets them comes from a virtual-experiment run)",
            super::DataSource::VirtualExperiment => "the virtual experiment's H1 and coherence themselves (window leakage and averaging: the noise model's misspecification is part of what is checked)",
        },
        spec.experiment.file.display(),
        spec.experiment.levels[spec.level].name,
        spec.experiment.levels[spec.level].force_rms_n,
    );
    let bins = spec.sbc.as_ref().map_or(10, |s| s.bins);
    let v = summarise(&merged, dir, figures, bins, &header)?;
    for t in &v.tables {
        t.write_parquet(dir.join(format!("{}.parquet", t.name())))?;
    }
    write_atomic_bytes(dir.join("summary.md"), v.markdown.as_bytes())?;
    Ok(v)
}
