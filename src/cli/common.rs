//! Shared CLI plumbing: global flags, exit codes, progress bars, argument parsing helpers.

use anyhow::Context;
use rfmlab::common::C64;
use std::path::Path;

/// Flags that apply to every command.
#[derive(Clone, Debug)]
pub struct Global {
    /// No progress bars or informational output (also set when CI is in the environment).
    pub quiet: bool,
}

/// Marks an error as caused by the user's input (exit code 2).
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct InputError(pub String);

/// The command wrote its results, but some fits in them are not results (exit code 3): the
/// message lists them with their reasons.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct FlaggedFits(pub String);

/// `Err(FlaggedFits)` naming every fit of `flagged`, `Ok` when there is none.
pub fn flagged_exit(flagged: &[rfmlab::pipeline::FlaggedFit]) -> anyhow::Result<()> {
    if flagged.is_empty() {
        return Ok(());
    }
    let mut m = format!(
        "{} (results written; see the warning at the top of report.md and the status columns):",
        if flagged.len() == 1 {
            "1 fit is not a result".to_string()
        } else {
            format!("{} fits are not results", flagged.len())
        }
    );
    for f in flagged {
        m.push_str(&format!("\n  {f}"));
    }
    Err(anyhow::Error::new(FlaggedFits(m)))
}

/// 3 when the results were written with flagged fits ([`FlaggedFits`]); 2 when any error in
/// the chain is an input error (study file, data file, arguments); else 1.
pub fn exit_code(e: &anyhow::Error) -> i32 {
    if e.is::<FlaggedFits>() {
        return 3;
    }
    for cause in e.chain() {
        if cause.is::<InputError>()
            || cause.is::<rfmlab::study::StudyError>()
            || cause.is::<rfmlab::data::DataError>()
            || refused_output(cause)
        {
            return 2;
        }
    }
    1
}

/// A progress bar that is hidden when quiet.
pub fn progress(g: &Global, len: u64, msg: &str) -> indicatif::ProgressBar {
    if g.quiet {
        return indicatif::ProgressBar::hidden();
    }
    let pb = indicatif::ProgressBar::new(len);
    pb.set_style(
        indicatif::ProgressStyle::with_template(
            "{msg:>28} [{bar:40}] {pos}/{len} {elapsed_precise}",
        )
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
        .progress_chars("=> "),
    );
    pb.set_message(msg.to_string());
    pb
}

/// A spinner for steps of unknown length, hidden when quiet.
pub fn spinner(g: &Global, msg: &str) -> indicatif::ProgressBar {
    if g.quiet {
        return indicatif::ProgressBar::hidden();
    }
    let pb = indicatif::ProgressBar::new_spinner();
    pb.set_message(msg.to_string());
    pb.enable_steady_tick(std::time::Duration::from_millis(120));
    pb
}

/// Parse "E',E''" (Pa) into a complex modulus.
pub fn parse_modulus(s: &str) -> Result<C64, InputError> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    let bad = || {
        InputError(format!(
            "--modulus {s:?}: give the storage and loss moduli in Pa separated by a comma, e.g. --modulus 6.974e6,1.4827e6"
        ))
    };
    if parts.len() != 2 {
        return Err(bad());
    }
    let re: f64 = parts[0].parse().map_err(|_| bad())?;
    let im: f64 = parts[1].parse().map_err(|_| bad())?;
    if !(re.is_finite() && re > 0.0 && im.is_finite() && im >= 0.0) {
        return Err(InputError(format!(
            "--modulus {s:?}: E' must be positive and E'' zero or positive (Pa)"
        )));
    }
    Ok(C64::new(re, im))
}

