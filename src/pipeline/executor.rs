//! The [`Executor`]: the owner of a run's loop. The stages compute; the executor holds what is
//! not the algorithm's business: the ROM cache folder, the progress observers, the
//! cancellation flag (checked between steps), and the timings and counters the manifest
//! records.

use crate::stage::{Event, RunError};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

/// A progress observer: called with every [`Event`] of the run, from any thread.
pub type Observer = Arc<dyn Fn(&Event) + Send + Sync>;

/// Runs a [`super::Plan`] (see [`super::run`]).
///
/// ```
/// use rfmlab::pipeline::Executor;
/// let mut ex = Executor::new().observer(|ev| eprintln!("{ev:?}"));
/// let stop = ex.cancel_flag(); // set it from another thread (Ctrl-C) to stop the run
/// stop.store(false, std::sync::atomic::Ordering::SeqCst);
/// assert!(ex.rom_cache_dir().is_none());
/// ```
pub struct Executor {
    rom_cache: Option<PathBuf>,
    observers: Vec<Observer>,
    cancel: Arc<AtomicBool>,
    timings: Vec<(String, f64)>,
    counters: Vec<(String, u64)>,
    lap: Instant,
}

impl Default for Executor {
    fn default() -> Self {
        Executor::new()
    }
}

impl std::fmt::Debug for Executor {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Executor")
            .field("rom_cache", &self.rom_cache)
            .field("observers", &self.observers.len())
            .field("cancelled", &self.cancel.load(Ordering::SeqCst))
            .field("timings", &self.timings)
            .field("counters", &self.counters)
            .finish()
    }
}

impl Executor {
    /// No ROM cache (every run builds and certifies its ROM), no observers, not cancelled.
    pub fn new() -> Self {
        Executor {
            rom_cache: None,
            observers: Vec::new(),
            cancel: Arc::new(AtomicBool::new(false)),
            timings: Vec::new(),
            counters: Vec::new(),
            lap: Instant::now(),
        }
    }
    /// Reuse certified ROMs from `dir` (keyed by model, points, band, range and tolerance,
    /// see [`crate::rom::cache`]); a ROM built by the run is saved there.
    pub fn rom_cache(mut self, dir: impl Into<PathBuf>) -> Self {
        self.rom_cache = Some(dir.into());
        self
    }
    /// Add a progress observer.
    pub fn observer(mut self, f: impl Fn(&Event) + Send + Sync + 'static) -> Self {
        self.observers.push(Arc::new(f));
        self
    }
    /// Use `flag` as the cancellation flag (e.g. one shared with a signal handler).
    pub fn with_cancel_flag(mut self, flag: Arc<AtomicBool>) -> Self {
        self.cancel = flag;
        self
    }
    /// The cancellation flag: set it to `true` (from any thread) and the run stops at the next
    /// step with [`RunError::Cancelled`].
    pub fn cancel_flag(&self) -> Arc<AtomicBool> {
        self.cancel.clone()
    }
    /// The ROM cache folder, if any.
    pub fn rom_cache_dir(&self) -> Option<&Path> {
        self.rom_cache.as_deref()
    }
    /// Timings (step, seconds) of the last run, in order.
    pub fn timings(&self) -> &[(String, f64)] {
        &self.timings
    }
    /// Counters (name, count) of the last run, e.g. `rom builds`.
    pub fn counters(&self) -> &[(String, u64)] {
        &self.counters
    }

    /// A progress callback that tells every observer (independent of `self`'s borrow).
    pub(crate) fn progress(&self) -> impl Fn(Event) + Sync + Send + 'static {
        let obs = self.observers.clone();
        move |ev: Event| {
            for o in &obs {
                o(&ev);
            }
        }
    }
    /// `Err(Cancelled)` once the flag is set.
    pub(crate) fn check(&self) -> Result<(), RunError> {
        if self.cancel.load(Ordering::SeqCst) {
            Err(RunError::Cancelled)
        } else {
            Ok(())
        }
    }
    /// Start timing a run.
    pub(crate) fn reset(&mut self) {
        self.timings.clear();
        self.counters.clear();
        self.lap = Instant::now();
    }
    /// Record the time since the previous lap under `step`, then check for cancellation.
    pub(crate) fn lap(&mut self, step: impl Into<String>) -> Result<(), RunError> {
        self.timings
            .push((step.into(), self.lap.elapsed().as_secs_f64()));
        self.lap = Instant::now();
        self.check()
    }
    /// Record a part of the step the next [`Executor::lap`] closes (its time is already in
    /// that lap; the manifest lists it for the breakdown).
    pub(crate) fn detail(&mut self, step: impl Into<String>, seconds: f64) {
        self.timings.push((format!("  {}", step.into()), seconds));
    }
    /// Add `n` to the counter `name`.
    pub(crate) fn count(&mut self, name: &str, n: u64) {
        match self.counters.iter_mut().find(|c| c.0 == name) {
            Some(c) => c.1 += n,
            None => self.counters.push((name.to_string(), n)),
        }
    }
}
