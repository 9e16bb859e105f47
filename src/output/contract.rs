//! The output contract: what rfmlab may replace.
//!
//! A command writes its results into one folder (or, for `simulate` and `frf`, into named
//! files). rfmlab replaces only what it made itself:
//! - a folder that does not exist, is empty, or holds rfmlab's `manifest.json` (a folder an
//!   earlier run of rfmlab wrote) is replaced as a whole, atomically ([`super::swap`]);
//! - a folder holding anything else, or a regular file where a folder is to go, is refused
//!   with [`OutputError::Refused`] (exit code 2 on the command line) naming the path, what is
//!   there and the fix, unless the caller asks to replace it anyway ([`Replace::Force`],
//!   `--force` on the command line), in which case it is replaced as a whole like any other;
//! - a file output (a parquet table, a UFF58 file, a truth sidecar) is replaced when it does
//!   not exist or when rfmlab wrote it (the caller says how to recognise its own files), and
//!   refused otherwise unless forced; a folder where a file is to go is always refused.
//!
//! The commands check their outputs with [`claim_folder`] / [`claim_file`] before they
//! compute anything, so a refusal comes at once; the writers check again just before they
//! swap (another process may have written there meanwhile).

use super::{Manifest, OutputError};
use std::path::{Path, PathBuf};

/// The name of the manifest that marks a folder as rfmlab's.
pub const MANIFEST: &str = "manifest.json";

/// Whether an output may replace what rfmlab did not write.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Replace {
    /// Replace only what does not exist, an empty folder or what rfmlab wrote (the default).
    #[default]
    IfOurs,
    /// Replace whatever is there (`--force`).
    Force,
}

impl Replace {
    /// [`Replace::Force`] when `force`, else [`Replace::IfOurs`].
    pub fn forced(force: bool) -> Replace {
        if force {
            Replace::Force
        } else {
            Replace::IfOurs
        }
    }
}

/// What is at an output path.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Found {
    /// Nothing: the path does not exist.
    Nothing,
    /// An empty folder (rfmlab's own temporary files aside).
    EmptyFolder,
    /// A folder holding rfmlab's `manifest.json` and nothing it does not list.
    OursFolder,
    /// A folder rfmlab wrote (it holds rfmlab's `manifest.json`) holding entries the manifest
    /// does not list: files a user put there. How many, and one of their names.
    OursWithOthers { entries: usize, example: String },
    /// A folder holding something else: how many entries, and one of their names.
    ForeignFolder { entries: usize, example: String },
    /// A regular file (or anything that is not a folder).
    File,
}

impl Found {
    /// What is there, in words, for the refusal message.
    fn describe(&self) -> String {
        match self {
            Found::Nothing => "nothing".into(),
            Found::EmptyFolder => "an empty folder".into(),
            Found::OursFolder => "a results folder rfmlab wrote".into(),
            Found::OursWithOthers { entries, example } => format!(
                "a results folder rfmlab wrote, holding {entries} {} its {MANIFEST} does not list ('{example}'{}): files put there since",
                if *entries == 1 { "entry" } else { "entries" },
                if *entries > 1 { ", ..." } else { "" }
            ),
            Found::ForeignFolder { entries, example } => format!(
                "a folder rfmlab did not write (no rfmlab {MANIFEST}) holding {entries} {} ('{example}'{})",
                if *entries == 1 { "entry" } else { "entries" },
                if *entries > 1 { ", ..." } else { "" }
            ),
            Found::File => "a file, not a folder".into(),
        }
    }
}

/// Whether `dir/manifest.json` is a manifest rfmlab wrote (it parses as a [`Manifest`]).
pub fn has_manifest(dir: &Path) -> bool {
    let p = dir.join(MANIFEST);
    p.is_file() && Manifest::read(&p).is_ok()
}

/// The entries of the folder `dir` (rfmlab's temporary files and the manifest aside) that its
/// manifest does not list, as (count, first name); a listed `sub/file` covers the entry `sub`.
fn unlisted_entries(dir: &Path) -> (usize, String) {
    let listed: Vec<String> = Manifest::read(dir.join(MANIFEST))
        .map(|m| m.files.into_iter().map(|f| f.name).collect())
        .unwrap_or_default();
    let covered = |name: &str| {
        listed.iter().any(|l| {
            l == name
                || l.strip_prefix(name)
                    .is_some_and(|rest| rest.starts_with('/') || rest.starts_with('\\'))
        })
    };
    let mut count = 0usize;
    let mut example = String::new();
    if let Ok(rd) = std::fs::read_dir(dir) {
        let mut names: Vec<String> = rd
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        for name in names {
            if name == MANIFEST || crate::fs_atomic::is_temp_name(&name) || covered(&name) {
                continue;
            }
            if count == 0 {
                example = name;
            }
            count += 1;
        }
    }
    (count, example)
}

