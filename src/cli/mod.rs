//! The command-line interface. `anyhow` lives here only; the library returns typed errors.
//!
//! Exit codes: 0 success, 1 a run that failed for a reason other than its input,
//! 2 bad input (study file, data file, arguments): the message names the file, key and fix.

use clap::{Parser, Subcommand};

pub mod common;
mod convergence;
mod diagnose;
mod frf;
mod inspect;
mod material;
mod modes;
mod rom;
mod run;
mod simulate;
mod validate;

#[derive(Parser, Debug)]
#[command(
    name = "rfmlab",
    version,
    about = "Identify viscoelastic adhesive models in bonded joints from measured FRFs"
)]
struct Cli {
    /// No progress bars and no informational messages.
    #[arg(long, global = true)]
    quiet: bool,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Lowest complex modes of the structure of a study file.
    Modes(modes::ModesArgs),
    /// FRFs of the structure at a given modulus, on the full model.
    Frf(frf::FrfArgs),
    /// Mesh convergence table (the paper's Table 1): elements, DOFs, y-mode frequencies, loss factors, time.
    Convergence(convergence::ConvergenceArgs),
    /// Export the structure's M, K_b, S as Matrix Market files with a DOF map.
    ExportMm(frf::ExportMmArgs),
    /// Build and certify the reduced-order model of a study's structure.
    Rom(rom::RomArgs),
    /// List datasets, channels, grids, quantities, units and levels of UFF58 / CSV files.
    Inspect(inspect::InspectArgs),
    /// Run a virtual experiment and write UFF58 data plus a truth sidecar.
    Simulate(simulate::SimulateArgs),
    /// Run a study: identification, correlation, results, figures and report.
    Run(run::RunArgs),
    /// Validate a study file (and its data) without running it.
    Check(run::CheckArgs),
    /// Fit relaxation laws to measured E'(w), E''(w) (a DMA master curve): evidence loop, residual tests, Kramers-Kronig check.
    Material(material::MaterialArgs),
    /// Statistical validation of the Bayesian layer (SBC, coverage, model selection, evidence
    /// against quadrature), shardable with --shard i/n; --merge combines the shards.
    Validate(validate::ValidateArgs),
    /// Close the loop: residuals of the fit, score tests of candidate effects, refits, before/after.
    Diagnose(diagnose::DiagnoseArgs),
}

/// Parse arguments, run, print the error chain, return the exit code.
pub fn run() -> i32 {
    let cli = match Cli::try_parse() {
        Ok(c) => c,
        Err(e) => {
            let _ = e.print();
            return match e.kind() {
                clap::error::ErrorKind::DisplayHelp | clap::error::ErrorKind::DisplayVersion => 0,
                _ => 2,
            };
        }
    };
    let g = common::Global {
        quiet: cli.quiet || std::env::var_os("CI").is_some(),
    };
    let result = match &cli.command {
        Command::Modes(a) => modes::run(a, &g),
        Command::Frf(a) => frf::run(a, &g),
        Command::Convergence(a) => convergence::run(a, &g),
        Command::ExportMm(a) => frf::run_export(a, &g),
        Command::Rom(a) => rom::run(a, &g),
        Command::Inspect(a) => inspect::run(a, &g),
        Command::Simulate(a) => simulate::run(a, &g),
        Command::Run(a) => run::run(a, &g),
        Command::Check(a) => run::check(a, &g),
        Command::Material(a) => material::run(a, &g),
        Command::Validate(a) => validate::run(a, &g),
        Command::Diagnose(a) => diagnose::run(a, &g),
    };
    match result {
        Ok(()) => 0,
        Err(e) => {
            eprintln!("error: {e}");
            for cause in e.chain().skip(1) {
                eprintln!("  caused by: {cause}");
            }
            common::exit_code(&e)
        }
    }
}
