//! Sharded tables: each shard of a run writes its rows of a table as one part of a
//! hive-partitioned parquet dataset, `DIR/<table>/shard=<i>/part.parquet`, which polars
//! (`scan_parquet("DIR/<table>/**/*.parquet", hive_partitioning=True)`), pyarrow
//! (`pyarrow.dataset.dataset("DIR/<table>", partitioning="hive")`) and DuckDB
//! (`read_parquet('DIR/<table>/*/*.parquet', hive_partitioning = true)`) read as one table,
//! with `shard` as a column taken from the folder names.
//!
//! Every table of a sharded run carries an integer column `unit` (the independent unit that
//! made the row; unit `k` runs in shard `k mod n`). [`merge_parts`] concatenates the parts and
//! orders the rows by `unit` (stably, so rows of one unit keep their order): the merge of any
//! number of shards is the single-machine table, value for value.

use super::{ColumnData, OutputError, Table};
use std::path::{Path, PathBuf};

/// Which part of the units a process runs: unit `k` belongs to shard `k mod count`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    pub index: usize,
    pub count: usize,
}

/// A `--shard` value that is not `i/n` with `0 <= i < n`.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("--shard {0}: give i/n with 0 <= i < n, e.g. 0/3 (Slurm: $SLURM_ARRAY_TASK_ID/$SLURM_ARRAY_TASK_COUNT)")]
pub struct BadShard(pub String);

impl Shard {
    /// The whole run in one process.
    pub const ALL: Shard = Shard { index: 0, count: 1 };

    /// Parse `i/n` (0 <= i < n).
    pub fn parse(s: &str) -> Result<Shard, BadShard> {
        let bad = || BadShard(s.to_string());
        let (a, b) = s.split_once('/').ok_or_else(bad)?;
        let index: usize = a.trim().parse().map_err(|_| bad())?;
        let count: usize = b.trim().parse().map_err(|_| bad())?;
        if count == 0 || index >= count {
            return Err(bad());
        }
        Ok(Shard { index, count })
    }

    /// Whether unit `k` is this shard's.
    pub fn owns(&self, k: usize) -> bool {
        k % self.count == self.index
    }
}

/// Path of a shard's part of `table` under `dir`.
pub fn part_path(dir: &Path, table: &str, shard: Shard) -> PathBuf {
    dir.join(table)
        .join(format!("shard={}", shard.index))
        .join("part.parquet")
}

/// Write a shard's part of a table (atomically; the folder is created).
pub fn write_part(dir: &Path, table: &Table, shard: Shard) -> Result<PathBuf, OutputError> {
    let p = part_path(dir, table.name(), shard);
    if let Some(parent) = p.parent() {
        std::fs::create_dir_all(parent).map_err(|e| OutputError::io(parent, "create", e))?;
    }
    table.write_parquet(&p)?;
    Ok(p)
}

/// The parts of `table` under `dir`, in shard order.
pub fn list_parts(dir: &Path, table: &str) -> Result<Vec<(usize, PathBuf)>, OutputError> {
    let root = dir.join(table);
    let mut parts = Vec::new();
    let rd = match std::fs::read_dir(&root) {
        Ok(rd) => rd,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(parts),
        Err(e) => return Err(OutputError::io(&root, "read", e)),
    };
    for entry in rd {
        let entry = entry.map_err(|e| OutputError::io(&root, "read", e))?;
        let name = entry.file_name().to_string_lossy().into_owned();
        if let Some(i) = name.strip_prefix("shard=").and_then(|s| s.parse().ok()) {
            let p = entry.path().join("part.parquet");
            if p.is_file() {
                parts.push((i, p));
            }
        }
    }
    parts.sort();
    Ok(parts)
}

/// Concatenate tables of one schema and order the rows by the integer column `unit`
/// (stable). Errors name the table and the column that differ.
pub fn concat_by_unit(name: &str, parts: &[Table]) -> Result<Table, OutputError> {
    let bad = |m: String| OutputError::Shard {
        table: name.to_string(),
        message: m,
    };
    let Some(first) = parts.first() else {
        return Ok(Table::new(name));
    };
    let mut cols: Vec<(String, String, ColumnData)> = first
        .columns()
        .iter()
        .map(|(n, c)| {
            (
                n.clone(),
                first.unit(n).unwrap_or("").to_string(),
                empty_like(c),
            )
        })
        .collect();
    for t in parts {
        if t.n_cols() != cols.len() {
            return Err(bad(format!(
                "a part has {} columns, another {}: the parts come from different versions; rerun all shards",
                t.n_cols(),
                cols.len()
            )));
        }
        for (n, _, acc) in cols.iter_mut() {
            let c = t
                .column(n)
                .ok_or_else(|| bad(format!("a part lacks column {n}")))?;
            append(acc, c).map_err(|k| bad(format!("column {n}: {k}")))?;
        }
    }
    let unit = match cols.iter().find(|(n, _, _)| n == "unit") {
        Some((_, _, ColumnData::I64(u))) => u.clone(),
        _ => return Err(bad("no integer column `unit` to order the rows by".into())),
    };
    let mut order: Vec<usize> = (0..unit.len()).collect();
    order.sort_by_key(|&r| unit[r]);
    let mut out = Table::new(name);
    for (n, u, c) in cols {
        out.push(n, u, permute(&c, &order))?;
    }
    Ok(out)
}

