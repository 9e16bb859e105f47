//! The user documentation against the code, so that it cannot drift:
//! * every key of the four input files (the serde structs that deny unknown keys) is in
//!   docs/study-files.md, and every key documented there exists; the key lists come from the
//!   structs themselves, traced by a recording serde `Deserializer` (below);
//! * every parquet table a quick run writes has exactly the columns, with the units, that
//!   docs/outputs.md lists for it, and every documented table of the runs made here was
//!   written;
//! * every command's `--help` names a documentation page that exists.

use serde::de::{self, DeserializeSeed, Deserializer, MapAccess, SeqAccess, Visitor};
use serde::Deserialize;
use std::cell::RefCell;
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_rfmlab");

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn read_doc(name: &str) -> String {
    let p = root().join("docs").join(name);
    std::fs::read_to_string(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

// ---------------------------------------------------------------------------------------------
// Tracing the serde structs: a Deserializer that answers every request with a placeholder and
// records the path of every struct field and map entry it is asked for. Structs give their
// field names (`deserialize_struct`'s `fields`, renames applied); maps get one entry `*`;
// sequences one element (tuples their length); options are `Some`; anything self-describing
// (`toml::Value`) a leaf.

type Keys = RefCell<BTreeSet<String>>;

struct Tracer<'a> {
    path: String,
    keys: &'a Keys,
    depth: usize,
}

impl<'a> Tracer<'a> {
    fn child(&self, segment: &str) -> Tracer<'a> {
        let path = if self.path.is_empty() {
            segment.to_string()
        } else {
            format!("{}.{segment}", self.path)
        };
        self.keys.borrow_mut().insert(path.clone());
        Tracer {
            path,
            keys: self.keys,
            depth: self.depth + 1,
        }
    }
    fn same(&self) -> Tracer<'a> {
        Tracer {
            path: self.path.clone(),
            keys: self.keys,
            depth: self.depth + 1,
        }
    }
}

fn too_deep<E: de::Error>(path: &str) -> E {
    E::custom(format!("{path}: nested too deep (a recursive type?)"))
}

macro_rules! leaf {
    ($($method:ident => $visit:ident($($value:expr)?);)*) => {
        $(fn $method<V: Visitor<'de>>(self, v: V) -> Result<V::Value, Self::Error> {
            v.$visit($($value)?)
        })*
    };
}

impl<'de> Deserializer<'de> for Tracer<'_> {
    type Error = de::value::Error;

    // Self-describing values (toml::Value) are leaves: answer a boolean.
    fn deserialize_any<V: Visitor<'de>>(self, v: V) -> Result<V::Value, Self::Error> {
        v.visit_bool(false)
    }
    leaf! {
        deserialize_bool => visit_bool(false);
        deserialize_i8 => visit_i64(0);
        deserialize_i16 => visit_i64(0);
        deserialize_i32 => visit_i64(0);
        deserialize_i64 => visit_i64(0);
        deserialize_u8 => visit_u64(0);
        deserialize_u16 => visit_u64(0);
        deserialize_u32 => visit_u64(0);
        deserialize_u64 => visit_u64(0);
        deserialize_f32 => visit_f64(0.0);
        deserialize_f64 => visit_f64(0.0);
        deserialize_char => visit_char('x');
        deserialize_str => visit_str("x");
        deserialize_string => visit_str("x");
        deserialize_bytes => visit_bytes(b"x");
        deserialize_byte_buf => visit_bytes(b"x");
        deserialize_unit => visit_unit();
        deserialize_identifier => visit_str("x");
        deserialize_ignored_any => visit_unit();
    }
    fn deserialize_option<V: Visitor<'de>>(self, v: V) -> Result<V::Value, Self::Error> {
        v.visit_some(self.same())
    }
    fn deserialize_unit_struct<V: Visitor<'de>>(
        self,
        _: &'static str,
        v: V,
    ) -> Result<V::Value, Self::Error> {
        v.visit_unit()
    }
    fn deserialize_newtype_struct<V: Visitor<'de>>(
        self,
        _: &'static str,
        v: V,
    ) -> Result<V::Value, Self::Error> {
        v.visit_newtype_struct(self.same())
    }
    fn deserialize_seq<V: Visitor<'de>>(self, v: V) -> Result<V::Value, Self::Error> {
        v.visit_seq(Elements {
            tracer: self,
            left: 1,
        })
    }
    fn deserialize_tuple<V: Visitor<'de>>(self, len: usize, v: V) -> Result<V::Value, Self::Error> {
        v.visit_seq(Elements {
            tracer: self,
            left: len,
        })
    }
    fn deserialize_tuple_struct<V: Visitor<'de>>(
        self,
        _: &'static str,
        len: usize,
        v: V,
    ) -> Result<V::Value, Self::Error> {
        self.deserialize_tuple(len, v)
    }
    fn deserialize_map<V: Visitor<'de>>(self, v: V) -> Result<V::Value, Self::Error> {
        if self.depth > 24 {
            return Err(too_deep(&self.path));
        }
        v.visit_map(Entries {
            tracer: self,
            names: &["*"],
            next: 0,
        })
    }
    fn deserialize_struct<V: Visitor<'de>>(
        self,
        _: &'static str,
        fields: &'static [&'static str],
        v: V,
    ) -> Result<V::Value, Self::Error> {
        if self.depth > 24 {
            return Err(too_deep(&self.path));
        }
        v.visit_map(Entries {
            tracer: self,
            names: fields,
            next: 0,
        })
    }
    fn deserialize_enum<V: Visitor<'de>>(
        self,
        name: &'static str,
        _: &'static [&'static str],
        _: V,
    ) -> Result<V::Value, Self::Error> {
        Err(de::Error::custom(format!(
            "{}: enum {name} is not traced; extend the tracer",
            self.path
        )))
    }
}

