//! Rows describing the contents of UFF58 and CSV files (`rfmlab inspect`).

use std::path::Path;

use crate::data::csv::{quantity_name, read_csv, CsvOptions};
use crate::data::uff58::{read_uff, Precision};
use crate::data::uff_frf::{dataset_dofs, detect_quantity, role, Role, UffImportOptions};
use crate::data::DataError;

/// One dataset (UFF) or channel (CSV) of a file.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct InspectRow {
    pub file: String,
    /// Dataset index (0-based) in a UFF file; channel index in a CSV file.
    pub dataset: usize,
    /// Dataset number (58, 164, 151, ...); 0 for CSV rows.
    pub number: i64,
    /// "FRF", "coherence", "function type N", "units", "skipped", "csv FRF".
    pub kind: String,
    /// Response and reference DOF like `1+z` (empty when none).
    pub response: String,
    pub reference: String,
    /// First and last abscissa value, increment (None when uneven), number of points.
    pub f0: Option<f64>,
    pub f1: Option<f64>,
    pub df: Option<f64>,
    pub n: usize,
    /// "accelerance", "mobility", "receptance" or "" when unknown / not an FRF.
    pub quantity: String,
    /// Ordinate units label (UFF) or "SI".
    pub units: String,
    /// "complex double", "real single", ... or "".
    pub storage: String,
    /// Level: ID line 4 (load case name) for UFF, the level column for CSV.
    pub level: String,
    /// Reader notes or the reason a dataset was skipped.
    pub notes: String,
}

fn is_csv(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("csv"))
}

/// Describe a UFF (any extension but `.csv`) or CSV file. CSV files whose quantity is not
/// stated are read as accelerance for the listing only.
pub fn inspect_file(path: impl AsRef<Path>) -> Result<Vec<InspectRow>, DataError> {
    let path = path.as_ref();
    let label = path.display().to_string();
    let mut rows = Vec::new();
    if is_csv(path) {
        let opts = CsvOptions {
            quantity: Some(crate::data::Quantity::Accelerance),
            ..Default::default()
        };
        let set = read_csv(path, &opts)?;
        for l in &set.levels {
            let n = l.freq_hz.len();
            for (i, c) in l.channels.iter().enumerate() {
                rows.push(InspectRow {
                    file: label.clone(),
                    dataset: i,
                    number: 0,
                    kind: if c.coherence.is_some() {
                        "csv FRF+coherence".into()
                    } else {
                        "csv FRF".into()
                    },
                    response: format!("{}{}", c.response_id, c.response_dir),
                    reference: format!("{}{}", c.reference_id, c.reference_dir),
                    f0: l.freq_hz.first().copied(),
                    f1: l.freq_hz.last().copied(),
                    df: even_df(&l.freq_hz),
                    n,
                    quantity: quantity_name(l.quantity).into(),
                    units: "SI".into(),
                    storage: "text".into(),
                    level: l.name.clone(),
                    notes: String::new(),
                });
            }
        }
        return Ok(rows);
    }
    let f = read_uff(path)?;
    let opts = UffImportOptions::default();
    for d in &f.datasets {
        match role(d, &opts) {
            Role::Frf => crate::data::checks::check_dataset(&label, d, false)?,
            Role::Coherence => crate::data::checks::check_dataset(&label, d, true)?,
            Role::Other => {}
        }
        let kind = match role(d, &opts) {
            Role::Frf => "FRF".to_string(),
            Role::Coherence => "coherence".to_string(),
            Role::Other => format!("function type {}", d.func_type),
        };
        let (response, reference) = match dataset_dofs(d, &opts) {
            Some(((r, rd), (c, cd))) => (format!("{r}{rd}"), format!("{c}{cd}")),
            None => (
                format!("{} {} {}", d.rsp_entity, d.rsp_node, d.rsp_dir),
                format!("{} {} {}", d.ref_entity, d.ref_node, d.ref_dir),
            ),
        };
        let quantity = if role(d, &opts) == Role::Frf {
            detect_quantity(d)
                .map(|(q, _)| quantity_name(q).to_string())
                .unwrap_or_else(|| "unknown".into())
        } else {
            String::new()
        };
        let storage = format!(
            "{} {}{}",
            if d.values.is_complex() {
                "complex"
            } else {
                "real"
            },
            if d.precision == Precision::Single {
                "single"
            } else {
                "double"
            },
            if d.binary { " 58b" } else { "" }
        );
        let level = d.ids[3].trim();
        rows.push(InspectRow {
            file: label.clone(),
            dataset: d.index,
            number: 58,
            kind,
            response,
            reference,
            f0: d.x.first().copied(),
            f1: d.x.last().copied(),
            df: if d.even { Some(d.dx) } else { None },
            n: d.num_pts,
            quantity,
            units: d.ordinate.units_label.clone(),
            storage,
            level: if level == "NONE" {
                String::new()
            } else {
                level.to_string()
            },
            notes: d.notes.join("; "),
        });
    }
    if let Some(u) = &f.units {
        rows.push(InspectRow {
            file: label.clone(),
            dataset: u.index,
            number: 164,
            kind: "units".into(),
            response: String::new(),
            reference: String::new(),
            f0: None,
            f1: None,
            df: None,
            n: 0,
            quantity: String::new(),
            units: format!("{} (length {}, force {})", u.description, u.length, u.force),
            storage: String::new(),
            level: String::new(),
            notes: String::new(),
        });
    }
    for s in &f.skipped {
        rows.push(InspectRow {
            file: label.clone(),
            dataset: s.index,
            number: s.number,
            kind: "skipped".into(),
            response: String::new(),
            reference: String::new(),
            f0: None,
            f1: None,
            df: None,
            n: 0,
            quantity: String::new(),
            units: String::new(),
            storage: String::new(),
            level: String::new(),
            notes: s.reason.clone(),
        });
    }
    rows.sort_by_key(|r| r.dataset);
    Ok(rows)
}

fn even_df(f: &[f64]) -> Option<f64> {
    if f.len() < 2 {
        return None;
    }
    let df = (f[f.len() - 1] - f[0]) / (f.len() - 1) as f64;
    let scale = f[f.len() - 1].abs().max(f[0].abs());
    f.iter()
        .enumerate()
        .all(|(k, x)| (x - (f[0] + k as f64 * df)).abs() <= 1e-9 * scale)
        .then_some(df)
}
