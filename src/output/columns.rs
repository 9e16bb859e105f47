//! Row-by-row construction of a [`Table`].

use super::{OutputError, Table};

/// A table built row by row: push each row's values by column name (columns appear in the
/// order first pushed, strings first, then integers, then floats), then turn it into a
/// [`Table`]. The short names keep row-building code readable: `s` string, `f` float with its
/// unit, `i` integer.
#[derive(Default)]
pub struct Columns {
    str_cols: Vec<(String, Vec<String>)>,
    f64_cols: Vec<(String, String, Vec<f64>)>,
    i64_cols: Vec<(String, Vec<i64>)>,
}

impl Columns {
    pub fn s(&mut self, name: &str, v: String) {
        match self.str_cols.iter_mut().find(|c| c.0 == name) {
            Some(c) => c.1.push(v),
            None => self.str_cols.push((name.to_string(), vec![v])),
        }
    }
    pub fn f(&mut self, name: &str, unit: &str, v: f64) {
        match self.f64_cols.iter_mut().find(|c| c.0 == name) {
            Some(c) => c.2.push(v),
            None => self
                .f64_cols
                .push((name.to_string(), unit.to_string(), vec![v])),
        }
    }
    pub fn i(&mut self, name: &str, v: i64) {
        match self.i64_cols.iter_mut().find(|c| c.0 == name) {
            Some(c) => c.1.push(v),
            None => self.i64_cols.push((name.to_string(), vec![v])),
        }
    }
    pub fn table(self, name: &str) -> Result<Table, OutputError> {
        let mut t = Table::new(name);
        for (n, v) in self.str_cols {
            t.push_str(n, v)?;
        }
        for (n, v) in self.i64_cols {
            t.push_i64(n, "", v)?;
        }
        for (n, u, v) in self.f64_cols {
            t.push_f64(n, u, v)?;
        }
        Ok(t)
    }
}
