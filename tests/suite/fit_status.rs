//! A fit is a result only when the model can represent it, and everything a user sees agrees
//! with the tables:
//! * the default study cut to Level 1 and Model 4 with a beam of 0.32 m against data of a
//!   0.30 m beam: the fit leaves the reduced model's certified modulus box; `rfmlab run` exits 3,
//!   prints the reasons, flags the fit in `--json`, parameters.parquet (`status`,
//!   `status_reason`) and the first lines of report.md, and its iteration count is the number
//!   of updates made, within `max_iterations`;
//! * the default study cut to Level 1 (Models 1-5, no band analyses): every number `--json`
//!   and the console print (identified parameters, iterations, stop reason, status, FRAC per
//!   FRF) equals the parquet tables' and report.md's.

use rfmlab::output::{ColumnData, Table};
use std::path::{Path, PathBuf};
use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_rfmlab");

/// studies/default.toml with Level 1 only, the models `models`, no band analyses, no per-line
/// RFM, sensitivities or figures, data paths made absolute, the beam `beam_m` long.
fn default_cut(models: &[&str], beam_m: &str, name: &str) -> String {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("studies");
    let s = std::fs::read_to_string(root.join("default.toml")).unwrap();
    let data = root.join("data");
    let mut out = String::new();
    // Sections to drop whole: the L2 level, models not kept, band analyses.
    let mut skip = false;
    let lines: Vec<&str> = s.lines().collect();
    for (i, line) in lines.iter().enumerate() {
        let t = line.trim_start();
        if t.starts_with('[') {
            let next = lines.get(i + 1).map(|l| l.trim()).unwrap_or("");
            skip = match t.split('#').next().unwrap().trim() {
                "[[measurements.levels]]" => next.contains("\"L2\""),
                "[[models]]" => !models.iter().any(|m| next == format!("name = \"{m}\"")),
                "[models.initial]" => skip,
                "[[analyses.band_constant]]" | "[[analyses.iem]]" => true,
                _ => false,
            };
        }
        if skip {
            continue;
        }
        out.push_str(line);
        out.push('\n');
    }
    out.replace("name = \"default\"", &format!("name = \"{name}\""))
        .replace("\"data/", &format!("\"{}/", data.display()))
        .replace(
            "length = 0.300           # m, along x",
            &format!("length = {beam_m}"),
        )
        .replace("per_line = true", "per_line = false")
        .replace("sensitivity = true", "sensitivity = false")
        .replace("figures = true", "figures = false")
}

struct Run {
    code: i32,
    stdout: String,
    stderr: String,
    out: PathBuf,
}

fn run(dir: &Path, name: &str, text: &str, json: bool) -> Run {
    let file = dir.join(format!("{name}.toml"));
    std::fs::write(&file, text).unwrap();
    let out = dir.join(format!("out_{name}"));
    let mut c = Command::new(BIN);
    // The ROMs through the suite's cache: the default study's is a fixture here, not what
    // the test measures.
    c.args(["run", file.to_str().unwrap(), "-o", out.to_str().unwrap()])
        .current_dir(dir)
        .env(
            rfmlab::stage::ROM_CACHE_ENV,
            crate::shared_rom_cache::runs_folder(),
        );
    if json {
        c.arg("--json").env("CI", "1");
    } else {
        c.env_remove("CI");
    }
    let o = c.output().unwrap();
    Run {
        code: o.status.code().unwrap_or(-1),
        stdout: String::from_utf8_lossy(&o.stdout).into_owned(),
        stderr: String::from_utf8_lossy(&o.stderr).into_owned(),
        out,
    }
}

fn read(path: &Path) -> Table {
    Table::read_parquet(path).unwrap()
}

fn strs(t: &Table, c: &str) -> Vec<String> {
    match t.column(c) {
        Some(ColumnData::Str(v)) => v.clone(),
        other => panic!("{c}: {other:?}"),
    }
}

