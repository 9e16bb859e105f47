//! Atomic replacement of a whole folder: fill a temporary sibling `<name>.tmp-<pid>`, then
//! swap it with the target.
//!
//! On Linux the swap is one `renameat2(RENAME_EXCHANGE)`: at every instant the target path
//! holds either the complete old folder or the complete new one (a kill at any moment
//! cannot leave it missing); the old folder, now at the temporary path, is then deleted.
//! Elsewhere (or on a file system without the exchange) the old folder is renamed to
//! `<name>.old-<pid>` and the new one into place; a kill between those two renames leaves
//! the target missing until the next call, which puts `<name>.old-*` back first.
//!
//! Temporary (`.tmp-<pid>`) and old (`.old-<pid>`) siblings left by a killed process (one no
//! longer running, on Linux; any other process elsewhere) are deleted by the next call for
//! the same target.
//!
//! What may be replaced is the output contract's ([`super::contract`]): [`replace_dir`]
//! replaces only an absent or empty folder or one rfmlab wrote; [`replace_dir_as`] with
//! [`Replace::Force`] replaces anything, a regular file included.

use super::contract::{claim_folder, Replace};
use super::OutputError;
use std::path::{Path, PathBuf};

/// `<dir>.<suffix>` beside `dir`.
fn sibling(dir: &Path, suffix: &str) -> PathBuf {
    let name = dir
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "results".into());
    dir.with_file_name(format!("{name}.{suffix}"))
}

/// Remove a folder with its contents, or a file.
fn remove_any(p: &Path) -> std::io::Result<()> {
    if std::fs::symlink_metadata(p)?.is_dir() {
        std::fs::remove_dir_all(p)
    } else {
        std::fs::remove_file(p)
    }
}

/// Whether process `pid` may still be running (so its temporary folder is not stale).
fn alive(pid: u32) -> bool {
    if pid == std::process::id() {
        return true;
    }
    #[cfg(target_os = "linux")]
    {
        Path::new(&format!("/proc/{pid}")).exists()
    }
    #[cfg(not(target_os = "linux"))]
    {
        false
    }
}

/// Delete stale `<target>.tmp-<pid>` folders; restore a `<target>.old-<pid>` when the target
/// is missing (a swap killed between its two renames), else delete stale ones.
pub fn clean_stale(target: &Path) -> Result<(), OutputError> {
    let Some(name) = target.file_name().map(|n| n.to_string_lossy().into_owned()) else {
        return Ok(());
    };
    let parent = match target.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let Ok(entries) = std::fs::read_dir(&parent) else {
        return Ok(());
    };
    let mut olds = Vec::new();
    for e in entries.flatten() {
        let file_name = e.file_name().to_string_lossy().into_owned();
        let Some(rest) = file_name.strip_prefix(&format!("{name}.")) else {
            continue;
        };
        let (kind, pid) = match rest.split_once('-') {
            Some((k @ ("tmp" | "old"), p)) => match p.parse::<u32>() {
                Ok(pid) => (k, pid),
                Err(_) => continue,
            },
            _ => continue,
        };
        if alive(pid) {
            continue;
        }
        if kind == "old" {
            olds.push(e.path());
        } else {
            remove_any(&e.path())
                .map_err(|err| OutputError::io(e.path(), "remove stale temporary folder", err))?;
        }
    }
    for old in olds {
        if !target.exists() {
            std::fs::rename(&old, target)
                .map_err(|e| OutputError::io(&old, "restore the previous results from", e))?;
        } else {
            remove_any(&old)
                .map_err(|e| OutputError::io(&old, "remove stale previous results", e))?;
        }
    }
    Ok(())
}

/// Swap the complete folder `new` into `target` (see the module doc); `new` is gone after.
pub fn swap_dir(new: &Path, target: &Path) -> Result<(), OutputError> {
    #[cfg(target_os = "linux")]
    if target.exists() {
        use rustix::fs::{renameat_with, RenameFlags, CWD};
        if renameat_with(CWD, new, CWD, target, RenameFlags::EXCHANGE).is_ok() {
            // `new` now holds the previous results (a folder, or a file replaced by force).
            let _ = remove_any(new);
            return Ok(());
        }
    }
    let old = sibling(target, &format!("old-{}", std::process::id()));
    if std::fs::symlink_metadata(target).is_ok() {
        std::fs::rename(target, &old)
            .map_err(|e| OutputError::io(target, "move the previous results aside", e))?;
    }
    if let Err(e) = std::fs::rename(new, target) {
        let _ = std::fs::rename(&old, target);
        return Err(OutputError::io(
            target,
            "move the new results into place",
            e,
        ));
    }
    if std::fs::symlink_metadata(&old).is_ok() {
        let _ = remove_any(&old);
    }
    Ok(())
}

/// Fill a fresh temporary sibling of `target` with `fill` (given its path), then swap it into
/// place. On error the temporary folder is removed and `target` is untouched. `target` must be
/// absent, an empty folder or a folder rfmlab wrote ([`Replace::IfOurs`]); else nothing is
/// written and the error is [`OutputError::Refused`].
pub fn replace_dir<T, E>(target: &Path, fill: impl FnOnce(&Path) -> Result<T, E>) -> Result<T, E>
where
    E: From<OutputError>,
{
    replace_dir_as(target, Replace::IfOurs, fill)
}