/// What is at `path`, seen as a results folder.
pub fn inspect_folder(path: &Path) -> Found {
    let Ok(meta) = std::fs::metadata(path) else {
        return match std::fs::symlink_metadata(path) {
            // A dangling link is still something the user put there.
            Ok(_) => Found::File,
            Err(_) => Found::Nothing,
        };
    };
    if !meta.is_dir() {
        return Found::File;
    }
    if has_manifest(path) {
        let (entries, example) = unlisted_entries(path);
        return if entries == 0 {
            Found::OursFolder
        } else {
            Found::OursWithOthers { entries, example }
        };
    }
    let mut entries = 0usize;
    let mut example = String::new();
    if let Ok(rd) = std::fs::read_dir(path) {
        for e in rd.flatten() {
            let name = e.file_name().to_string_lossy().into_owned();
            if crate::fs_atomic::is_temp_name(&name) {
                continue;
            }
            if entries == 0 {
                example = name;
            }
            entries += 1;
        }
    }
    if entries == 0 {
        Found::EmptyFolder
    } else {
        Found::ForeignFolder { entries, example }
    }
}

/// The nearest existing ancestor of `path` (itself included), `.` for a relative path none of
/// whose components exists.
fn existing_ancestor(path: &Path) -> PathBuf {
    let mut p = path;
    loop {
        if p.as_os_str().is_empty() {
            return PathBuf::from(".");
        }
        if p.exists() {
            return p.to_path_buf();
        }
        match p.parent() {
            Some(q) => p = q,
            None => return PathBuf::from("."),
        }
    }
}

/// Whether the current user may create entries in the folder `dir` (nothing is written).
fn can_write_into(dir: &Path) -> bool {
    #[cfg(target_os = "linux")]
    {
        use rustix::fs::{access, Access};
        access(dir, Access::WRITE_OK | Access::EXEC_OK).is_ok()
    }
    #[cfg(not(target_os = "linux"))]
    {
        std::fs::metadata(dir).is_ok_and(|m| !m.permissions().readonly())
    }
}

/// Checks that rfmlab can create `path` (a folder or a file): the nearest existing folder
/// above it is a folder the user may write into. Nothing is written.
pub fn check_writable(path: &Path) -> Result<(), OutputError> {
    let parent = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    let anc = existing_ancestor(parent);
    if !anc.is_dir() {
        return Err(OutputError::NotWritable {
            path: path.to_path_buf(),
            reason: format!("'{}' is a file, not a folder", anc.display()),
        });
    }
    if !can_write_into(&anc) {
        return Err(OutputError::NotWritable {
            path: path.to_path_buf(),
            reason: format!("the folder '{}' is not writable", anc.display()),
        });
    }
    Ok(())
}

/// The pre-flight of a results folder: `Ok` with what is there when rfmlab may replace it
/// ([`Replace`]) and can write there; [`OutputError::Refused`] naming the path, what is there
/// and the fix otherwise. Writes nothing.
pub fn claim_folder(path: &Path, replace: Replace) -> Result<Found, OutputError> {
    let found = inspect_folder(path);
    match (&found, replace) {
        (Found::Nothing | Found::EmptyFolder | Found::OursFolder, _) | (_, Replace::Force) => {}
        (Found::OursWithOthers { .. }, _) => {
            return Err(OutputError::Refused {
                path: path.to_path_buf(),
                found: found.describe(),
                fix: "rfmlab replaces its own folder as a whole, which would delete them: move them out, pass --force to replace the folder anyway, or choose a new folder with -o/--output".into(),
            })
        }
        _ => {
            return Err(OutputError::Refused {
                path: path.to_path_buf(),
                found: found.describe(),
                fix: "rfmlab replaces only a folder it made itself (one holding its manifest.json); pass --force to replace it as a whole, or choose a new folder with -o/--output".into(),
            })
        }
    }
    check_writable(path)?;
    Ok(found)
}

/// The pre-flight of an output file: `Ok(true)` when a file is there that rfmlab may replace
/// (it is `ours`, or `replace` is [`Replace::Force`]), `Ok(false)` when nothing is there;
/// [`OutputError::Refused`] for a file rfmlab did not write (unless forced) and for a folder.
/// Writes nothing.
pub fn claim_file(
    path: &Path,
    replace: Replace,
    ours: impl Fn(&Path) -> bool,
) -> Result<bool, OutputError> {
    let exists = match std::fs::metadata(path) {
        Ok(m) if m.is_dir() => {
            return Err(OutputError::Refused {
                path: path.to_path_buf(),
                found: "a folder".into(),
                fix: "give the path of a file to write (a file cannot replace a folder, even with --force)".into(),
            })
        }
        Ok(_) => true,
        Err(_) => std::fs::symlink_metadata(path).is_ok(),
    };
    if exists && replace == Replace::IfOurs && !ours(path) {
        return Err(OutputError::Refused {
            path: path.to_path_buf(),
            found: "a file rfmlab did not write".into(),
            fix: "pass --force to replace it, or choose another file name".into(),
        });
    }
    check_writable(path)?;
    Ok(exists)
}

