//! The command-line interface. `anyhow` lives here only; the library returns typed errors.
//!
//! Exit codes: 0 success, 1 a run that failed for a reason other than its input,
//! 2 bad input (study file, data file, arguments, an output path the output contract refuses or
//! that cannot be written): the message names the file, key or path and the fix,
//! 3 results written but some fits are not results (flagged: outside the certified modulus
//! box, at a range's edge, at the iteration limit, unphysical or not finite).

use clap::{Parser, Subcommand};

pub mod common;
mod convergence;
mod design;
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
    #[command(
        after_help = "Prints each mode's frequency, loss factor, phi^T S phi and y-dominance (--json for scripts); writes nothing.\nDocs: docs/study-files.md (the [structure] section), docs/method.md (IEM)."
    )]
    Modes(modes::ModesArgs),
    /// FRFs of the structure at a given modulus, on the full model.
    #[command(
        after_help = "Writes: --out FILE.parquet, one row per line and FRF (accelerance, optionally dH'/dE').\nDocs: docs/outputs.md (section rfmlab frf: every column with units)."
    )]
    Frf(frf::FrfArgs),
    /// Mesh convergence table (the paper's Table 1): elements, DOFs, y-mode frequencies, loss factors, time.
    #[command(
        after_help = "Prints the table (--json for scripts); writes nothing.\nDocs: docs/validation.md (the mesh study against the paper), docs/performance.md."
    )]
    Convergence(convergence::ConvergenceArgs),
    /// Export the structure's M, K_b, S as Matrix Market files with a DOF map.
    #[command(
        after_help = "Writes: DIR/M.mtx, DIR/K_b.mtx, DIR/S.mtx (DIR/C_b.mtx, DIR/D_b.mtx with damping), DIR/dofmap.csv and DIR/manifest.json.\nDocs: docs/data.md (the Matrix Market files), docs/study-files.md ([structure.import]), docs/outputs.md (Output contract)."
    )]
    ExportMm(frf::ExportMmArgs),
    /// Build and certify the reduced-order model of a study's structure.
    #[command(
        after_help = "Prints the ROM's size, certificate and timings (--json for scripts); writes nothing.\nDocs: docs/method.md (the certified reduced-order model), docs/performance.md."
    )]
    Rom(rom::RomArgs),
    /// List datasets, channels, grids, quantities, units and levels of UFF58 / CSV files.
    #[command(
        after_help = "Prints one row per dataset (--json for scripts); writes nothing.\nDocs: docs/data.md (UFF58 and CSV formats)."
    )]
    Inspect(inspect::InspectArgs),
    /// Run a virtual experiment and write UFF58 data plus a truth sidecar.
    #[command(
        after_help = "Writes: one UFF58 file per level, <output stem>_<level>.uff, and <output stem>.truth.json beside them.\nDocs: docs/study-files.md (experiment files), docs/data.md."
    )]
    Simulate(simulate::SimulateArgs),
    /// Run a study: identification, correlation, results, figures and report.
    #[command(
        after_help = RUN_HELP
    )]
    Run(run::RunArgs),
    /// Validate a study file (and its data) without running it.
    #[command(
        after_help = "Prints OK with the model size, levels and models (--json for scripts); writes nothing. Errors name the file, the key and the fix (exit code 2); -o DIR checks that `rfmlab run -o DIR` may write there.\nDocs: docs/study-files.md (every key with units and defaults), docs/outputs.md (Output contract)."
    )]
    Check(run::CheckArgs),
    /// Fit relaxation laws to measured E'(w), E''(w) (a DMA master curve): evidence loop, residual tests, Kramers-Kronig check.
    #[command(
        after_help = MATERIAL_HELP
    )]
    Material(material::MaterialArgs),
    /// Statistical validation of the Bayesian layer (SBC, coverage, model selection, evidence
    /// against quadrature), shardable with --shard i/n; --merge combines the shards.
    #[command(
        after_help = VALIDATE_HELP
    )]
    Validate(validate::ValidateArgs),
    /// Close the loop: residuals of the fit, score tests of candidate effects, refits, before/after.
    #[command(
        after_help = DIAGNOSE_HELP
    )]
    Diagnose(diagnose::DiagnoseArgs),
    /// Plan the test: where the sensors go, in which directions, where the shaker drives, with the posterior each design will give.
    #[command(
        after_help = DESIGN_HELP
    )]
    Design(design::DesignArgs),
}