struct Elements<'a> {
    tracer: Tracer<'a>,
    left: usize,
}

impl<'de> SeqAccess<'de> for Elements<'_> {
    type Error = de::value::Error;
    fn next_element_seed<T: DeserializeSeed<'de>>(
        &mut self,
        seed: T,
    ) -> Result<Option<T::Value>, Self::Error> {
        if self.left == 0 {
            return Ok(None);
        }
        self.left -= 1;
        seed.deserialize(self.tracer.same()).map(Some)
    }
}

struct Entries<'a> {
    tracer: Tracer<'a>,
    names: &'static [&'static str],
    next: usize,
}

impl<'de> MapAccess<'de> for Entries<'_> {
    type Error = de::value::Error;
    fn next_key_seed<K: DeserializeSeed<'de>>(
        &mut self,
        seed: K,
    ) -> Result<Option<K::Value>, Self::Error> {
        let Some(name) = self.names.get(self.next) else {
            return Ok(None);
        };
        seed.deserialize(de::value::BorrowedStrDeserializer::new(name))
            .map(Some)
    }
    fn next_value_seed<V: DeserializeSeed<'de>>(
        &mut self,
        seed: V,
    ) -> Result<V::Value, Self::Error> {
        let name = self.names[self.next];
        self.next += 1;
        seed.deserialize(self.tracer.child(name))
    }
}

/// Every key path of a file type: `a.b.c` for nested tables and arrays of tables, `*` for a
/// key the user names (a map entry).
fn keys_of<T: for<'de> Deserialize<'de>>() -> BTreeSet<String> {
    let keys = Keys::default();
    let tracer = Tracer {
        path: String::new(),
        keys: &keys,
        depth: 0,
    };
    if let Err(e) = T::deserialize(tracer) {
        panic!("tracing {}: {e}", std::any::type_name::<T>());
    }
    keys.into_inner()
}