/// Parse "a,b" into a pair of positive increasing numbers.
pub fn parse_pair(flag: &str, s: &str) -> Result<(f64, f64), InputError> {
    let v: Vec<f64> = s.split(',').filter_map(|t| t.trim().parse().ok()).collect();
    if v.len() != 2 || !(v[0] >= 0.0 && v[1] > v[0]) {
        return Err(InputError(format!(
            "{flag} {s:?}: give two numbers low,high with 0 <= low < high"
        )));
    }
    Ok((v[0], v[1]))
}

/// Load and validate a study file (errors are input errors: exit code 2).
pub fn load_study(path: &Path) -> anyhow::Result<rfmlab::study::Study> {
    if let Ok(text) = std::fs::read_to_string(path) {
        if rfmlab::study::material::is_material_study(&text) {
            return Err(InputError(format!(
                "{}: material_data: this is a material study (E'(w), E''(w) without a structure); run it with `rfmlab material {}`",
                path.display(),
                path.display()
            ))
            .into());
        }
    }
    Ok(rfmlab::study::load(path)?)
}

/// Build the model of a study with a spinner.
pub fn build_model(
    g: &Global,
    study: &rfmlab::study::Study,
) -> anyhow::Result<rfmlab::study::build::BuiltModel> {
    let sp = spinner(g, "assembling the FE model");
    let quiet = g.quiet;
    let b = rfmlab::study::build::build_model_with(
        &study.structure,
        &study.file.display().to_string(),
        &|line| {
            if !quiet {
                sp.suspend(|| eprintln!("{line}"));
            }
        },
    )?;
    sp.finish_and_clear();
    Ok(b)
}

/// Print a value as pretty JSON.
pub fn print_json(v: &serde_json::Value) -> anyhow::Result<()> {
    println!(
        "{}",
        serde_json::to_string_pretty(v).context("JSON output")?
    );
    Ok(())
}

/// The default modulus for structure-only commands: the paper's IEM value for Level 1, mode 1.
pub const DEFAULT_MODULUS: C64 = C64::new(6.974e6, 1.4827e6);

/// Whether `cause` is the output contract's refusal or an unwritable output path (exit code 2),
/// directly or inside the error of the library call that wrote.
fn refused_output(cause: &(dyn std::error::Error + 'static)) -> bool {
    use rfmlab::output::OutputError;
    if let Some(o) = cause.downcast_ref::<OutputError>() {
        return o.is_input();
    }
    if let Some(rfmlab::stage::RunError::Output(o)) = cause.downcast_ref() {
        return o.is_input();
    }
    if let Some(rfmlab::validate::ValidateError::Output(o)) = cause.downcast_ref() {
        return o.is_input();
    }
    if let Some(rfmlab::report::material::MaterialRunError::Output(o)) = cause.downcast_ref() {
        return o.is_input();
    }
    false
}

/// The output contract's pre-flight of a results folder ([`rfmlab::output::claim_folder`]),
/// run before anything is computed: a refusal is an input error (exit code 2).
pub fn claim_folder(dir: &Path, force: bool) -> anyhow::Result<rfmlab::output::Replace> {
    let replace = rfmlab::output::Replace::forced(force);
    rfmlab::output::claim_folder(dir, replace).map_err(|e| InputError(e.to_string()))?;
    Ok(replace)
}

/// The output contract's pre-flight of an output file ([`rfmlab::output::claim_file`]; `ours`
/// recognises a file rfmlab wrote): a refusal is an input error (exit code 2).
pub fn claim_file(path: &Path, force: bool, ours: impl Fn(&Path) -> bool) -> anyhow::Result<()> {
    rfmlab::output::claim_file(path, rfmlab::output::Replace::forced(force), ours)
        .map_err(|e| InputError(e.to_string()))?;
    Ok(())
}

/// The help of `--force`, the same on every command that writes.
pub const FORCE_HELP: &str = "Replace the output even if rfmlab did not write it (a folder with other files, or a file): it is replaced as a whole. Without it, rfmlab replaces only a folder holding its own manifest.json and nothing it does not list, an empty folder or a new path (docs/outputs.md, Output contract)";
