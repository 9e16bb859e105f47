//! The pre-flight that `rfmlab run`, `rfmlab diagnose` and `rfmlab check` share, the broken
//! pipe, `inspect`'s header checks and the messages of bad flags and keys, each as a user
//! meets it: the command that shows it and what it does now. Bad input stops before anything
//! is fitted (exit code 2, naming the file, the key or the flag, and the fix).

use crate::runner_common::*;

use rfmlab::common::Direction;
use rfmlab::data::{Channel, FrfSet, UffImportOptions};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

fn rfmlab(args: &[&str]) -> (Option<i32>, String, String) {
    rfmlab_cli(args)
}

fn study(s: &Setup, data: &Path) -> String {
    study_text(
        "s",
        &s.out,
        data,
        (10.0, 100.0),
        &[("model1", initial_of(1))],
        ANALYSES,
        "full",
    )
}

/// The data of [`setup`] as read back.
fn read_set(path: &Path) -> FrfSet {
    rfmlab::data::frf_set_from_uff(&[(path, "L1".to_string())], &UffImportOptions::default())
        .expect("read the data back")
}

fn write_set(set: &FrfSet, path: &Path) -> PathBuf {
    rfmlab::data::frf_set_to_uff(set, path, false).expect("write UFF");
    path.to_path_buf()
}

/// Runs `cmd` (run, check, ...) on `file` and expects exit code 2 with every needle.
fn expect_2(cmd: &str, file: &Path, needles: &[&str]) -> String {
    let (code, _, err) = rfmlab(&["--quiet", cmd, file.to_str().unwrap()]);
    assert_eq!(code, Some(2), "{cmd} {}: stderr:\n{err}", file.display());
    for n in needles {
        assert!(err.contains(n), "{cmd}: {n:?} not in:\n{err}");
    }
    err
}

/// The data of [`setup`] with the channel of point 3 changed by `change`, written as `name`.
fn with_channel_3(s: &Setup, name: &str, change: impl FnOnce(&mut Channel)) -> PathBuf {
    let mut set = read_set(&s.data);
    let ch = set.levels[0]
        .channels
        .iter_mut()
        .find(|c| c.response_id == 3)
        .unwrap();
    change(ch);
    write_set(&set, &s.root.join(name))
}

/// A channel measured along x at a point the study declares +y: every command stops with
/// exit 2 naming the data file, the channel, the point and the fix (it was fitted with its
/// sign reversed).
#[test]
fn channel_along_another_axis_stops() {
    let s = setup();
    let data = with_channel_3(&s, "x3.uff", |ch| ch.response_dir = Direction::PX);
    let file = write(&s.root.join("axis.toml"), &study(&s, &data));
    for cmd in ["run", "check"] {
        expect_2(
            cmd,
            &file,
            &[
                "axis.toml",
                "x3.uff",
                "3+x/2+y",
                "point 3",
                "structure.points[2].direction",
                "optional = true",
            ],
        );
    }
    assert!(!s.out.exists(), "nothing is written");
}

/// A channel measured in -y at a point declared +y (same axis, opposite sign): flipped, and
/// said so in `check`, in `run`'s console and in the report's first lines; the fit is that of
/// the data measured in +y.
#[test]
fn channel_with_opposite_sign_is_flipped_and_said() {
    let s = setup();
    let data = with_channel_3(&s, "m3.uff", |ch| {
        ch.response_dir = Direction::new(rfmlab::common::Axis::Y, -1);
        for v in &mut ch.values {
            *v = -*v;
        }
    });
    let file = write(&s.root.join("flip.toml"), &study(&s, &data));
    let (code, _, err) = rfmlab(&["--quiet", "check", file.to_str().unwrap()]);
    assert_eq!(code, Some(0), "{err}");
    assert!(
        err.contains("3-y/2+y") && err.contains("flipped"),
        "check: {err}"
    );
    let (code, _, err) = rfmlab(&["--quiet", "run", file.to_str().unwrap()]);
    assert_eq!(code, Some(0), "{err}");
    assert!(err.contains("warning:") && err.contains("flipped"), "{err}");
    let report = std::fs::read_to_string(s.out.join("report.md")).unwrap();
    let head: String = report.lines().take(6).collect::<Vec<_>>().join("\n");
    assert!(
        head.contains("flipped") && head.contains("3-y/2+y"),
        "{head}"
    );
    // the flipped data are the +y data: the fit finds the truth
    let t = rfmlab::output::Table::read_parquet(s.out.join("parameters.parquet")).unwrap();
    let ident = t
        .column("identified")
        .and_then(|c| c.as_f64())
        .unwrap()
        .to_vec();
    let e0 = ident[0];
    assert!((e0 / 7e6 - 1.0).abs() < 1e-3, "E0 {e0}");
}