fn floats(t: &Table, c: &str) -> Vec<f64> {
    match t.column(c) {
        Some(ColumnData::F64(v)) => v.clone(),
        Some(ColumnData::OptF64(v)) => v.iter().map(|x| x.unwrap_or(f64::NAN)).collect(),
        Some(ColumnData::I64(v)) => v.iter().map(|&x| x as f64).collect(),
        Some(ColumnData::U32(v)) => v.iter().map(|&x| x as f64).collect(),
        other => panic!("{c}: {other:?}"),
    }
}

/// Rows of `df` (indices) of `level` and `model`.
fn rows_of(df: &Table, level: &str, model: &str) -> Vec<usize> {
    let (l, m) = (strs(df, "level"), strs(df, "model"));
    (0..df.n_rows())
        .filter(|&i| l[i] == level && m[i] == model)
        .collect()
}

#[test]
fn a_fit_outside_the_certified_box_is_flagged_everywhere_and_exits_3() {
    let dir = tempfile::tempdir().unwrap();
    let text = default_cut(&["model4"], "0.320", "beam032");
    let r = run(dir.path(), "beam032", &text, true);
    assert_eq!(r.code, 3, "exit code; stderr:\n{}", r.stderr);
    assert!(
        r.stderr.contains("warning:") && r.stderr.contains("L1 model4"),
        "the console names the flagged fit:\n{}",
        r.stderr
    );
    // --json
    let j: serde_json::Value = serde_json::from_str(&r.stdout).unwrap();
    let m = &j["models"][0];
    assert_eq!(m["model"], "model4");
    assert_eq!(m["status"], "flagged", "{m}");
    let kinds: Vec<&str> = m["flags"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f["reason"].as_str().unwrap())
        .collect();
    assert!(
        kinds.contains(&"outside_certified_box"),
        "the fit leaves the certified box: {kinds:?}"
    );
    assert_eq!(
        j["flagged"].as_array().unwrap().len(),
        1,
        "{}",
        j["flagged"]
    );
    // The iteration count is the count made, within max_iterations = 100.
    let iterations = m["iterations"].as_u64().unwrap();
    assert!(
        iterations <= 100,
        "{iterations} iterations > max_iterations"
    );
    let it = read(&r.out.join("iterations.parquet"));
    let rows = rows_of(&it, "L1", "model4");
    let iters = floats(&it, "iteration");
    let last = rows.iter().map(|&i| iters[i]).fold(0.0, f64::max);
    assert_eq!(
        last as u64, iterations,
        "the history's last update is the count reported"
    );
    // parameters.parquet
    let p = read(&r.out.join("parameters.parquet"));
    let status = strs(&p, "status");
    let reason = strs(&p, "status_reason");
    assert!(status.iter().all(|s| s == "flagged"), "{status:?}");
    assert!(
        reason.iter().all(|s| s.contains("certified box")),
        "{reason:?}"
    );
    assert_eq!(reason[0], m["status_reason"].as_str().unwrap());
    // report.md opens with the warning.
    let report = std::fs::read_to_string(r.out.join("report.md")).unwrap();
    let head: String = report.lines().take(8).collect::<Vec<_>>().join("\n");
    assert!(
        head.contains("WARNING") && head.contains("L1 model4"),
        "report.md's first lines:\n{head}"
    );
}

/// The same f64 up to the JSON reader: serde_json's default float parser may land one ulp
/// off the value rfmlab printed (rfmlab prints the shortest representation that round-trips).
fn same(a: f64, b: f64) -> bool {
    a == b || (a - b).abs() <= 2.0 * f64::EPSILON * a.abs().max(b.abs())
}

/// `x` printed with `d` decimals (the report's format).
fn fixed(x: f64, d: usize) -> String {
    format!("{x:.d$}")
}

