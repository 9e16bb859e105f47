//! Result files: atomic writes, parquet tables, the run manifest, the results folder and the
//! markdown report. This module sits outside the numerical core: it may use anything in the
//! library, but numerical modules never import it.
//!
//! # Conventions for every table rfmlab writes
//! - Column names are `snake_case`; a name carries its unit as a suffix where the unit is not
//!   an SI base or derived unit written out in the name (`freq_hz`, `omega_rad_s`); moduli are
//!   in Pa, accelerances in (m/s^2)/N.
//! - Units are stored **inside each parquet file**, as file-level key-value metadata:
//!   key `rfmlab.units` holds a JSON object `{"column": "unit", ...}` (`""` for labels and
//!   counters, `"1"` for dimensionless ratios), key `rfmlab.table` the table name and key
//!   `rfmlab.columns` the column kinds (used to restore [`ColumnData::OptF64`] exactly).
//!   Python: `pyarrow.parquet.ParquetFile(path).metadata.metadata[b"rfmlab.units"]` or
//!   `polars.read_parquet_metadata(path)["rfmlab.units"]`.
//! - A complex quantity `x` is stored as two f64 columns `x_re` and `x_im` (same unit);
//!   see [`Table::push_c64`] and [`Table::c64_column`].
//! - Every file is written atomically ([`write_atomic`], on [`crate::fs_atomic`]): a uniquely
//!   named temporary file in the same folder, fsync, rename. An interrupted or failed run never
//!   leaves a half-written file and earlier results stay intact.
//! - A results folder is replaced only when rfmlab made it (its `manifest.json`), it is empty
//!   or absent, or the caller forces it ([`contract`]); it is filled as a temporary sibling and
//!   swapped in whole ([`swap`]).

mod atomic;
mod columns;
pub mod contract;
mod error;
mod manifest;
mod report;
mod results_dir;
mod table;

pub(crate) use atomic::{check_parent, commit, temp_sibling};
pub use atomic::{write_atomic, write_atomic_bytes};
pub use columns::Columns;
pub use error::OutputError;
pub use manifest::{
    git_revision, sha256_file, sha256_hex, utc_now_rfc3339, FileEntry, Manifest, StepTiming,
};
pub use report::Report;
pub use results_dir::ResultsDir;
pub use table::{ColumnData, Table};
pub mod shards;
pub mod swap;
pub use contract::{claim_file, claim_folder, Replace};
pub use swap::{replace_dir, replace_dir_as};
