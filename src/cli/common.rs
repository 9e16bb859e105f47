//! Shared CLI plumbing: global flags, exit codes, progress bars.

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

/// 2 when any error in the chain is an input error (study file, data file, arguments), else 1.
pub fn exit_code(e: &anyhow::Error) -> i32 {
    for cause in e.chain() {
        if cause.is::<InputError>()
            || cause.is::<rfmlab::study::StudyError>()
            || cause.is::<rfmlab::data::DataError>()
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
            "{msg:>24} [{bar:40}] {pos}/{len} {elapsed_precise}",
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