#[test]
fn the_tracer_sees_renames_maps_options_and_nesting() {
    #[derive(Deserialize)]
    #[allow(dead_code)]
    struct Inner {
        #[serde(rename = "E")]
        e: f64,
        pair: [f64; 2],
    }
    #[derive(Deserialize)]
    #[allow(dead_code)]
    struct Outer {
        inner: Option<Inner>,
        #[serde(default)]
        list: Vec<Inner>,
        map: BTreeMap<String, BTreeMap<String, Inner>>,
        any: Option<toml::Value>,
    }
    let got = keys_of::<Outer>();
    let want: BTreeSet<String> = [
        "inner",
        "inner.E",
        "inner.pair",
        "list",
        "list.E",
        "list.pair",
        "map",
        "map.*",
        "map.*.*",
        "map.*.*.E",
        "map.*.*.pair",
        "any",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    assert_eq!(got, want);
}

// ---------------------------------------------------------------------------------------------
// docs/study-files.md: `## <file kind>` parts; `### `[a.b]``, `[[a.b]]` headings (several
// paths separated by commas; `<name>` segments stand for `*`); table rows whose first cell is
// a backticked key. A heading's path and every row's `path.key` are documented keys.

fn doc_path(s: &str) -> String {
    s.trim_matches(|c| c == '[' || c == ']')
        .split('.')
        .map(|seg| {
            if seg.starts_with('<') && seg.ends_with('>') {
                "*"
            } else {
                seg
            }
        })
        .collect::<Vec<_>>()
        .join(".")
}

fn backticked(s: &str) -> Vec<&str> {
    s.split('`').skip(1).step_by(2).collect()
}

/// Documented keys per part (the `##` heading that starts each part).
fn documented_keys(doc: &str) -> BTreeMap<String, BTreeSet<String>> {
    let mut parts: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    let mut part = String::new();
    let mut sections: Vec<String> = Vec::new();
    let mut in_code = false;
    for line in doc.lines() {
        if line.starts_with("```") {
            in_code = !in_code;
            continue;
        }
        if in_code {
            continue;
        }
        if let Some(h) = line.strip_prefix("## ") {
            part = h.trim().to_string();
            sections.clear();
        } else if let Some(h) = line.strip_prefix("### ") {
            sections = backticked(h)
                .into_iter()
                .filter(|s| s.starts_with('['))
                .map(doc_path)
                .collect();
            for s in &sections {
                parts.entry(part.clone()).or_default().insert(s.clone());
            }
        } else if let Some(row) = line.strip_prefix("| `") {
            let key = row.split('`').next().unwrap_or("");
            if key == "key" || sections.is_empty() {
                continue;
            }
            for s in &sections {
                parts
                    .entry(part.clone())
                    .or_default()
                    .insert(format!("{s}.{}", doc_path(key)));
            }
        }
    }
    parts
}

fn diff(code: &BTreeSet<String>, doc: &BTreeSet<String>, what: &str) -> Vec<String> {
    let mut out = Vec::new();
    for k in code.difference(doc) {
        out.push(format!(
            "{what}: key `{k}` exists in the code but not in docs/study-files.md"
        ));
    }
    for k in doc.difference(code) {
        out.push(format!(
            "{what}: key `{k}` is documented but the code does not accept it"
        ));
    }
    out
}

#[test]
fn every_input_file_key_is_documented_and_every_documented_key_exists() {
    let doc = documented_keys(&read_doc("study-files.md"));
    let part = |name: &str| -> BTreeSet<String> {
        doc.get(name)
            .cloned()
            .unwrap_or_else(|| panic!("docs/study-files.md has no part `## {name}`"))
    };
    let study = keys_of::<rfmlab::study::raw::RawStudy>();
    let experiment = keys_of::<rfmlab::study::experiment::RawExperimentFile>();
    let material = keys_of::<rfmlab::study::material::RawMaterialStudy>();
    let validation = keys_of::<rfmlab::validate::spec::RawFile>();
    // The experiment file's [structure] is the study file's, documented once.
    let structure = |k: &BTreeSet<String>| -> BTreeSet<String> {
        k.iter()
            .filter(|k| k.as_str() == "structure" || k.starts_with("structure."))
            .cloned()
            .collect()
    };
    assert_eq!(
        structure(&experiment),
        structure(&study),
        "the experiment file's [structure] differs from the study file's: document it on its own"
    );
    let experiment: BTreeSet<String> = experiment
        .into_iter()
        .filter(|k| !k.starts_with("structure."))
        .collect();
    let mut doc_experiment = part("Experiment files");
    doc_experiment.insert("structure".into());

    let mut problems = Vec::new();
    problems.extend(diff(&study, &part("Study files"), "study file"));
    problems.extend(diff(&experiment, &doc_experiment, "experiment file"));
    problems.extend(diff(&material, &part("Material studies"), "material study"));
    problems.extend(diff(
        &validation,
        &part("Validation files"),
        "validation file",
    ));
    assert!(problems.is_empty(), "{}", problems.join("\n"));
    // The trace itself is not empty: a sample of keys each file must have.
    for (keys, k) in [
        (&study, "structure.beam.material.E"),
        (&study, "inference.priors.*.*.family"),
        (&study, "closed_loop.candidates"),
        (&experiment, "levels.params.*"),
        (&material, "material_fit.kk_threshold"),
        (&validation, "quadrature.ss_replicas"),
    ] {
        assert!(keys.contains(k), "{k} not traced");
    }
}

// ---------------------------------------------------------------------------------------------
// docs/outputs.md: `## ` parts (one per command or folder); in each, `### `name.parquet``
// headings followed by rows `| `column` | unit | meaning |` (a `<...>` segment in a column name
// matches any run of letters, digits and underscores; the unit cell is the unit the file
// stores, empty when it stores none), and a `### Figures` table whose rows name figure files
// (`fig_frf_<level>.png`).

#[derive(Debug, Default)]
struct DocTable {
    columns: Vec<(String, String)>,
}

#[derive(Debug, Default)]
struct DocPart {
    tables: BTreeMap<String, DocTable>,
    figures: Vec<String>,
}

fn documented_outputs(doc: &str) -> BTreeMap<String, DocPart> {
    let mut parts: BTreeMap<String, DocPart> = BTreeMap::new();
    let mut part = String::new();
    let mut table: Option<String> = None;
    let mut figures = false;
    let mut in_code = false;
    for line in doc.lines() {
        if line.starts_with("```") {
            in_code = !in_code;
            continue;
        }
        if in_code {
            continue;
        }
        if let Some(h) = line.strip_prefix("## ") {
            part = h.trim().to_string();
            parts.entry(part.clone()).or_default();
            table = None;
            figures = false;
        } else if let Some(h) = line.strip_prefix("### ") {
            figures = h.trim() == "Figures";
            table = backticked(h)
                .into_iter()
                .find(|s| s.ends_with(".parquet"))
                .map(|s| s.trim_end_matches(".parquet").to_string());
            if let Some(t) = &table {
                parts
                    .entry(part.clone())
                    .or_default()
                    .tables
                    .entry(t.clone())
                    .or_default();
            }
        } else if let Some(row) = line.strip_prefix("| `") {
            let cells: Vec<&str> = row.split('|').map(str::trim).collect();
            let name = cells[0].trim_end_matches('`').to_string();
            let p = parts.entry(part.clone()).or_default();
            if figures {
                p.figures.push(name);
            } else if let Some(t) = &table {
                let unit = cells.get(1).copied().unwrap_or("").trim_matches('`');
                p.tables
                    .get_mut(t)
                    .unwrap()
                    .columns
                    .push((name, unit.to_string()));
            }
        }
    }
    parts
}

/// Whether `name` matches the documented pattern (`<...>` = one or more of [A-Za-z0-9_.]).
fn matches(pattern: &str, name: &str) -> bool {
    fn go(p: &[u8], n: &[u8]) -> bool {
        match p.first() {
            None => n.is_empty(),
            Some(b'<') => {
                let Some(end) = p.iter().position(|&c| c == b'>') else {
                    return false;
                };
                let rest = &p[end + 1..];
                let word = |c: &u8| c.is_ascii_alphanumeric() || *c == b'_' || *c == b'.';
                (1..=n.len())
                    .take_while(|&k| word(&n[k - 1]))
                    .any(|k| go(rest, &n[k..]))
            }
            Some(&c) => n.first() == Some(&c) && go(&p[1..], &n[1..]),
        }
    }
    go(pattern.as_bytes(), name.as_bytes())
}

#[test]
fn documented_patterns_match_what_they_should() {
    assert!(matches("frac_initial_<id>", "frac_initial_3"));
    assert!(matches("fig_frf_<level>.png", "fig_frf_L1.png"));
    assert!(matches("start_<parameter>", "start_eta1"));
    assert!(!matches("start_<parameter>", "start_"));
    assert!(!matches("frac_<id>_map", "frac_1_median"));
    assert!(matches("level", "level"));
    assert!(!matches("level", "levels"));
}

/// Every parquet file under `dir` (recursively, hive shard parts left out) by its path
/// relative to `dir` without `.parquet`, with its columns and units.
fn written_tables(dir: &Path) -> BTreeMap<String, Vec<(String, String)>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            let name = p.file_name().unwrap().to_string_lossy().into_owned();
            if p.is_dir() {
                if !name.starts_with('.') && !name.contains('=') {
                    stack.push(p);
                }
            } else if let Some(stem) = name.strip_suffix(".parquet") {
                let rel = p.parent().unwrap().strip_prefix(dir).unwrap().join(stem);
                let t = rfmlab::output::Table::read_parquet(&p)
                    .unwrap_or_else(|e| panic!("{}: {e}", p.display()));
                out.insert(rel.to_string_lossy().replace('\\', "/"), t.units().to_vec());
            }
        }
    }
    out
}