/// A level's file whose header states another force level than the level (the L2 file given
/// as L1: 14x): a warning naming both levels; files of one level that disagree: exit 2.
#[test]
fn level_files_against_the_level() {
    let s = setup();
    let mut set = read_set(&s.data);
    set.levels[0].force_rms_n = Some(46.2);
    let l2 = write_set(&set, &s.root.join("l2.uff"));
    let two_levels = |l1: &Path| {
        study(&s, l1).replace("name = \"L1\"\n", "name = \"L1\"\nforce_rms_n = 3.3\n")
            + &format!(
                "[[measurements.levels]]\nname = \"L2\"\nfiles = [\"{}\"]\nforce_rms_n = 46.2\n",
                l2.display()
            )
    };
    let file = write(&s.root.join("swapped.toml"), &two_levels(&l2));
    let (code, _, err) = rfmlab(&["--quiet", "check", file.to_str().unwrap()]);
    assert_eq!(code, Some(0), "{err}");
    assert!(
        err.contains("warning:")
            && err.contains("level L1 has force_rms_n = 3.3 N")
            && err.contains("46.2")
            && err.contains("14.0x")
            && err.contains("level L2's data"),
        "{err}"
    );
    // one level from two files of different force levels
    let mut a = read_set(&s.data);
    a.levels[0].force_rms_n = Some(3.3);
    a.levels[0].channels.retain(|c| c.response_id <= 2);
    let mut b = read_set(&s.data);
    b.levels[0].force_rms_n = Some(46.2);
    b.levels[0].channels.retain(|c| c.response_id > 2);
    let fa = write_set(&a, &s.root.join("a.uff"));
    let fb = write_set(&b, &s.root.join("b.uff"));
    let text = study(&s, &fa).replace(
        &format!("files = [\"{}\"]", fa.display()),
        &format!("files = [\"{}\", \"{}\"]", fa.display(), fb.display()),
    );
    let file = write(&s.root.join("mixed.toml"), &text);
    for cmd in ["run", "check"] {
        expect_2(
            cmd,
            &file,
            &[
                "mixed.toml",
                "measurements.levels[0].files",
                "disagree",
                "a.uff",
                "b.uff",
            ],
        );
    }
}

/// A point without data stops `run` as it stops `check` (it was dropped), unless the point is
/// marked `optional = true`.
#[test]
fn point_without_data_stops_unless_optional() {
    let s = setup();
    let mut set = read_set(&s.data);
    set.levels[0].channels.retain(|c| c.response_id != 4);
    let data = write_set(&set, &s.root.join("no4.uff"));
    let text = study(&s, &data);
    let file = write(&s.root.join("nopoint.toml"), &text);
    for cmd in ["run", "check"] {
        expect_2(
            cmd,
            &file,
            &["nopoint.toml", "structure.points", "[4]", "optional = true"],
        );
    }
    assert!(!s.out.exists());
    let marked = text.replace(
        "position = [0.250, 0.010, 0.010]\ndirection = \"+y\"\n",
        "position = [0.250, 0.010, 0.010]\ndirection = \"+y\"\noptional = true\n",
    );
    assert_ne!(marked, text);
    let file = write(&s.root.join("optional.toml"), &marked);
    let (code, _, err) = rfmlab(&["--quiet", "check", file.to_str().unwrap()]);
    assert_eq!(code, Some(0), "{err}");
    assert!(err.contains("optional point(s) [4]"), "{err}");
}

/// `diagnose` runs the same pre-flight: a point without data stops it at once.
#[test]
fn diagnose_runs_the_preflight() {
    let s = setup();
    let mut set = read_set(&s.data);
    set.levels[0].channels.retain(|c| c.response_id != 4);
    let data = write_set(&set, &s.root.join("no4.uff"));
    let text = study(&s, &data) + "[inference]\nmodels = [\"model1\"]\n";
    let file = write(&s.root.join("diag.toml"), &text);
    expect_2("diagnose", &file, &["diag.toml", "structure.points", "[4]"]);
}

