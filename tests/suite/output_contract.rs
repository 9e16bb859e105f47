//! The output contract of every command that writes (docs/outputs.md, "Output contract"):
//! `-o` on a folder holding a user's file, or on a regular file, exits with code 2 before
//! anything is computed and leaves it byte-identical, with no temporary file left; `--force`
//! replaces it as a whole; a folder rfmlab wrote is replaced on a rerun. Also: the ROM cache
//! follows `-o`, and the manifest records the study file's absolute path.

use crate::runner_common::*;

use std::path::{Path, PathBuf};
use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_rfmlab");

fn rfmlab_in(cwd: &Path, args: &[&str]) -> (i32, String) {
    let out = Command::new(BIN)
        .args(args)
        .current_dir(cwd)
        .env("CI", "1")
        .env_remove("RFMLAB_ROM_CACHE")
        .output()
        .expect("run rfmlab");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Every path under `dir` (relative) with the bytes of the files.
fn tree(dir: &Path) -> Vec<(String, Option<Vec<u8>>)> {
    fn walk(root: &Path, d: &Path, out: &mut Vec<(String, Option<Vec<u8>>)>) {
        for e in std::fs::read_dir(d).unwrap() {
            let p = e.unwrap().path();
            let rel = p.strip_prefix(root).unwrap().to_string_lossy().into_owned();
            if p.is_dir() {
                out.push((rel, None));
                walk(root, &p, out);
            } else {
                out.push((rel, Some(std::fs::read(&p).unwrap())));
            }
        }
    }
    let mut out = Vec::new();
    walk(dir, dir, &mut out);
    out.sort();
    out
}

/// Names of temporary files or folders (`*.tmp-*`) anywhere under `dir`.
fn temporaries(dir: &Path) -> Vec<String> {
    tree(dir)
        .into_iter()
        .map(|(n, _)| n)
        .filter(|n| n.contains(".tmp-") || n.contains(".old-"))
        .collect()
}

/// A command's arguments for an output path.
type ArgsFor<'a> = Box<dyn Fn(&Path) -> Vec<String> + 'a>;

/// A command under test: its name and its arguments for an output path.
struct Cmd<'a> {
    name: &'a str,
    args: ArgsFor<'a>,
}

impl Cmd<'_> {
    fn run(&self, root: &Path, out: &Path, extra: &[&str]) -> (i32, String) {
        let mut a = (self.args)(out);
        a.extend(extra.iter().map(|s| s.to_string()));
        let a: Vec<&str> = a.iter().map(String::as_str).collect();
        rfmlab_in(root, &a)
    }
}

/// `-o` on a folder holding a user's file and on a regular file: exit 2 at once, naming the
/// path and the fix; both byte-identical; no temporary left.
fn refuses_what_it_did_not_write(cmd: &Cmd, root: &Path) {
    let victim = root.join("victim");
    std::fs::create_dir_all(&victim).unwrap();
    std::fs::write(victim.join("important.txt"), b"the user's notes\n").unwrap();
    let afile = root.join("afile");
    std::fs::write(&afile, b"a user's file\n").unwrap();
    let before = tree(root);
    for target in [&victim, &afile] {
        let t0 = std::time::Instant::now();
        let (code, err) = cmd.run(root, target, &[]);
        assert_eq!(
            code,
            2,
            "{} -o {}: exit {code}\n{err}",
            cmd.name,
            target.display()
        );
        assert!(
            err.contains(&target.display().to_string()) && err.contains("--force"),
            "{}: the message names neither the path nor --force:\n{err}",
            cmd.name
        );
        // Refused in the pre-flight, not after computing.
        assert!(
            t0.elapsed().as_secs_f64() < 20.0,
            "{}: refused after {:.1} s",
            cmd.name,
            t0.elapsed().as_secs_f64()
        );
    }
    assert_eq!(tree(root), before, "{}: the user's files changed", cmd.name);
    assert!(
        temporaries(root).is_empty(),
        "{}: {:?}",
        cmd.name,
        temporaries(root)
    );
}