/// The PNG figures in `dir` itself (subfolders are other parts).
fn written_figures(dir: &Path) -> Vec<String> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_file() && p.extension().is_some_and(|e| e == "png") {
            out.push(p.file_name().unwrap().to_string_lossy().into_owned());
        }
    }
    out
}

/// Compare the tables (and figures, when `figures`) a run wrote under `dir` with the part
/// `part` of docs/outputs.md. `prefix` selects the files of that part (e.g. `closed_loop/`).
fn check_part(
    doc: &BTreeMap<String, DocPart>,
    part: &str,
    dir: &Path,
    prefix: &str,
    figures: bool,
    problems: &mut Vec<String>,
) {
    let Some(p) = doc.get(part) else {
        problems.push(format!("docs/outputs.md has no part `## {part}`"));
        return;
    };
    let written: BTreeMap<String, Vec<(String, String)>> = written_tables(dir)
        .into_iter()
        .filter_map(|(k, v)| {
            if prefix.is_empty() {
                (!k.contains('/')).then_some((k, v))
            } else {
                k.strip_prefix(prefix).map(|s| (s.to_string(), v))
            }
        })
        .collect();
    for (name, cols) in &written {
        let Some(d) = p.tables.get(name) else {
            problems.push(format!(
                "{part}: table `{name}` is written but not documented"
            ));
            continue;
        };
        for (c, unit) in cols {
            // An exact name first, then the first pattern that matches.
            let row = d
                .columns
                .iter()
                .find(|(pat, _)| pat == c)
                .or_else(|| d.columns.iter().find(|(pat, _)| matches(pat, c)));
            match row {
                None => problems.push(format!(
                    "{part}: `{name}` column `{c}` is written but not documented"
                )),
                // Per-parameter columns carry each parameter's own unit.
                Some((_, du)) if du == "the parameter's" => {}
                Some((pat, du)) if du != unit => problems.push(format!(
                    "{part}: `{name}` column `{c}` (documented as `{pat}`) has unit `{unit}` in the file, `{du}` in the docs"
                )),
                _ => {}
            }
        }
        for (pat, _) in &d.columns {
            if !cols.iter().any(|(c, _)| matches(pat, c)) {
                problems.push(format!(
                    "{part}: `{name}` column `{pat}` is documented but not written"
                ));
            }
        }
    }
    for name in p.tables.keys() {
        if !written.contains_key(name) {
            problems.push(format!(
                "{part}: table `{name}` is documented but not written by the test's runs"
            ));
        }
    }
    if figures {
        let fig = written_figures(&dir.join(prefix));
        for f in &fig {
            if !p.figures.iter().any(|pat| matches(pat, f)) {
                problems.push(format!(
                    "{part}: figure `{f}` is written but not documented"
                ));
            }
        }
        for pat in &p.figures {
            if !fig.iter().any(|f| matches(pat, f)) {
                problems.push(format!(
                    "{part}: figure `{pat}` is documented but not written"
                ));
            }
        }
    }
}

