//! A small column-oriented table, written to and read from parquet with polars.

use std::collections::BTreeMap;
use std::fs::File;
use std::path::Path;

use polars_core::prelude::{Column, DataFrame, DataType};
use polars_io::parquet::read::ParquetReader;
use polars_io::parquet::write::{KeyValueMetadata, ParquetWriter};
use polars_io::SerReader;

use super::atomic::write_atomic;
use super::OutputError;
use crate::common::C64;

/// Key of the parquet key-value metadata entry holding `{"column": "unit"}` as JSON.
pub const UNITS_KEY: &str = "rfmlab.units";
/// Key of the metadata entry holding the table name.
pub const TABLE_KEY: &str = "rfmlab.table";
/// Key of the metadata entry holding `{"column": "kind"}` (kinds as in [`ColumnData::kind`]).
pub const KINDS_KEY: &str = "rfmlab.columns";

/// The values of one column. All columns of a [`Table`] have the same length.
#[derive(Clone, Debug, PartialEq)]
pub enum ColumnData {
    F64(Vec<f64>),
    I64(Vec<i64>),
    U32(Vec<u32>),
    Str(Vec<String>),
    Bool(Vec<bool>),
    /// f64 with missing values (stored as parquet nulls), e.g. a FRAC that was not computed.
    OptF64(Vec<Option<f64>>),
}

impl ColumnData {
    /// Number of rows.
    pub fn len(&self) -> usize {
        match self {
            ColumnData::F64(v) => v.len(),
            ColumnData::I64(v) => v.len(),
            ColumnData::U32(v) => v.len(),
            ColumnData::Str(v) => v.len(),
            ColumnData::Bool(v) => v.len(),
            ColumnData::OptF64(v) => v.len(),
        }
    }
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// The kind name stored in the file metadata: `f64`, `i64`, `u32`, `str`, `bool`, `opt_f64`.
    pub fn kind(&self) -> &'static str {
        match self {
            ColumnData::F64(_) => "f64",
            ColumnData::I64(_) => "i64",
            ColumnData::U32(_) => "u32",
            ColumnData::Str(_) => "str",
            ColumnData::Bool(_) => "bool",
            ColumnData::OptF64(_) => "opt_f64",
        }
    }
    /// The values as f64 if the column is `F64`.
    pub fn as_f64(&self) -> Option<&[f64]> {
        match self {
            ColumnData::F64(v) => Some(v),
            _ => None,
        }
    }
    fn to_polars(&self, name: &str) -> Column {
        match self {
            ColumnData::F64(v) => Column::new(name.into(), v),
            ColumnData::I64(v) => Column::new(name.into(), v),
            ColumnData::U32(v) => Column::new(name.into(), v),
            ColumnData::Str(v) => Column::new(name.into(), v),
            ColumnData::Bool(v) => Column::new(name.into(), v),
            ColumnData::OptF64(v) => Column::new(name.into(), v),
        }
    }
}

/// A named table of equally long columns, each with a unit.
///
/// Built column by column (`push_*`), written atomically to parquet with
/// [`Table::write_parquet`] and read back with [`Table::read_parquet`]. Column names must be
/// `snake_case` (`[a-z][a-z0-9_]*`) and unique; units are free text (`"Hz"`, `"Pa"`,
/// `"(m/s^2)/N"`, `"1"` for ratios, `""` for labels and counters).
#[derive(Clone, Debug, PartialEq)]
pub struct Table {
    name: String,
    columns: Vec<(String, ColumnData)>,
    units: Vec<(String, String)>,
}

fn check_snake_case(name: &str) -> Result<(), &'static str> {
    let mut chars = name.chars();
    match chars.next() {
        None => return Err("the name is empty"),
        Some(c) if !c.is_ascii_lowercase() => {
            return Err("a column name must start with a lowercase ASCII letter (snake_case)")
        }
        _ => {}
    }
    if chars.all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_') {
        Ok(())
    } else {
        Err("a column name may hold only a-z, 0-9 and '_' (snake_case, unit as suffix: freq_hz)")
    }
}

