//! One folder of certified ROMs and term ROMs for the suite's process, shared by the tests that
//! diagnose the paper's joint (the closed loop on time-domain data, on the independent data)
//! and by the in-process runs whose ROM is a fixture rather than what the test measures:
//! building and certifying them is most of a diagnosis, and a cached ROM is exact (its
//! matrices are stored bit for bit, keyed by everything it depends on), so each is built once
//! per run of the suite instead of once per test. Tests that count the run's ROMs (the default
//! study, the loop inside the run) count those built and those read from the cache.
//!
//! The folder is `<CARGO_TARGET_TMPDIR>/suite-rom-cache`, emptied at its first use in a process
//! (no ROM of an earlier build of the code is read). A test's results folder `<dir>/<name>` has
//! its cache at `<dir>/.rom-cache` (`rfmlab::stage::rom_cache_dir`); [`share`] makes that a
//! link to the shared folder, and [`lock`] makes the tests' diagnoses take turns. Under cargo,
//! `RFMLAB_ROM_CACHE` (`target/rom-cache`, .cargo/config.toml) takes the place of both.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard, OnceLock};

/// The shared folder, emptied at its first use in this process.
fn folder() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("suite-rom-cache");
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    })
}

/// The ROM cache of the suite's in-process runs whose ROM is a fixture (not what the test
/// measures): the folder `RFMLAB_ROM_CACHE` names (under cargo, `target/rom-cache`, which the
/// `rfmlab` processes the tests start use as well), else the shared folder. A run that loads
/// its ROM from it gives the results of the run that built it: the entry is that ROM, bit for
/// bit, under a key of everything it depends on.
pub fn runs_folder() -> PathBuf {
    match std::env::var_os(rfmlab::stage::ROM_CACHE_ENV).filter(|d| !d.is_empty()) {
        Some(d) => PathBuf::from(d),
        None => folder().to_path_buf(),
    }
}

/// An executor whose ROMs go through [`runs_folder`].
pub fn executor() -> rfmlab::pipeline::Executor {
    rfmlab::pipeline::Executor::new().rom_cache(runs_folder())
}

/// Assert that the run of `results` used one certified ROM, built or read from the cache: its
/// counters are `rom builds` and `rom cache loads` and nothing else, and they sum to one
/// (`what` says why, in the message).
pub fn assert_one_rom(results: &rfmlab::pipeline::Results, what: &str) {
    let c = results.counters();
    let count = |name: &str| c.iter().find(|x| x.0 == name).map_or(0, |x| x.1);
    assert_eq!(
        (count("rom builds") + count("rom cache loads"), c.len()),
        (1, 2),
        "{what}: {c:?}"
    );
}

/// Make `<dir>/.rom-cache` (the ROM cache of results folders in `dir`) the shared folder.
pub fn share(dir: &Path) {
    let link = dir.join(".rom-cache");
    if std::fs::symlink_metadata(&link).is_ok() {
        return;
    }
    std::os::unix::fs::symlink(folder(), &link).unwrap();
}

/// Held while a test diagnoses a study with the shared folder: one diagnosis at a time (the
/// studies of the time-domain loop and of the independent data share their joint, and so their
/// ROMs), so that the second of two tests run at the same time reads what the first built
/// instead of building it again. A test that failed while holding it does not stop the others.
pub fn lock() -> MutexGuard<'static, ()> {
    static LOCK: Mutex<()> = Mutex::new(());
    LOCK.lock().unwrap_or_else(|e| e.into_inner())
}