/// `--force` on a folder holding a user's file replaces it as a whole; a rerun into the folder
/// rfmlab made replaces it again; a file put into rfmlab's folder since is not deleted by a
/// rerun (exit 2, the file named and untouched) unless `--force`, which replaces the folder
/// whole (the file is gone: not merged).
fn force_and_rerun_replace_the_folder_whole(cmd: &Cmd, root: &Path) {
    let victim = root.join("forced");
    std::fs::create_dir_all(&victim).unwrap();
    std::fs::write(victim.join("important.txt"), b"the user's notes\n").unwrap();
    let (code, err) = cmd.run(root, &victim, &["--force"]);
    assert_eq!(code, 0, "{} --force: exit {code}\n{err}", cmd.name);
    assert!(!victim.join("important.txt").exists(), "{}", cmd.name);
    assert!(
        victim.join("manifest.json").is_file(),
        "{}: no manifest",
        cmd.name
    );
    let (code, err) = cmd.run(root, &victim, &[]);
    assert_eq!(code, 0, "{} rerun: exit {code}\n{err}", cmd.name);
    std::fs::write(victim.join("notes.txt"), b"put there since").unwrap();
    let (code, err) = cmd.run(root, &victim, &[]);
    assert_eq!(
        code, 2,
        "{}: a rerun over a file the user put into rfmlab's folder: exit {code}\n{err}",
        cmd.name
    );
    assert!(
        err.contains("notes.txt") && err.contains("--force"),
        "{err}"
    );
    assert_eq!(
        std::fs::read(victim.join("notes.txt")).unwrap(),
        b"put there since",
        "{}",
        cmd.name
    );
    let (code, err) = cmd.run(root, &victim, &["--force"]);
    assert_eq!(code, 0, "{} rerun --force: exit {code}\n{err}", cmd.name);
    assert!(
        !victim.join("notes.txt").exists(),
        "{}: the rerun merged into the folder instead of replacing it",
        cmd.name
    );
    assert!(victim.join("manifest.json").is_file(), "{}", cmd.name);
    assert!(
        temporaries(root).is_empty(),
        "{}: {:?}",
        cmd.name,
        temporaries(root)
    );
}

/// A tiny study of the synthetic joint (Model 1, ten lines) in `root`.
fn tiny_study(root: &Path, engine: &str, extra: &str) -> PathBuf {
    let data = root.join("d.uff");
    write_small_data(&data);
    let text = study_text(
        "s",
        &root.join("results").join("s"),
        &data,
        (10.0, 100.0),
        &[("model1", initial_of(1))],
        &format!("[analyses]\nper_line = false\nsensitivity = false\nfigures = false\n{extra}"),
        engine,
    );
    write(&root.join("s.toml"), &text)
}

fn study_cmd<'a>(name: &'a str, study: &'a Path) -> Cmd<'a> {
    Cmd {
        name,
        args: Box::new(move |out| {
            vec![
                name.to_string(),
                study.display().to_string(),
                "-o".into(),
                out.display().to_string(),
            ]
        }),
    }
}

#[test]
fn run_refuses_a_user_s_folder_or_file_and_replaces_its_own() {
    let dir = tempfile::tempdir().unwrap();
    let study = tiny_study(dir.path(), "full", "");
    let cmd = study_cmd("run", &study);
    refuses_what_it_did_not_write(&cmd, dir.path());
    force_and_rerun_replace_the_folder_whole(&cmd, dir.path());
}

#[test]
fn check_validates_the_output_folder_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let study = tiny_study(dir.path(), "full", "");
    let cmd = study_cmd("check", &study);
    refuses_what_it_did_not_write(&cmd, dir.path());
    let fresh = dir.path().join("fresh");
    let (code, err) = cmd.run(dir.path(), &fresh, &[]);
    assert_eq!(code, 0, "{err}");
    assert!(!fresh.exists(), "check created {}", fresh.display());
    let (code, err) = cmd.run(dir.path(), &dir.path().join("victim"), &["--force"]);
    assert_eq!(code, 0, "{err}");
    assert!(dir.path().join("victim/important.txt").is_file());
    // Under a regular file nothing can be written.
    let (code, err) = cmd.run(dir.path(), &dir.path().join("afile/sub"), &[]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("afile"), "{err}");
}