/// A study of the repository with its data paths made absolute, text replaced and its output
/// folder `out`, written to `file`; returns `file`.
fn study_variant(name: &str, out: &Path, edits: &[(&str, &str)], file: PathBuf) -> PathBuf {
    let studies = root().join("studies");
    let mut s = std::fs::read_to_string(studies.join(name)).unwrap();
    s = s.replace("\"data/", &format!("\"{}/", studies.join("data").display()));
    for (a, b) in edits {
        assert!(
            s.contains(a),
            "{name} no longer contains `{a}`: update this test"
        );
        s = s.replace(a, b);
    }
    let s = s.replace(
        "[study]\n",
        &format!("[study]\noutput_dir = \"{}\"\n", out.display()),
    );
    std::fs::write(&file, s).unwrap();
    file
}

fn rfmlab(args: &[&str]) {
    let o = Command::new(BIN)
        .args(args)
        .env("CI", "1")
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "rfmlab {args:?} failed:\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
}

fn problems_or_pass(problems: Vec<String>) {
    assert!(
        problems.is_empty(),
        "docs/outputs.md differs from what rfmlab writes:\n{}",
        problems.join("\n")
    );
}

/// A problem saying that something documented was not written.
fn absence(p: &str) -> bool {
    p.contains("documented but")
}