/// An IEM band outside the data and an output folder that cannot be made stop `run` at once
/// with exit 2, as `check` does (they failed after computing, exit 1).
#[test]
fn bands_and_output_folder_before_computing() {
    let s = setup();
    let text = study(&s, &s.data) + "[[analyses.iem]]\ncenter_hz = 400.0\nwidth_hz = 10.0\n";
    let file = write(&s.root.join("iem.toml"), &text);
    for cmd in ["run", "check"] {
        expect_2(cmd, &file, &["iem.toml", "analyses.iem[0]"]);
    }
    // a results folder below a regular file cannot be made
    std::fs::write(s.root.join("afile"), "x").unwrap();
    let text = study(&s, &s.data).replace(
        &format!("output_dir = \"{}\"", s.out.display()),
        &format!(
            "output_dir = \"{}\"",
            s.root.join("afile/results").display()
        ),
    );
    let file = write(&s.root.join("unwritable.toml"), &text);
    let t = std::time::Instant::now();
    for cmd in ["run", "check"] {
        expect_2(cmd, &file, &["afile/results", "afile' is a file"]);
    }
    assert!(t.elapsed().as_secs_f64() < 60.0);
    assert_eq!(std::fs::read_to_string(s.root.join("afile")).unwrap(), "x");
}

/// CSV data load in studies as documented (run and check rejected them).
#[test]
fn csv_data_load_in_studies() {
    let s = setup();
    let set = read_set(&s.data);
    let csv = s.root.join("d.csv");
    rfmlab::data::csv::write_csv(&set, &csv).unwrap();
    let file = write(&s.root.join("csv.toml"), &study(&s, &csv));
    let (code, _, err) = rfmlab(&["--quiet", "check", file.to_str().unwrap()]);
    assert_eq!(code, Some(0), "{err}");
    let (code, _, err) = rfmlab(&["--quiet", "run", file.to_str().unwrap()]);
    assert_eq!(code, Some(0), "{err}");
    assert!(s.out.join("report.md").is_file());
}

/// Runs `args` with stdout a pipe whose reader has gone: no panic (101), a quiet end (0, or
/// the SIGPIPE status 141 in a shell).
fn quiet_on_broken_pipe(args: &[&str]) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_rfmlab"))
        .args(args)
        .env("CI", "1")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run rfmlab");
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!err.contains("panicked"), "{args:?}: {err}");
    #[cfg(unix)]
    {
        use std::os::unix::process::ExitStatusExt;
        assert!(
            out.status.code() == Some(0) || out.status.signal() == Some(13),
            "{args:?}: {:?} {err}",
            out.status
        );
    }
    #[cfg(not(unix))]
    assert_ne!(out.status.code(), Some(101), "{args:?}: {err}");
}

/// `rfmlab inspect F | true` and `rfmlab modes study.toml | true` panicked (exit 101).
#[test]
fn broken_pipe_ends_quietly() {
    let s = setup();
    let file = write(&s.root.join("modes.toml"), &study(&s, &s.data));
    quiet_on_broken_pipe(&["inspect", s.data.to_str().unwrap()]);
    quiet_on_broken_pipe(&["inspect", "--json", s.data.to_str().unwrap()]);
    quiet_on_broken_pipe(&["modes", file.to_str().unwrap()]);
}

/// The data file's text with record 7 of its first dataset (the line after the function
/// record, 8 lines below the dataset's "-1") changed by `f`.
fn with_record7(path: &Path, f: impl Fn(&mut Vec<String>)) -> String {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    let mut fields: Vec<String> = lines[8].split_whitespace().map(String::from).collect();
    f(&mut fields);
    lines[8] = format!(
        "{:>10}{:>10}{:>10}{:>13}{:>13}{:>13}",
        fields[0], fields[1], fields[2], fields[3], fields[4], fields[5]
    );
    lines.join("\n") + "\n"
}

/// `inspect` rejects bad headers and values naming the file and line (exit 2), and `run` names
/// the bad file instead of blaming the level ("0 lines NaN..NaN Hz").
#[test]
fn inspect_validates_headers() {
    let s = setup();
    let text = std::fs::read_to_string(&s.data).unwrap();
    assert!(
        text.lines().nth(8).unwrap().trim_start().starts_with('6'),
        "record 7 at line 9"
    );
    let zero = s.root.join("zero.uff");
    std::fs::write(&zero, with_record7(&s.data, |f| f[1] = "0".into())).unwrap();
    let neg = s.root.join("neg.uff");
    std::fs::write(
        &neg,
        with_record7(&s.data, |f| f[4] = "-1.00000e+00".into()),
    )
    .unwrap();
    let mut set = read_set(&s.data);
    let n = set.levels[0].freq_hz.len();
    let mut coh = vec![0.99; n];
    coh[3] = 1.5;
    set.levels[0].channels[0].coherence = Some(coh);
    let c15 = write_set(&set, &s.root.join("coh.uff"));
    // a value Inf: the first number of the first dataset's values (line 14)
    let nan = s.root.join("nan.uff");
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    let first = lines[13].split_whitespace().next().unwrap().to_string();
    lines[13] = lines[13].replacen(
        &first,
        &format!("{:>width$}", "1.0e+999", width = first.len()),
        1,
    );
    std::fs::write(&nan, lines.join("\n") + "\n").unwrap();
    for (f, needle) in [
        (&zero, "0 points"),
        (&neg, "spacing"),
        (&c15, "coherence"),
        (&nan, "NaN or Inf"),
    ] {
        let (code, _, err) = rfmlab(&["inspect", f.to_str().unwrap()]);
        assert_eq!(code, Some(2), "{}: {err}", f.display());
        assert!(
            err.contains(f.file_name().unwrap().to_str().unwrap())
                && err.contains("line ")
                && err.contains(needle),
            "{}: {err}",
            f.display()
        );
    }
    let file = write(&s.root.join("zero.toml"), &study(&s, &zero));
    let err = expect_2("run", &file, &["zero.uff", "0 points"]);
    assert!(!err.contains("NaN..NaN"), "{err}");
}