/// Whether the file at `path` contains `marker` within its first `head` bytes or its last
/// `tail` bytes (how rfmlab recognises the files it wrote: a parquet footer's metadata, a UFF
/// file's ID line).
pub fn file_mentions(path: &Path, marker: &[u8], head: usize, tail: usize) -> bool {
    use std::io::{Read, Seek, SeekFrom};
    let Ok(mut f) = std::fs::File::open(path) else {
        return false;
    };
    let len = f.metadata().map_or(0, |m| m.len());
    let find = |buf: &[u8]| buf.windows(marker.len()).any(|w| w == marker);
    let mut buf = Vec::new();
    if (&mut f).take(head as u64).read_to_end(&mut buf).is_ok() && find(&buf) {
        return true;
    }
    if tail > 0 && len > head as u64 {
        let from = len.saturating_sub(tail as u64).max(head as u64);
        buf.clear();
        if f.seek(SeekFrom::Start(from)).is_ok() && f.read_to_end(&mut buf).is_ok() {
            return find(&buf);
        }
    }
    false
}

/// Whether `path` is a parquet table rfmlab wrote (its footer names the `rfmlab.table`).
pub fn is_rfmlab_table(path: &Path) -> bool {
    file_mentions(path, b"PAR1", 4, 0) && file_mentions(path, b"rfmlab.table", 0, 1 << 16)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn folders_are_classified_and_foreign_ones_refused_unless_forced() {
        let root = tempfile::tempdir().unwrap();
        let d = root.path().join("res");
        assert_eq!(claim_folder(&d, Replace::IfOurs).unwrap(), Found::Nothing);
        std::fs::create_dir(&d).unwrap();
        // rfmlab's temporary files do not count as content.
        std::fs::write(d.join(".a.json.tmp-12-3.json"), "x").unwrap();
        assert_eq!(
            claim_folder(&d, Replace::IfOurs).unwrap(),
            Found::EmptyFolder
        );
        std::fs::write(d.join("important.txt"), "mine").unwrap();
        let e = claim_folder(&d, Replace::IfOurs).unwrap_err().to_string();
        assert!(e.contains("important.txt") && e.contains("--force"), "{e}");
        assert!(matches!(
            claim_folder(&d, Replace::Force).unwrap(),
            Found::ForeignFolder { entries: 1, .. }
        ));
        // A manifest.json that is not rfmlab's does not make the folder rfmlab's.
        std::fs::write(d.join(MANIFEST), "{\"name\": \"mine\"}").unwrap();
        assert!(claim_folder(&d, Replace::IfOurs).is_err());
        let mut m = Manifest::new("study.toml", None);
        m.add_file("report.md", None);
        m.add_file("closed_loop/residuals.parquet", None);
        m.write(d.join(MANIFEST)).unwrap();
        std::fs::write(d.join("report.md"), "ours").unwrap();
        std::fs::create_dir(d.join("closed_loop")).unwrap();
        // rfmlab's folder with a user's file put in it since: refused, the file named.
        let e = claim_folder(&d, Replace::IfOurs).unwrap_err().to_string();
        assert!(
            e.contains("important.txt") && e.contains("rfmlab wrote") && e.contains("--force"),
            "{e}"
        );
        assert!(matches!(
            claim_folder(&d, Replace::Force).unwrap(),
            Found::OursWithOthers { entries: 1, .. }
        ));
        std::fs::remove_file(d.join("important.txt")).unwrap();
        assert_eq!(
            claim_folder(&d, Replace::IfOurs).unwrap(),
            Found::OursFolder
        );
        let f = root.path().join("afile");
        std::fs::write(&f, "x").unwrap();
        let e = claim_folder(&f, Replace::IfOurs).unwrap_err().to_string();
        assert!(e.contains("a file, not a folder"), "{e}");
        // Under a file: not writable.
        let e = claim_folder(&f.join("sub"), Replace::Force)
            .unwrap_err()
            .to_string();
        assert!(e.contains("is a file"), "{e}");
    }

    #[test]
    fn files_are_replaced_only_when_ours_or_forced() {
        let root = tempfile::tempdir().unwrap();
        let f = root.path().join("t.parquet");
        assert!(!claim_file(&f, Replace::IfOurs, is_rfmlab_table).unwrap());
        std::fs::write(&f, "PAR1 not ours").unwrap();
        assert!(claim_file(&f, Replace::IfOurs, is_rfmlab_table).is_err());
        assert!(claim_file(&f, Replace::Force, is_rfmlab_table).unwrap());
        let mut t = super::super::Table::new("t");
        t.push_f64("x", "Pa", vec![1.0]).unwrap();
        t.write_parquet(&f).unwrap();
        assert!(claim_file(&f, Replace::IfOurs, is_rfmlab_table).unwrap());
        assert!(claim_file(root.path(), Replace::Force, |_| true).is_err());
    }
}