/// A problem about a table or figure of the deterministic part of `rfmlab run`.
fn about_deterministic(p: &str) -> bool {
    [
        "frf",
        "parameters",
        "iterations",
        "correlation",
        "correlation_curves",
        "modulus",
        "svd",
        "modal",
        "sensitivity",
        "fig_frf_",
        "fig_scc_",
        "fig_acc_",
        "fig_modulus_",
        "fig_convergence_",
    ]
    .iter()
    .any(|t| p.contains(&format!("`{t}`")) || p.contains(&format!("`{t}<")))
}

#[test]
fn the_default_study_s_tables_and_figures_are_documented() {
    let doc = documented_outputs(&read_doc("outputs.md"));
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("default");
    // The default study on a 10 mm mesh: the same tables and figures, a fraction of the time.
    let file = study_variant(
        "default.toml",
        &out,
        &[("element_size = 0.005", "element_size = 0.010")],
        dir.path().join("default.toml"),
    );
    rfmlab(&["run", file.to_str().unwrap(), "--no-cache"]);
    let mut problems = Vec::new();
    check_part(&doc, "rfmlab run", &out, "", true, &mut problems);
    // The Bayesian tables and figures are checked by the next test.
    problems.retain(|p| !absence(p) || about_deterministic(p));
    problems_or_pass(problems);
}

#[test]
fn the_bayesian_and_closed_loop_tables_and_figures_are_documented() {
    let doc = documented_outputs(&read_doc("outputs.md"));
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("bayes");
    // studies/bayes.toml cut to seconds (10 mm mesh, 10-60 Hz, Model 4, short chains) with
    // every part on: stepping-stone, comparison across levels, basins and the closed loop.
    let file = study_variant(
        "bayes.toml",
        &out,
        &[
            ("element_size = 0.005", "element_size = 0.010"),
            ("band_hz = [1.0, 500.0]", "band_hz = [10.0, 60.0]"),
            (
                "models = [\"model3\", \"model4\", \"model5\"]",
                "models = [\"model4\"]",
            ),
            ("chains = 4", "chains = 2"),
            ("tune = 1000", "tune = 60"),
            ("draws = 1000", "draws = 60"),
            ("particles = 1000", "particles = 60"),
            ("particles = 200", "particles = 60"),
            ("replicas = 8", "replicas = 2"),
            ("starts = 8", "starts = 1"),
            // the mesh's estimate (the study fixes its mesh): the discretisation table
            ("[analyses]\n", "[analyses]\nmesh_error = true\n"),
            // Model 5 takes about 170 updates over 10-60 Hz: within the budget, not flagged.
            (
                "[solver]\nengine = \"rom\"",
                "[solver]\nengine = \"rom\"\nmax_iterations = 300",
            ),
            (
                "shared = true",
                "shared = true\n\n[inference.basins]\nstarts = 3\n\n[closed_loop]\ncandidates = [\"gain_ch3\"]\nmax_effects = 1\ntop = 1\np_threshold = 1.0",
            ),
        ],
        dir.path().join("bayes.toml"),
    );
    rfmlab(&["run", file.to_str().unwrap(), "--no-cache"]);
    let mut problems = Vec::new();
    check_part(&doc, "rfmlab run", &out, "", true, &mut problems);
    // The deterministic part (its tables and figures, some of them empty or left out here) is
    // checked by the default study's test.
    problems.retain(|p| !(absence(p) && about_deterministic(p)));
    check_part(
        &doc,
        "Closed-loop tables",
        &out,
        "closed_loop/",
        true,
        &mut problems,
    );
    // `mesh` comes from `rfmlab diagnose`'s refined-mesh pass only; its columns are read by
    // closed_loop_td::time_domain_mesh_error_is_explained_and_the_mesh_allowance_widens_the_sds.
    problems.retain(|p| !p.contains("table `mesh` is documented but not written"));
    problems_or_pass(problems);
}