#[test]
fn diagnose_refuses_a_user_s_folder_or_file_and_accepts_its_own() {
    let dir = tempfile::tempdir().unwrap();
    // Without [inference] the loop cannot run: the output check comes first all the same.
    let study = tiny_study(dir.path(), "full", "");
    let cmd = study_cmd("diagnose", &study);
    refuses_what_it_did_not_write(&cmd, dir.path());
    // A folder rfmlab wrote passes the output check (the error is then the missing section),
    // and it is left as it was.
    let ours = dir.path().join("ours");
    std::fs::create_dir(&ours).unwrap();
    let mut manifest = rfmlab::output::Manifest::new(&study, None);
    manifest.add_file("closed_loop.md", None);
    manifest.write(ours.join("manifest.json")).unwrap();
    std::fs::write(ours.join("closed_loop.md"), b"earlier").unwrap();
    let before = tree(&ours);
    let (code, err) = cmd.run(dir.path(), &ours, &[]);
    assert_eq!(code, 2, "{err}");
    assert!(!err.contains("refusing"), "{err}");
    assert!(err.contains("inference"), "{err}");
    assert_eq!(tree(&ours), before);
}

/// `studies/dma_tensile.toml` cut to two branches and one start, its data path absolute.
fn material_study(root: &Path) -> PathBuf {
    let studies = repo().join("studies");
    let s = std::fs::read_to_string(studies.join("dma_tensile.toml")).unwrap();
    assert!(s.contains("max_branches = 30"), "update this test");
    let s = s
        .replace("\"data/", &format!("\"{}/", studies.join("data").display()))
        .replace("max_branches = 30", "max_branches = 2\nn_starts = 1");
    write(&root.join("material.toml"), &s)
}

#[test]
fn material_refuses_a_user_s_folder_or_file_and_replaces_its_own() {
    let dir = tempfile::tempdir().unwrap();
    let study = material_study(dir.path());
    let cmd = study_cmd("material", &study);
    refuses_what_it_did_not_write(&cmd, dir.path());
    force_and_rerun_replace_the_folder_whole(&cmd, dir.path());
}

#[test]
fn export_mm_refuses_a_user_s_folder_or_file_and_replaces_its_own() {
    let dir = tempfile::tempdir().unwrap();
    let study = tiny_study(dir.path(), "full", "");
    let cmd = study_cmd("export-mm", &study);
    refuses_what_it_did_not_write(&cmd, dir.path());
    force_and_rerun_replace_the_folder_whole(&cmd, dir.path());
    assert!(dir.path().join("forced/M.mtx").is_file());
}

/// The smallest validation of the docs' test: 51 lines, one unit per part.
fn validation(root: &Path) -> PathBuf {
    let experiment = crate::validate::EXPERIMENT.replace(
        "lines_hz = [1.0, 500.0, 1.0]",
        "lines_hz = [10.0, 60.0, 1.0]",
    );
    assert!(experiment.contains("[10.0, 60.0, 1.0]"));
    std::fs::write(root.join("experiment.toml"), experiment).unwrap();
    write(
        &root.join("validation.toml"),
        "[validation]\nname = \"contract\"\nexperiment = \"experiment.toml\"\nlevel = \"L1\"\nseed = 5\n\
         [sbc]\ndraws = 1\nposterior_draws = 3\nbins = 2\n[coverage]\nreplicates = 1\n\
         [selection]\nreplicates = 1\nmodels = [\"model4\"]\n\
         [quadrature]\nreplicates = 1\nmodels = [\"model1\"]\ngrid = 11\nhalf_width_sd = 3.0\n",
    )
}