/// [`replace_dir`] with the contract's choice: [`Replace::Force`] replaces whatever is at
/// `target` (a folder rfmlab did not write, a file) as a whole. The contract is checked before
/// `fill` runs and again just before the swap.
pub fn replace_dir_as<T, E>(
    target: &Path,
    replace: Replace,
    fill: impl FnOnce(&Path) -> Result<T, E>,
) -> Result<T, E>
where
    E: From<OutputError>,
{
    claim_folder(target, replace)?;
    clean_stale(target)?;
    let tmp = sibling(target, &format!("tmp-{}", std::process::id()));
    if std::fs::symlink_metadata(&tmp).is_ok() {
        remove_any(&tmp).map_err(|e| OutputError::io(&tmp, "remove stale temporary folder", e))?;
    }
    if let Some(p) = target.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(p)
            .map_err(|e| OutputError::io(p, "create the results' parent folder", e))?;
    }
    std::fs::create_dir(&tmp).map_err(|e| OutputError::io(&tmp, "create temporary folder", e))?;
    let out = match fill(&tmp) {
        Ok(v) => v,
        Err(e) => {
            let _ = std::fs::remove_dir_all(&tmp);
            return Err(e);
        }
    };
    let swapped = claim_folder(target, replace).and_then(|_| swap_dir(&tmp, target));
    if let Err(e) = swapped {
        let _ = std::fs::remove_dir_all(&tmp);
        return Err(e.into());
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn replace_keeps_the_old_folder_on_error_and_swaps_on_success() {
        let root = tempfile::tempdir().unwrap();
        let target = root.path().join("res");
        std::fs::create_dir(&target).unwrap();
        std::fs::write(target.join("a"), "old").unwrap();
        let mut manifest = super::super::Manifest::new("s.toml", None);
        manifest.add_file("a", None);
        manifest.write(target.join("manifest.json")).unwrap();
        // A temporary folder and an old folder of a process that no longer runs.
        let dead = u32::MAX - 1;
        std::fs::create_dir(root.path().join(format!("res.tmp-{dead}"))).unwrap();
        std::fs::create_dir(root.path().join(format!("res.old-{dead}"))).unwrap();
        let r: Result<(), OutputError> = replace_dir(&target, |p| {
            std::fs::write(p.join("a"), "half").unwrap();
            Err(OutputError::io(p, "write", std::io::Error::other("boom")))
        });
        assert!(r.is_err());
        assert_eq!(std::fs::read_to_string(target.join("a")).unwrap(), "old");
        replace_dir::<_, OutputError>(&target, |p| {
            std::fs::write(p.join("a"), "new").map_err(|e| OutputError::io(p, "write", e))
        })
        .unwrap();
        assert_eq!(std::fs::read_to_string(target.join("a")).unwrap(), "new");
        let names: Vec<String> = std::fs::read_dir(root.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        assert_eq!(names, vec!["res".to_string()], "stray folders: {names:?}");
    }

    #[test]
    fn a_foreign_folder_or_file_is_refused_untouched_and_replaced_whole_when_forced() {
        let root = tempfile::tempdir().unwrap();
        let fill = |p: &Path| -> Result<(), OutputError> {
            std::fs::write(p.join("new"), "results").map_err(|e| OutputError::io(p, "write", e))
        };
        let victim = root.path().join("victim");
        std::fs::create_dir(&victim).unwrap();
        std::fs::write(victim.join("important.txt"), "mine").unwrap();
        let afile = root.path().join("afile");
        std::fs::write(&afile, "mine too").unwrap();
        for t in [&victim, &afile] {
            let called = std::cell::Cell::new(false);
            let r = replace_dir(t, |p| {
                called.set(true);
                fill(p)
            });
            assert!(matches!(r, Err(OutputError::Refused { .. })), "{r:?}");
            assert!(!called.get(), "the folder was filled before the refusal");
        }
        assert_eq!(
            std::fs::read_to_string(victim.join("important.txt")).unwrap(),
            "mine"
        );
        assert_eq!(std::fs::read_to_string(&afile).unwrap(), "mine too");
        for t in [&victim, &afile] {
            replace_dir_as(t, Replace::Force, fill).unwrap();
            let names: Vec<String> = std::fs::read_dir(t)
                .unwrap()
                .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .collect();
            assert_eq!(names, vec!["new".to_string()]);
        }
        let mut names: Vec<String> = std::fs::read_dir(root.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        assert_eq!(names, vec!["afile".to_string(), "victim".to_string()]);
    }

    #[test]
    fn a_swap_killed_between_its_renames_is_repaired() {
        let root = tempfile::tempdir().unwrap();
        let target = root.path().join("res");
        // The state after "target -> old" of a killed process: no target, an old folder.
        let old = root.path().join(format!("res.old-{}", u32::MAX - 1));
        std::fs::create_dir(&old).unwrap();
        std::fs::write(old.join("a"), "old").unwrap();
        clean_stale(&target).unwrap();
        assert_eq!(std::fs::read_to_string(target.join("a")).unwrap(), "old");
        assert!(!old.exists());
    }
}