#[test]
fn the_material_loop_s_tables_are_documented() {
    let doc = documented_outputs(&read_doc("outputs.md"));
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("material");
    let file = study_variant(
        "dma_tensile.toml",
        &out,
        &[("max_branches = 30", "max_branches = 2\nn_starts = 1")],
        dir.path().join("material.toml"),
    );
    rfmlab(&["material", file.to_str().unwrap()]);
    let mut problems = Vec::new();
    check_part(&doc, "rfmlab material", &out, "", true, &mut problems);
    problems_or_pass(problems);
}

#[test]
fn the_frf_command_s_table_is_documented() {
    let doc = documented_outputs(&read_doc("outputs.md"));
    let dir = tempfile::tempdir().unwrap();
    let file = study_variant(
        "default.toml",
        &dir.path().join("unused"),
        &[("element_size = 0.005", "element_size = 0.010")],
        dir.path().join("joint.toml"),
    );
    let out = dir.path().join("frf_out");
    std::fs::create_dir_all(&out).unwrap();
    let table = out.join("FILE.parquet");
    rfmlab(&[
        "frf",
        file.to_str().unwrap(),
        "--band",
        "20,22",
        "--derivatives",
        "--out",
        table.to_str().unwrap(),
    ]);
    let mut problems = Vec::new();
    check_part(&doc, "rfmlab frf", &out, "", false, &mut problems);
    problems_or_pass(problems);
}

// ---------------------------------------------------------------------------------------------
// `--help`: every command names a documentation page that exists, and the commands that write
// tables name every table docs/outputs.md documents for them.

fn help(args: &[&str]) -> String {
    let o = Command::new(BIN).args(args).output().unwrap();
    assert!(o.status.success(), "rfmlab {args:?} failed");
    String::from_utf8_lossy(&o.stdout).into_owned()
}