#[test]
fn validate_refuses_a_user_s_folder_or_file_and_replaces_its_own() {
    let dir = tempfile::tempdir().unwrap();
    let file = validation(dir.path());
    let cmd = Cmd {
        name: "validate",
        args: Box::new(|out| {
            vec![
                "validate".into(),
                file.display().to_string(),
                "--no-figures".into(),
                "-o".into(),
                out.display().to_string(),
            ]
        }),
    };
    refuses_what_it_did_not_write(&cmd, dir.path());
    force_and_rerun_replace_the_folder_whole(&cmd, dir.path());
    assert!(dir.path().join("forced/summary.md").is_file());
    // The rerun read the reduced model its first run saved in the ROM cache.
    let run: serde_json::Value = serde_json::from_slice(
        &std::fs::read(dir.path().join("forced/runs/shard=0.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(run["rom_from_cache"], true, "{run}");
    // --no-cache builds it again.
    let fresh = dir.path().join("fresh");
    let (code, err) = cmd.run(dir.path(), &fresh, &["--no-cache"]);
    assert_eq!(code, 0, "{err}");
    let run: serde_json::Value =
        serde_json::from_slice(&std::fs::read(fresh.join("runs/shard=0.json")).unwrap()).unwrap();
    assert_eq!(run["rom_from_cache"], false, "{run}");
    // A shard accepts the folder of the run (it holds rfmlab's manifest) and refuses a user's.
    let (code, err) = cmd.run(dir.path(), &dir.path().join("victim"), &["--shard", "0/2"]);
    assert_eq!(code, 2, "{err}");
    assert!(dir.path().join("victim/important.txt").is_file());
}

fn experiment_text() -> String {
    format!(
        r#"
[experiment]
name = "contract"
description = "output contract test (SIMULATED)"
mode = "frequency"
seed = 7
output = "unused.uff"
engine = "full"

{}
[chain]
band_hz = [10.0, 20.0]
lines_hz = [10.0, 20.0, 2.0]
fs_hz = 256.0
block_s = 1.0
overlap = 0.5
averages = 10
window = "hann"
force_noise_fraction = 0.002
response_noise_fraction = 0.002

[[levels]]
name = "L1"
force_rms_n = 3.3
law = "model1"
params = {{ E0 = 7.0e6, h = 1.5e6 }}
"#,
        structure()
    )
}

#[test]
fn simulate_refuses_a_user_s_folder_or_file_and_replaces_its_own_files() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    let file = write(&root.join("experiment.toml"), &experiment_text());
    let cmd = Cmd {
        name: "simulate",
        args: Box::new(|out| {
            vec![
                "simulate".into(),
                file.display().to_string(),
                "-o".into(),
                out.display().to_string(),
            ]
        }),
    };
    refuses_what_it_did_not_write(&cmd, root);
    // A user's file where a level's data would go: refused, untouched.
    std::fs::write(root.join("sim_L1.uff"), b"a measurement").unwrap();
    let (code, err) = cmd.run(root, &root.join("sim.uff"), &[]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("sim_L1.uff") && err.contains("--force"),
        "{err}"
    );
    assert_eq!(
        std::fs::read(root.join("sim_L1.uff")).unwrap(),
        b"a measurement"
    );
    assert!(!root.join("sim.truth.json").exists());
    // --force replaces it; a rerun replaces what rfmlab wrote.
    let (code, err) = cmd.run(root, &root.join("sim.uff"), &["--force"]);
    assert_eq!(code, 0, "{err}");
    assert!(rfmlab::simulate::is_simulated_file(
        &root.join("sim_L1.uff")
    ));
    assert!(rfmlab::simulate::is_simulated_file(
        &root.join("sim.truth.json")
    ));
    let (code, err) = cmd.run(root, &root.join("sim.uff"), &[]);
    assert_eq!(code, 0, "{err}");
    // A folder at -o is refused even with --force (a file cannot replace a folder).
    let (code, err) = cmd.run(root, &root.join("victim"), &["--force"]);
    assert_eq!(code, 2, "{err}");
    assert!(root.join("victim/important.txt").is_file());
    // The hidden --out of earlier versions still works.
    let (code, err) = rfmlab_in(
        root,
        &[
            "simulate",
            file.to_str().unwrap(),
            "--out",
            root.join("sim.uff").to_str().unwrap(),
        ],
    );
    assert_eq!(code, 0, "{err}");
    assert!(temporaries(root).is_empty(), "{:?}", temporaries(root));
}

#[test]
fn frf_refuses_to_overwrite_a_file_it_did_not_write() {
    let dir = tempfile::tempdir().unwrap();
    let study = tiny_study(dir.path(), "full", "");
    let afile = dir.path().join("table.parquet");
    std::fs::write(&afile, b"not a table").unwrap();
    let (code, err) = rfmlab_in(
        dir.path(),
        &[
            "frf",
            study.to_str().unwrap(),
            "--band",
            "20,22",
            "-o",
            afile.to_str().unwrap(),
        ],
    );
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("table.parquet") && err.contains("--force"),
        "{err}"
    );
    assert_eq!(std::fs::read(&afile).unwrap(), b"not a table");
}

#[test]
fn the_rom_cache_follows_the_output_folder_and_the_manifest_holds_an_absolute_study_path() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    tiny_study(root, "rom", "");
    let elsewhere = root.join("elsewhere");
    std::fs::create_dir(&elsewhere).unwrap();
    let out = elsewhere.join("res");
    // A relative study path, run from the study's folder.
    let (code, err) = rfmlab_in(root, &["run", "s.toml", "-o", out.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    assert!(
        !root.join("results").exists(),
        "the run wrote into the current folder's results/"
    );
    assert!(
        elsewhere.join(".rom-cache").is_dir(),
        "no ROM cache beside the output folder"
    );
    let m = rfmlab::output::Manifest::read(out.join("manifest.json")).unwrap();
    let p = Path::new(&m.study_file);
    assert!(p.is_absolute(), "{}", m.study_file);
    assert_eq!(p, root.join("s.toml").canonicalize().unwrap());
}

/// A wrong type in a material study or a validation file is worded as in a study file: the
/// file and line, the key, the value, what the key takes (no serde wording), exit code 2.
#[test]
fn material_and_validation_files_name_the_key_and_value_of_a_wrong_type() {
    let dir = tempfile::tempdir().unwrap();
    let material = material_study(dir.path());
    let text = std::fs::read_to_string(&material).unwrap();
    assert!(text.contains("max_branches = 2"), "update this test");
    std::fs::write(
        &material,
        text.replace("max_branches = 2", "max_branches = \"two\""),
    )
    .unwrap();
    let validation = validation(dir.path());
    let text = std::fs::read_to_string(&validation).unwrap();
    std::fs::write(&validation, text.replace("seed = 5", "seed = \"five\"")).unwrap();
    for (cmd, file, key, value) in [
        ("material", &material, "max_branches", "\"two\""),
        ("validate", &validation, "seed", "\"five\""),
    ] {
        let out = dir.path().join(format!("{cmd}_out"));
        let (code, err) = rfmlab_in(
            dir.path(),
            &[cmd, file.to_str().unwrap(), "-o", out.to_str().unwrap()],
        );
        assert_eq!(code, 2, "{cmd}: {err}");
        for needle in [
            key,
            value,
            "takes",
            file.file_name().unwrap().to_str().unwrap(),
        ] {
            assert!(err.contains(needle), "{cmd}: no {needle:?} in\n{err}");
        }
        for serde in ["invalid type", "expected", "(syntax)", "(toml)"] {
            assert!(!err.contains(serde), "{cmd}: {serde:?} in\n{err}");
        }
        assert!(!out.exists(), "{cmd} wrote {}", out.display());
    }
}