#[test]
fn json_console_report_and_tables_give_the_same_numbers() {
    let dir = tempfile::tempdir().unwrap();
    let models = ["model1", "model2", "model3", "model4", "model5"];
    let text = default_cut(&models, "0.300", "agree");
    let r = run(dir.path(), "agree", &text, true);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let j: serde_json::Value = serde_json::from_str(&r.stdout).unwrap();
    assert!(
        j["flagged"].as_array().unwrap().is_empty(),
        "{}",
        j["flagged"]
    );
    let p = read(&r.out.join("parameters.parquet"));
    let c = read(&r.out.join("correlation.parquet"));
    let report = std::fs::read_to_string(r.out.join("report.md")).unwrap();
    let ids = [1, 2, 3, 4];
    let summaries = j["models"].as_array().unwrap();
    assert_eq!(summaries.len(), models.len());
    for m in summaries {
        let (level, model) = (m["level"].as_str().unwrap(), m["model"].as_str().unwrap());
        let rows = rows_of(&p, level, model);
        let identified = floats(&p, "identified");
        let names = strs(&p, "parameter");
        let js: Vec<f64> = m["identified"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        assert_eq!(rows.len(), js.len(), "{level} {model}");
        for (k, &i) in rows.iter().enumerate() {
            assert_eq!(names[i], m["param_names"][k].as_str().unwrap());
            assert!(
                same(identified[i], js[k]),
                "{level} {model} {}: table {} vs --json {}",
                names[i],
                identified[i],
                js[k]
            );
        }
        let i0 = rows[0];
        assert_eq!(
            floats(&p, "iterations")[i0] as u64,
            m["iterations"].as_u64().unwrap()
        );
        assert_eq!(
            strs(&p, "stop_reason")[i0],
            m["stop_reason"].as_str().unwrap()
        );
        assert_eq!(strs(&p, "status")[i0], m["status"].as_str().unwrap());
        let frac: Vec<f64> = m["frac"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        let crow = rows_of(&c, level, model);
        let (kind, cid, cfrac) = (
            strs(&c, "kind"),
            floats(&c, "response_id"),
            floats(&c, "frac"),
        );
        for (k, id) in ids.iter().enumerate() {
            let table = floats(&p, &format!("frac_updated_{id}"))[i0];
            assert!(
                same(table, frac[k]),
                "{model} FRAC {id}: parameters {table} vs --json {}",
                frac[k]
            );
            let corr = crow
                .iter()
                .find(|&&i| kind[i] == "updated" && cid[i] as i64 == *id)
                .map(|&i| cfrac[i])
                .unwrap();
            assert!(
                same(corr, frac[k]),
                "{model} FRAC {id}: correlation {corr} vs --json {}",
                frac[k]
            );
        }
        // report.md: the model's identified row of Table 4 shows the same values.
        let row = report
            .lines()
            .find(|l| l.starts_with(&format!("| {model} | identified |")))
            .unwrap_or_else(|| panic!("no identified row of {model} in report.md"));
        for f in &frac {
            assert!(row.contains(&fixed(*f, 4)), "{row} lacks FRAC {f}");
        }
        assert!(row.contains(&format!("| {} |", m["iterations"])), "{row}");
        for (k, v) in js.iter().enumerate() {
            let name = m["param_names"][k].as_str().unwrap();
            let scale = if name.starts_with("eta") { 1e-3 } else { 1e-6 };
            let shown = format!("{name} = {}", fixed(v * scale, 4));
            assert!(row.contains(&shown), "{row} lacks {shown}");
        }
    }
    // The console prints the same FRACs as --json (a second run of the same study: the
    // identification is deterministic).
    let r2 = run(dir.path(), "agree", &text, false);
    assert_eq!(r2.code, 0, "{}", r2.stderr);
    for m in summaries {
        let (level, model) = (m["level"].as_str().unwrap(), m["model"].as_str().unwrap());
        let line = r2
            .stderr
            .lines()
            .find(|l| l.starts_with(&format!("{level} {model}:")))
            .unwrap_or_else(|| panic!("no console line of {level} {model}:\n{}", r2.stderr));
        let fr: Vec<String> = m["frac"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| fixed(v.as_f64().unwrap(), 4))
            .collect();
        assert!(
            line.contains(&format!("FRAC {}", fr.join(" "))),
            "{line} vs --json {fr:?}"
        );
        assert!(
            line.contains(&format!("{} iterations", m["iterations"])),
            "{line}"
        );
    }
}