/// Messages for people: a wrong type names the key, the value and what is allowed; a
/// dimensionless key has no unit "-"; a folder given as a data file is named a folder.
#[test]
fn study_messages_name_key_value_and_fix() {
    let s = setup();
    let good = study(&s, &s.data);
    let typed = good.replacen("thickness = 0.010\n", "thickness = \"abc\"\n", 1);
    assert_ne!(typed, good);
    let file = write(&s.root.join("typed.toml"), &typed);
    let err = expect_2(
        "check",
        &file,
        &[
            "typed.toml",
            "structure.beam.thickness",
            "\"abc\"",
            "a number",
        ],
    );
    assert!(
        !err.contains("(syntax)") && !err.contains("invalid type") && !err.contains("expected f64"),
        "{err}"
    );
    let tol = good.replace("tolerance = 1e-9", "tolerance = -1.0");
    let file = write(&s.root.join("tol.toml"), &tol);
    let err = expect_2("check", &file, &["solver.tolerance", "-1"]);
    assert!(!err.contains(" in -"), "{err}");
    std::fs::create_dir(s.root.join("adir")).unwrap();
    let folder = study(&s, &s.root.join("adir"));
    let file = write(&s.root.join("folder.toml"), &folder);
    let err = expect_2("check", &file, &["adir", "is a folder"]);
    assert!(!err.contains("not found"), "{err}");
}

/// Flags: `diagnose --model` is checked at once against the study's models, a negative
/// `--threshold-nats` gets a range message (not clap's "use '-- -3'"), and `rom --tolerance 0`
/// and `--cert-lines 0` are refused with exit 2.
#[test]
fn flags_are_checked_at_once() {
    let s = setup();
    let text = study(&s, &s.data) + "[inference]\nmodels = [\"model1\"]\n";
    let file = write(&s.root.join("flags.toml"), &text);
    let f = file.to_str().unwrap();
    let t = std::time::Instant::now();
    let (code, _, err) = rfmlab(&["--quiet", "diagnose", f, "--model", "model9"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("--model model9")
            && err.contains("model1")
            && !err.contains("inference.models"),
        "{err}"
    );
    assert!(t.elapsed().as_secs_f64() < 5.0, "{:?}", t.elapsed());
    let (code, _, err) = rfmlab(&["--quiet", "diagnose", f, "--threshold-nats", "-3"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("--threshold-nats -3") && !err.contains("'-- -3'"),
        "{err}"
    );
    let (code, _, err) = rfmlab(&["--quiet", "rom", f, "--tolerance", "0"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("--tolerance 0"), "{err}");
    let (code, out, err) = rfmlab(&["--quiet", "rom", f, "--cert-lines", "0"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("--cert-lines 0") && !out.contains("CERTIFIED"),
        "{err}"
    );
}

/// A UFF58 file and a CSV file of one level on different frequency grids: exit 2 naming the
/// level's files and both grids.
#[test]
fn files_of_one_level_on_different_grids_stop() {
    let s = setup();
    let mut set = read_set(&s.data);
    let level = &mut set.levels[0];
    let n = level.freq_hz.len() - 1;
    level.freq_hz.truncate(n);
    for ch in &mut level.channels {
        ch.values.truncate(n);
        if let Some(c) = &mut ch.coherence {
            c.truncate(n);
        }
    }
    let csv = s.root.join("short.csv");
    rfmlab::data::csv::write_csv(&set, &csv).unwrap();
    let text = study(&s, &s.data).replace(
        &format!("files = [\"{}\"]", s.data.display()),
        &format!("files = [\"{}\", \"{}\"]", s.data.display(), csv.display()),
    );
    let file = write(&s.root.join("grids.toml"), &text);
    expect_2(
        "check",
        &file,
        &[
            "measurements.levels[0].files",
            "different frequency lines",
            "10..100 Hz",
            "10..90 Hz",
        ],
    );
}
