//! `rfmlab inspect FILE... [--json]`: what the data files hold.

use std::path::PathBuf;

use anyhow::Context;
use rfmlab::data::{inspect_file, InspectRow};

use super::common::Global;

#[derive(clap::Args, Debug)]
pub struct InspectArgs {
    /// UFF58 (.uff/.unv/...) or CSV files.
    #[arg(required = true)]
    pub files: Vec<PathBuf>,
    /// Print JSON (an array of rows) instead of a table.
    #[arg(long)]
    pub json: bool,
}

fn opt(v: Option<f64>) -> String {
    v.map(|x| format!("{x}")).unwrap_or_else(|| "-".into())
}

pub fn run(a: &InspectArgs, _g: &Global) -> anyhow::Result<()> {
    let mut rows: Vec<InspectRow> = Vec::new();
    for f in &a.files {
        rows.extend(inspect_file(f).with_context(|| format!("inspecting {}", f.display()))?);
    }
    if a.json {
        println!("{}", serde_json::to_string_pretty(&rows)?);
        return Ok(());
    }
    let head = [
        "file",
        "ds",
        "set",
        "kind",
        "response",
        "reference",
        "f0",
        "f1",
        "df",
        "n",
        "quantity",
        "units",
        "storage",
        "level",
        "notes",
    ];
    let table: Vec<[String; 15]> = rows
        .iter()
        .map(|r| {
            [
                r.file.clone(),
                r.dataset.to_string(),
                r.number.to_string(),
                r.kind.clone(),
                r.response.clone(),
                r.reference.clone(),
                opt(r.f0),
                opt(r.f1),
                r.df.map(|d| format!("{d}")).unwrap_or_else(|| {
                    if r.n > 0 {
                        "uneven".into()
                    } else {
                        "-".into()
                    }
                }),
                r.n.to_string(),
                r.quantity.clone(),
                r.units.clone(),
                r.storage.clone(),
                r.level.clone(),
                r.notes.clone(),
            ]
        })
        .collect();
    let mut w: Vec<usize> = head.iter().map(|h| h.chars().count()).collect();
    for t in &table {
        for (k, c) in t.iter().enumerate() {
            w[k] = w[k].max(c.chars().count());
        }
    }
    let line = |cells: Vec<String>| {
        let s: Vec<String> = cells
            .iter()
            .enumerate()
            .map(|(k, c)| format!("{c:<width$}", width = w[k]))
            .collect();
        println!("{}", s.join("  ").trim_end());
    };
    line(head.iter().map(|s| s.to_string()).collect());
    for t in table {
        line(t.to_vec());
    }
    Ok(())
}