/// `rfmlab run --help`: what it writes (tests/suite/docs.rs checks the tables against docs/outputs.md).
const RUN_HELP: &str = "Writes results/<name>/ (or [study] output_dir): report.md, manifest.json, figures fig_*.png/.svg and parquet tables:
  frf, parameters, iterations, correlation, correlation_curves, modulus, svd, modal, sensitivity,
  discretisation (a meshed joint's estimated mesh error per mode);
  with [inference]: draws, summary, starts, laplace, sampler_runs, evidence, model_comparison, ppc, predictive,
  pointwise_loglik, level_change, level_evidence, redundancy, basins;
  with [closed_loop]: closed_loop/ (residuals, candidates, closed_loop, verdict, signatures, closed_loop.md).
Docs: docs/outputs.md (every table, column and figure), docs/study-files.md (every key), docs/method.md.";

/// `rfmlab material --help`.
const MATERIAL_HELP: &str = "Writes results/<name>/ (or [study] output_dir): report.md, manifest.json, figures and parquet tables
  steps, parameters, residuals, kk.
Docs: docs/outputs.md (section rfmlab material), docs/study-files.md (material studies).";

/// `rfmlab validate --help`.
const VALIDATE_HELP: &str = "Writes DIR/ (or the file's output_dir): summary.md, sbc_ranks.png and parquet tables
  sbc, coverage, selection, quadrature (each shard's part as DIR/<table>/shard=<i>/part.parquet),
  sbc_summary, sbc_histogram, coverage_summary, selection_summary, quadrature_summary.
Docs: docs/outputs.md (section rfmlab validate), docs/validation.md, docs/study-files.md (validation files).";

/// `rfmlab diagnose --help`.
const DIAGNOSE_HELP: &str = "Writes results/<name>.diagnose/: closed_loop.md, manifest.json, residuals_<level>.png and parquet tables
  residuals, candidates, closed_loop, verdict, signatures, and mesh when a refined mesh was compared;
  closed_loop.md's first line is the status per level.
Docs: docs/closed-loop.md (what each status means and what to do next), docs/outputs.md (closed-loop tables).";

/// `rfmlab design --help`.
const DESIGN_HELP: &str = "Writes results/<name>.design/: report.md, manifest.json, design_information.png/.svg and parquet tables
  design (the ranked designs, the study's own first), design_candidates (every candidate sensor and what it adds).
Docs: docs/planning.md (planning a test, a worked example), docs/study-files.md ([design]), docs/outputs.md (design tables).";

/// Restore the default action of SIGPIPE (the Rust runtime ignores it, so that a write to a
/// closed pipe fails and `println!` panics): a command whose reader went away, as in
/// `rfmlab inspect F | head`, then ends quietly as other command-line tools do (status 141
/// in the shell).
fn default_sigpipe() {
    #[cfg(unix)]
    // SAFETY: called once at the start of main, before any thread is spawned; SIG_DFL is a
    // valid disposition of SIGPIPE.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

/// Parse arguments, run, print the error chain, return the exit code.
pub fn run() -> i32 {
    default_sigpipe();
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
        Command::Design(a) => design::run(a, &g),
    };
    match result {
        Ok(()) => 0,
        Err(e) if e.is::<common::FlaggedFits>() => {
            eprintln!("warning: {e}");
            common::exit_code(&e)
        }
        Err(e) => {
            eprintln!("error: {e}");
            for cause in e.chain().skip(1) {
                eprintln!("  caused by: {cause}");
            }
            common::exit_code(&e)
        }
    }
}
