//! Flags mean the same on every command, and `--help` agrees with the README's commands table:
//! every flag a command's `--help` lists is in its row of the table and every flag of the row is
//! in `--help` (the binary is run as a user would).

use std::collections::BTreeSet;
use std::process::Command;

/// The long flags (`--name`) a command's `--help` lists, without `--help`, `--version` and the
/// global `--quiet`; and whether `-o` is the short form of `--output`.
fn help_flags(cmd: &str) -> (BTreeSet<String>, bool) {
    let out = Command::new(env!("CARGO_BIN_EXE_rfmlab"))
        .args([cmd, "--help"])
        .env("CI", "1")
        .output()
        .expect("run rfmlab");
    assert_eq!(out.status.code(), Some(0), "rfmlab {cmd} --help");
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    let mut flags = BTreeSet::new();
    let mut short_o = false;
    for line in text.lines() {
        let t = line.trim_start();
        // Flags stand at most 6 columns in; deeper lines are descriptions, which may name flags.
        if line.len() - t.len() > 6 {
            continue;
        }
        let t = match t.strip_prefix('-') {
            Some(rest) if !rest.starts_with('-') => {
                // "-o, --output <DIR>"
                if rest.starts_with("o, --output") {
                    short_o = true;
                }
                match rest.split_once(", ") {
                    Some((_, long)) => long,
                    None => continue,
                }
            }
            Some(_) => t,
            None => continue,
        };
        let Some(name) = t.strip_prefix("--") else {
            continue;
        };
        let name: String = name
            .chars()
            .take_while(|c| c.is_ascii_alphanumeric() || *c == '-')
            .collect();
        if !["help", "version", "quiet"].contains(&name.as_str()) {
            flags.insert(name);
        }
    }
    (flags, short_o)
}

/// The commands table of README.md: command name -> the long flags of its row (`-o` read as
/// `--output`).
fn readme_rows() -> Vec<(String, BTreeSet<String>)> {
    let readme = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/README.md"))
        .expect("README.md");
    let mut rows = Vec::new();
    for line in readme.lines() {
        let Some(rest) = line.strip_prefix("| `rfmlab ") else {
            continue;
        };
        let Some((usage, _)) = rest.split_once("` |") else {
            continue;
        };
        let name = usage
            .split_whitespace()
            .next()
            .unwrap_or_default()
            .to_string();
        let mut flags = BTreeSet::new();
        for tok in usage.split(|c: char| c.is_whitespace() || c == '[' || c == ']') {
            if tok == "-o" {
                flags.insert("output".to_string());
            } else if let Some(f) = tok.strip_prefix("--") {
                let f: String = f
                    .chars()
                    .take_while(|c| c.is_ascii_alphanumeric() || *c == '-')
                    .collect();
                if !f.is_empty() {
                    flags.insert(f);
                }
            }
        }
        rows.push((name, flags));
    }
    rows
}

const COMMANDS: [&str; 12] = [
    "run",
    "check",
    "diagnose",
    "simulate",
    "inspect",
    "modes",
    "frf",
    "convergence",
    "rom",
    "export-mm",
    "material",
    "validate",
];

#[test]
fn help_and_the_readme_list_the_same_flags_for_every_command() {
    let rows = readme_rows();
    let mut problems = Vec::new();
    for cmd in COMMANDS {
        let Some((_, doc)) = rows.iter().find(|(n, _)| n == cmd) else {
            problems.push(format!(
                "README's commands table has no row for `rfmlab {cmd}`"
            ));
            continue;
        };
        let (help, _) = help_flags(cmd);
        for f in help.difference(doc) {
            problems.push(format!(
                "`rfmlab {cmd} --help` lists --{f}, README's row does not"
            ));
        }
        for f in doc.difference(&help) {
            problems.push(format!(
                "README's row of `rfmlab {cmd}` lists --{f}, its --help does not"
            ));
        }
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}

/// The same flag on every command where it makes sense: every command that writes takes
/// `-o/--output` and `--force`; every command takes `--json`; the commands that draw take
/// `--no-figures`; those that use the ROM cache take `--no-cache`.
#[test]
fn flags_mean_the_same_on_every_command() {
    let writes = [
        "run",
        "check",
        "diagnose",
        "simulate",
        "frf",
        "export-mm",
        "material",
        "validate",
    ];
    let draws = ["run", "diagnose", "material", "validate"];
    let caches = ["run", "diagnose", "validate"];
    let mut problems = Vec::new();
    for cmd in COMMANDS {
        let (help, short_o) = help_flags(cmd);
        let mut want = vec!["json"];
        if writes.contains(&cmd) {
            want.extend(["output", "force"]);
            if !short_o {
                problems.push(format!("rfmlab {cmd}: --output has no short form -o"));
            }
        }
        if draws.contains(&cmd) {
            want.push("no-figures");
        }
        if caches.contains(&cmd) {
            want.push("no-cache");
        }
        for f in want {
            if !help.contains(f) {
                problems.push(format!("rfmlab {cmd} has no --{f}"));
            }
        }
        // No hidden or differently named output flag.
        if help.contains("out") {
            problems.push(format!(
                "rfmlab {cmd} lists --out; the output flag is -o/--output"
            ));
        }
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}