impl Table {
    /// An empty table; `name` becomes the file stem in [`super::ResultsDir::write_table`].
    pub fn new(name: impl Into<String>) -> Self {
        Table {
            name: name.into(),
            columns: Vec::new(),
            units: Vec::new(),
        }
    }
    pub fn name(&self) -> &str {
        &self.name
    }
    /// Number of rows (0 for a table without columns).
    pub fn n_rows(&self) -> usize {
        self.columns.first().map_or(0, |(_, c)| c.len())
    }
    pub fn n_cols(&self) -> usize {
        self.columns.len()
    }
    /// Columns in insertion order.
    pub fn columns(&self) -> &[(String, ColumnData)] {
        &self.columns
    }
    /// `(column, unit)` pairs in column order.
    pub fn units(&self) -> &[(String, String)] {
        &self.units
    }
    /// The column called `name`.
    pub fn column(&self, name: &str) -> Option<&ColumnData> {
        self.columns.iter().find(|(n, _)| n == name).map(|(_, c)| c)
    }
    /// The unit of column `name`.
    pub fn unit(&self, name: &str) -> Option<&str> {
        self.units
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, u)| u.as_str())
    }
    /// The complex column stored as `<name>_re` and `<name>_im`.
    pub fn c64_column(&self, name: &str) -> Option<Vec<C64>> {
        let re = self.column(&format!("{name}_re"))?.as_f64()?;
        let im = self.column(&format!("{name}_im"))?.as_f64()?;
        Some(re.iter().zip(im).map(|(&r, &i)| C64::new(r, i)).collect())
    }

    fn bad(&self, column: &str, reason: impl Into<String>) -> OutputError {
        OutputError::BadColumn {
            table: self.name.clone(),
            column: column.to_string(),
            reason: reason.into(),
        }
    }

    /// Adds a column. Fails (leaving the table unchanged) if the name is not snake_case, is
    /// already used, or the length differs from the existing columns.
    pub fn push(
        &mut self,
        name: impl Into<String>,
        unit: impl Into<String>,
        data: ColumnData,
    ) -> Result<&mut Self, OutputError> {
        let name = name.into();
        check_snake_case(&name).map_err(|r| self.bad(&name, r))?;
        if self.column(&name).is_some() {
            return Err(self.bad(&name, "a column of that name already exists"));
        }
        if let Some((first, c)) = self.columns.first() {
            if c.len() != data.len() {
                return Err(self.bad(
                    &name,
                    format!(
                        "it has {} rows but column '{first}' has {} (all columns must be equally long)",
                        data.len(),
                        c.len()
                    ),
                ));
            }
        }
        self.units.push((name.clone(), unit.into()));
        self.columns.push((name, data));
        Ok(self)
    }
    pub fn push_f64(
        &mut self,
        name: impl Into<String>,
        unit: impl Into<String>,
        values: Vec<f64>,
    ) -> Result<&mut Self, OutputError> {
        self.push(name, unit, ColumnData::F64(values))
    }
    pub fn push_i64(
        &mut self,
        name: impl Into<String>,
        unit: impl Into<String>,
        values: Vec<i64>,
    ) -> Result<&mut Self, OutputError> {
        self.push(name, unit, ColumnData::I64(values))
    }
    pub fn push_u32(
        &mut self,
        name: impl Into<String>,
        unit: impl Into<String>,
        values: Vec<u32>,
    ) -> Result<&mut Self, OutputError> {
        self.push(name, unit, ColumnData::U32(values))
    }
    /// A label column (unit `""`).
    pub fn push_str(
        &mut self,
        name: impl Into<String>,
        values: Vec<String>,
    ) -> Result<&mut Self, OutputError> {
        self.push(name, "", ColumnData::Str(values))
    }
    /// A flag column (unit `""`).
    pub fn push_bool(
        &mut self,
        name: impl Into<String>,
        values: Vec<bool>,
    ) -> Result<&mut Self, OutputError> {
        self.push(name, "", ColumnData::Bool(values))
    }
    pub fn push_opt_f64(
        &mut self,
        name: impl Into<String>,
        unit: impl Into<String>,
        values: Vec<Option<f64>>,
    ) -> Result<&mut Self, OutputError> {
        self.push(name, unit, ColumnData::OptF64(values))
    }
    /// A complex column, stored as the two f64 columns `<name>_re` and `<name>_im`, both with
    /// `unit`. Both are added or neither.
    pub fn push_c64(
        &mut self,
        name: &str,
        unit: &str,
        values: &[C64],
    ) -> Result<&mut Self, OutputError> {
        let re_name = format!("{name}_re");
        let im_name = format!("{name}_im");
        if self.column(&im_name).is_some() {
            return Err(self.bad(&im_name, "a column of that name already exists"));
        }
        self.push_f64(re_name, unit, values.iter().map(|z| z.re).collect())?;
        self.push_f64(im_name, unit, values.iter().map(|z| z.im).collect())
    }

    fn polars_err(&self, path: &Path, source: polars_core::error::PolarsError) -> OutputError {
        OutputError::Polars {
            table: self.name.clone(),
            path: path.to_path_buf(),
            source,
        }
    }

    /// The table as a polars `DataFrame` (units are not part of it).
    pub fn to_dataframe(&self) -> Result<DataFrame, OutputError> {
        let cols = self
            .columns
            .iter()
            .map(|(n, c)| c.to_polars(n))
            .collect::<Vec<_>>();
        DataFrame::new(self.n_rows(), cols).map_err(|e| self.polars_err(Path::new(""), e))
    }

    fn metadata(&self) -> Result<KeyValueMetadata, OutputError> {
        let units: BTreeMap<&str, &str> = self
            .units
            .iter()
            .map(|(n, u)| (n.as_str(), u.as_str()))
            .collect();
        let kinds: BTreeMap<&str, &str> = self
            .columns
            .iter()
            .map(|(n, c)| (n.as_str(), c.kind()))
            .collect();
        let json = |v: &BTreeMap<&str, &str>| {
            serde_json::to_string(v).map_err(|source| OutputError::Json {
                path: self.name.clone().into(),
                source,
            })
        };
        Ok(KeyValueMetadata::from_static(vec![
            (TABLE_KEY.to_string(), self.name.clone()),
            (UNITS_KEY.to_string(), json(&units)?),
            (KINDS_KEY.to_string(), json(&kinds)?),
        ]))
    }

    /// Writes the table to `path` as parquet (zstd), atomically, with the units in the file
    /// metadata (see the module documentation).
    pub fn write_parquet(&self, path: impl AsRef<Path>) -> Result<(), OutputError> {
        let path = path.as_ref();
        let mut df = self.to_dataframe().map_err(|e| match e {
            OutputError::Polars { source, .. } => self.polars_err(path, source),
            other => other,
        })?;
        let meta = self.metadata()?;
        write_atomic(path, |w| {
            ParquetWriter::new(w)
                .with_key_value_metadata(Some(meta))
                .set_parallel(false)
                .finish(&mut df)
                .map(|_| ())
                .map_err(std::io::Error::other)
        })
    }

    /// Reads a parquet file written by [`Table::write_parquet`] (or any parquet file whose
    /// columns are f64, i64, u32, string or bool). Units and the table name come from the file
    /// metadata when present (else units are `""` and the name is the file stem). A f64 column
    /// with nulls reads as [`ColumnData::OptF64`].
    pub fn read_parquet(path: impl AsRef<Path>) -> Result<Table, OutputError> {
        let path = path.as_ref();
        let stem = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        let perr = |source| OutputError::Polars {
            table: stem.clone(),
            path: path.to_path_buf(),
            source,
        };
        let file = File::open(path).map_err(|e| OutputError::io(path, "open", e))?;
        let mut reader = ParquetReader::new(file);
        let kv: BTreeMap<String, String> = reader
            .get_metadata()
            .map_err(perr)?
            .key_value_metadata()
            .iter()
            .flatten()
            .filter_map(|kv| Some((kv.key.clone(), kv.value.clone()?)))
            .collect();
        let df = reader.finish().map_err(perr)?;

        let parse_map = |key: &str| -> Result<BTreeMap<String, String>, OutputError> {
            match kv.get(key) {
                None => Ok(BTreeMap::new()),
                Some(s) => serde_json::from_str(s).map_err(|source| OutputError::Json {
                    path: path.to_path_buf(),
                    source,
                }),
            }
        };
        let units = parse_map(UNITS_KEY)?;
        let kinds = parse_map(KINDS_KEY)?;
        let mut table = Table::new(kv.get(TABLE_KEY).cloned().unwrap_or(stem.clone()));

        for col in df.columns() {
            let name = col.name().to_string();
            let unsupported = || OutputError::UnsupportedColumn {
                path: path.to_path_buf(),
                column: name.clone(),
                dtype: col.dtype().to_string(),
            };
            let no_nulls = |has_nulls: bool| {
                if has_nulls {
                    Err(OutputError::BadColumn {
                        table: table.name.clone(),
                        column: name.clone(),
                        reason: format!(
                            "'{}' holds missing values, which only f64 columns may have",
                            path.display()
                        ),
                    })
                } else {
                    Ok(())
                }
            };
            let has_nulls = col.null_count() > 0;
            let data = match col.dtype() {
                DataType::Float64 => {
                    let ca = col.f64().map_err(perr)?;
                    if has_nulls || kinds.get(&name).map(String::as_str) == Some("opt_f64") {
                        ColumnData::OptF64(ca.iter().collect())
                    } else {
                        ColumnData::F64(ca.no_null_iter().collect())
                    }
                }
                DataType::Int64 => {
                    no_nulls(has_nulls)?;
                    ColumnData::I64(col.i64().map_err(perr)?.no_null_iter().collect())
                }
                DataType::UInt32 => {
                    no_nulls(has_nulls)?;
                    ColumnData::U32(col.u32().map_err(perr)?.no_null_iter().collect())
                }
                DataType::String => {
                    no_nulls(has_nulls)?;
                    ColumnData::Str(
                        col.str()
                            .map_err(perr)?
                            .no_null_iter()
                            .map(str::to_string)
                            .collect(),
                    )
                }
                DataType::Boolean => {
                    no_nulls(has_nulls)?;
                    ColumnData::Bool(col.bool().map_err(perr)?.no_null_iter().collect())
                }
                _ => return Err(unsupported()),
            };
            let unit = units.get(&name).cloned().unwrap_or_default();
            // Files from elsewhere may hold names that are not snake_case: keep them as read.
            table.units.push((name.clone(), unit));
            table.columns.push((name, data));
        }
        Ok(table)
    }
}