/// Read every part of `table` under `dir` and combine them ([`concat_by_unit`]).
pub fn merge_parts(dir: &Path, table: &str) -> Result<Table, OutputError> {
    let parts = list_parts(dir, table)?
        .into_iter()
        .map(|(_, p)| Table::read_parquet(p))
        .collect::<Result<Vec<_>, _>>()?;
    concat_by_unit(table, &parts)
}

fn empty_like(c: &ColumnData) -> ColumnData {
    match c {
        ColumnData::F64(_) => ColumnData::F64(Vec::new()),
        ColumnData::I64(_) => ColumnData::I64(Vec::new()),
        ColumnData::U32(_) => ColumnData::U32(Vec::new()),
        ColumnData::Str(_) => ColumnData::Str(Vec::new()),
        ColumnData::Bool(_) => ColumnData::Bool(Vec::new()),
        ColumnData::OptF64(_) => ColumnData::OptF64(Vec::new()),
    }
}

/// Two parts of one column hold different kinds of values.
#[derive(Debug, thiserror::Error)]
#[error("{0} in one part, {1} in another")]
struct KindMismatch(&'static str, &'static str);

fn append(acc: &mut ColumnData, c: &ColumnData) -> Result<(), KindMismatch> {
    match (acc, c) {
        (ColumnData::F64(a), ColumnData::F64(b)) => a.extend_from_slice(b),
        (ColumnData::I64(a), ColumnData::I64(b)) => a.extend_from_slice(b),
        (ColumnData::U32(a), ColumnData::U32(b)) => a.extend_from_slice(b),
        (ColumnData::Str(a), ColumnData::Str(b)) => a.extend_from_slice(b),
        (ColumnData::Bool(a), ColumnData::Bool(b)) => a.extend_from_slice(b),
        (ColumnData::OptF64(a), ColumnData::OptF64(b)) => a.extend_from_slice(b),
        // A f64 column without nulls in one part and with nulls in another.
        (ColumnData::OptF64(a), ColumnData::F64(b)) => a.extend(b.iter().map(|v| Some(*v))),
        (a, b) => return Err(KindMismatch(a.kind(), b.kind())),
    }
    Ok(())
}

fn permute(c: &ColumnData, order: &[usize]) -> ColumnData {
    fn p<T: Clone>(v: &[T], o: &[usize]) -> Vec<T> {
        o.iter().map(|&i| v[i].clone()).collect()
    }
    match c {
        ColumnData::F64(v) => ColumnData::F64(p(v, order)),
        ColumnData::I64(v) => ColumnData::I64(p(v, order)),
        ColumnData::U32(v) => ColumnData::U32(p(v, order)),
        ColumnData::Str(v) => ColumnData::Str(p(v, order)),
        ColumnData::Bool(v) => ColumnData::Bool(p(v, order)),
        ColumnData::OptF64(v) => ColumnData::OptF64(p(v, order)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn part(units: &[i64], x: &[f64]) -> Table {
        let mut t = Table::new("t");
        t.push_i64("unit", "", units.to_vec()).unwrap();
        t.push_f64("x", "Pa", x.to_vec()).unwrap();
        t
    }

    #[test]
    fn shard_parse_and_ownership() {
        assert_eq!(Shard::parse("1/3").unwrap(), Shard { index: 1, count: 3 });
        assert!(Shard::parse("3/3").is_err());
        assert!(Shard::parse("0/0").is_err());
        assert!(Shard::parse("a").is_err());
        let s = Shard::parse("2/3").unwrap();
        let owned: Vec<usize> = (0..9).filter(|&k| s.owns(k)).collect();
        assert_eq!(owned, vec![2, 5, 8]);
    }

    #[test]
    fn parts_merge_in_unit_order_with_rows_of_a_unit_kept_in_order() {
        let dir = tempfile::tempdir().unwrap();
        // Units 0..5 over 2 shards; unit 2 has two rows.
        let a = part(&[0, 2, 2, 4], &[0.0, 2.0, 2.5, 4.0]);
        let b = part(&[1, 3], &[1.0, 3.0]);
        write_part(dir.path(), &a, Shard { index: 0, count: 2 }).unwrap();
        write_part(dir.path(), &b, Shard { index: 1, count: 2 }).unwrap();
        let m = merge_parts(dir.path(), "t").unwrap();
        assert_eq!(
            m.column("unit"),
            Some(&ColumnData::I64(vec![0, 1, 2, 2, 3, 4]))
        );
        assert_eq!(
            m.column("x"),
            Some(&ColumnData::F64(vec![0.0, 1.0, 2.0, 2.5, 3.0, 4.0]))
        );
        assert_eq!(m.unit("x"), Some("Pa"));
        let mut bad = Table::new("t");
        bad.push_i64("unit", "", vec![5]).unwrap();
        bad.push_str("x", vec!["a".into()]).unwrap();
        assert!(concat_by_unit("t", &[a, bad]).is_err());
    }
}