#[test]
fn every_command_s_help_names_its_outputs_and_its_documentation() {
    let top = help(&["--help"]);
    let commands: Vec<String> = top
        .lines()
        .skip_while(|l| !l.starts_with("Commands:"))
        .skip(1)
        .take_while(|l| l.starts_with("  "))
        .filter_map(|l| l.split_whitespace().next().map(str::to_string))
        .filter(|c| c != "help")
        .collect();
    assert!(commands.len() >= 12, "commands not found in:\n{top}");
    let doc = documented_outputs(&read_doc("outputs.md"));
    let tables = |part: &str| -> Vec<String> {
        doc.get(part)
            .unwrap_or_else(|| panic!("docs/outputs.md has no part `## {part}`"))
            .tables
            .keys()
            .cloned()
            .collect()
    };
    let writes: BTreeMap<&str, Vec<String>> = [
        (
            "run",
            [tables("rfmlab run"), tables("Closed-loop tables")]
                .concat()
                .into_iter()
                // the refined-mesh pass is `rfmlab diagnose`'s
                .filter(|t| t != "mesh")
                .collect(),
        ),
        ("diagnose", tables("Closed-loop tables")),
        ("material", tables("rfmlab material")),
        ("validate", tables("rfmlab validate")),
        ("frf", tables("rfmlab frf")),
    ]
    .into_iter()
    .collect();
    let mut problems = Vec::new();
    for c in &commands {
        let h = help(&[c, "--help"]);
        let pages: Vec<&str> = h
            .split(|ch: char| ch.is_whitespace() || ch == '(' || ch == ')' || ch == ',')
            .filter(|w| w.starts_with("docs/"))
            .map(|w| w.trim_end_matches(['.', ';', ':']))
            .collect();
        if pages.is_empty() {
            problems.push(format!("`rfmlab {c} --help` names no page under docs/"));
        }
        for p in pages {
            if !root().join(p).is_file() {
                problems.push(format!(
                    "`rfmlab {c} --help` names {p}, which does not exist"
                ));
            }
        }
        let words: BTreeSet<&str> = h
            .split(|ch: char| !(ch.is_ascii_alphanumeric() || ch == '_' || ch == '.'))
            .map(|w| w.trim_end_matches('.'))
            .collect();
        for t in writes.get(c.as_str()).into_iter().flatten() {
            let named =
                words.contains(t.as_str()) || words.contains(format!("{t}.parquet").as_str());
            if !named && t != "FILE" {
                problems.push(format!(
                    "`rfmlab {c} --help` does not name its table `{t}` (docs/outputs.md)"
                ));
            }
        }
    }
    for c in writes.keys() {
        if !commands.iter().any(|x| x == c) {
            problems.push(format!("no command `{c}` in `rfmlab --help`"));
        }
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}

#[test]
fn the_validation_tables_are_documented() {
    let doc = documented_outputs(&read_doc("outputs.md"));
    let dir = tempfile::tempdir().unwrap();
    // The validation smoke configuration of tests/suite/validate.rs on 51 lines, one unit per
    // part: every table and the figure, in seconds.
    let experiment = crate::validate::EXPERIMENT.replace(
        "lines_hz = [1.0, 500.0, 1.0]",
        "lines_hz = [10.0, 60.0, 1.0]",
    );
    assert!(experiment.contains("[10.0, 60.0, 1.0]"));
    std::fs::write(dir.path().join("experiment.toml"), experiment).unwrap();
    let file = dir.path().join("validation.toml");
    std::fs::write(
        &file,
        "[validation]\nname = \"docs\"\nexperiment = \"experiment.toml\"\nlevel = \"L1\"\nseed = 5\n\
         [sbc]\ndraws = 1\nposterior_draws = 3\nbins = 2\n[coverage]\nreplicates = 1\n\
         [selection]\nreplicates = 1\nmodels = [\"model4\"]\n\
         [quadrature]\nreplicates = 1\nmodels = [\"model1\"]\ngrid = 11\nhalf_width_sd = 3.0\n",
    )
    .unwrap();
    let out = dir.path().join("out");
    rfmlab(&[
        "validate",
        file.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let mut problems = Vec::new();
    check_part(&doc, "rfmlab validate", &out, "", true, &mut problems);
    problems_or_pass(problems);
}

// ---------------------------------------------------------------------------------------------
// Links: every relative link of README.md, CHANGELOG.md and docs/*.md names a file that exists
// and, with `#anchor`, a heading of that file (GitHub's anchors: lower case, punctuation other
// than `-` and `_` dropped, spaces to `-`).

fn anchors(md: &str) -> BTreeSet<String> {
    md.lines()
        .filter(|l| l.starts_with('#'))
        .map(|l| {
            l.trim_start_matches('#')
                .trim()
                .to_lowercase()
                .chars()
                .filter_map(|c| match c {
                    ' ' => Some('-'),
                    c if c.is_alphanumeric() || c == '-' || c == '_' => Some(c),
                    _ => None,
                })
                .collect()
        })
        .collect()
}

#[test]
fn every_documentation_link_resolves() {
    let mut pages = vec![root().join("README.md"), root().join("CHANGELOG.md")];
    for e in std::fs::read_dir(root().join("docs")).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_some_and(|x| x == "md") {
            pages.push(p);
        }
    }
    let mut problems = Vec::new();
    for page in &pages {
        // The text outside code blocks and code spans (`E[H1](f_k)` is no link).
        let mut text = String::new();
        let mut in_code = false;
        for line in std::fs::read_to_string(page).unwrap().lines() {
            if line.starts_with("```") {
                in_code = !in_code;
            } else if !in_code {
                text.extend(line.split('`').step_by(2));
                text.push('\n');
            }
        }
        let base = page.parent().unwrap();
        for (i, _) in text.match_indices("](") {
            let rest = &text[i + 2..];
            let Some(end) = rest.find(')') else { continue };
            let link = &rest[..end];
            if link.starts_with("http") || link.contains(' ') || link.is_empty() {
                continue;
            }
            let (file, anchor) = link.split_once('#').unwrap_or((link, ""));
            let target = if file.is_empty() {
                page.clone()
            } else {
                base.join(file)
            };
            if !target.exists() {
                problems.push(format!("{}: link {link}: no such file", page.display()));
                continue;
            }
            if !anchor.is_empty() {
                let md = std::fs::read_to_string(&target).unwrap_or_default();
                if !anchors(&md).contains(anchor) {
                    problems.push(format!("{}: link {link}: no such heading", page.display()));
                }
            }
        }
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}
