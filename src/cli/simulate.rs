//! `rfmlab simulate EXPERIMENT.toml`: the virtual experiment. Writes UFF58 (H1 and coherence,
//! labelled as simulated) and a `<output>.truth.json` sidecar stating the truth.

use super::common::{print_json, progress, Global};
use rfmlab::simulate::SimulateError;
use rfmlab::study::experiment::load_experiment;
use serde_json::json;
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct SimulateArgs {
    /// Experiment file (truth, structure and measurement chain).
    pub experiment: PathBuf,
    /// The data file to write instead of the file's `experiment.output`: one file per level,
    /// `<stem>_<level>.uff`, and `<stem>.truth.json` beside it. A file there that rfmlab
    /// did not write, or a folder at this path, is refused unless --force.
    #[arg(short = 'o', long = "output", alias = "out", value_name = "FILE")]
    pub out: Option<PathBuf>,
    #[arg(long, help = super::common::FORCE_HELP)]
    pub force: bool,
    /// Print a JSON summary for scripts.
    #[arg(long)]
    pub json: bool,
}

pub fn run(a: &SimulateArgs, g: &Global) -> anyhow::Result<()> {
    let ex = load_experiment(&a.experiment)?;
    let out = a.out.clone().unwrap_or_else(|| ex.output.clone());
    // The output contract before anything is computed: `out` itself (a folder there, or a
    // file rfmlab did not write) and every file the experiment writes.
    let ours = rfmlab::simulate::is_simulated_file;
    super::common::claim_file(&out, a.force, ours)?;
    let names: Vec<&str> = ex.levels.iter().map(|l| l.name.as_str()).collect();
    let (data, sidecar) = rfmlab::simulate::planned_files(&out, &names);
    for p in data.iter().chain([&sidecar]) {
        super::common::claim_file(p, a.force, ours)?;
    }
    // The bar stands at 0 while the model and the FRF engine are built.
    let pb = progress(g, ex.levels.len() as u64, "simulating levels");
    let sim = rfmlab::simulate::simulate(&ex, &|| pb.inc(1)).map_err(|e| match e {
        // The study error itself in the chain: exit code 2.
        SimulateError::Study(e) => anyhow::Error::new(e),
        e => anyhow::Error::new(e),
    })?;
    pb.finish_and_clear();
    if !g.quiet {
        for n in &sim.notes {
            eprintln!("{n}");
        }
    }
    let (written, sidecar) = sim.write(&out)?;
    if a.json {
        return print_json(
            &json!({"files": written.iter().map(|p| p.display().to_string()).collect::<Vec<_>>(), "truth": sidecar.display().to_string()}),
        );
    }
    if !g.quiet {
        for p in &written {
            println!("wrote {}", p.display());
        }
        println!("wrote {}", sidecar.display());
    }
    Ok(())
}
