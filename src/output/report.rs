//! A markdown report (`report.md`) built block by block.

use std::path::Path;

use super::atomic::write_atomic_bytes;
use super::OutputError;

/// A markdown document: headings, paragraphs, tables and images, in order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Report {
    blocks: Vec<String>,
}

/// Escapes what would break a table cell: `|` and line breaks.
fn cell(s: &str) -> String {
    s.replace('|', "\\|").replace(['\r', '\n'], " ")
}

impl Report {
    pub fn new() -> Self {
        Report::default()
    }
    /// A heading of `level` 1..=6 (clamped).
    pub fn heading(&mut self, level: usize, text: &str) -> &mut Self {
        let level = level.clamp(1, 6);
        self.blocks.push(format!(
            "{} {}",
            "#".repeat(level),
            text.replace(['\r', '\n'], " ")
        ));
        self
    }
    /// A paragraph of markdown text (written as given).
    pub fn paragraph(&mut self, text: &str) -> &mut Self {
        self.blocks.push(text.trim_end().to_string());
        self
    }
    /// A table; rows shorter than the header are padded with empty cells, longer ones keep
    /// their extra cells (markdown renderers drop them), `|` in cells is escaped.
    pub fn table<S: AsRef<str>, T: AsRef<str>>(
        &mut self,
        headers: &[S],
        rows: &[Vec<T>],
    ) -> &mut Self {
        let n = headers.len().max(1);
        let mut s = String::new();
        let head: Vec<String> = headers.iter().map(|h| cell(h.as_ref())).collect();
        s.push_str(&format!("| {} |\n", head.join(" | ")));
        s.push_str(&format!("|{}\n", "---|".repeat(n)));
        for row in rows {
            let mut cells: Vec<String> = row.iter().map(|c| cell(c.as_ref())).collect();
            while cells.len() < n {
                cells.push(String::new());
            }
            s.push_str(&format!("| {} |\n", cells.join(" | ")));
        }
        self.blocks.push(s.trim_end().to_string());
        self
    }
    /// An image link; `path` should be relative to the report's folder (spaces are encoded).
    pub fn image(&mut self, path: impl AsRef<Path>, alt: &str) -> &mut Self {
        let p = path
            .as_ref()
            .to_string_lossy()
            .replace('\\', "/")
            .replace(' ', "%20");
        self.blocks
            .push(format!("![{}]({p})", alt.replace([']', '\n'], " ")));
        self
    }
    /// The document as markdown text.
    pub fn to_markdown(&self) -> String {
        let mut s = self.blocks.join("\n\n");
        s.push('\n');
        s
    }
    /// Writes the document to `path` atomically (normally `<results>/report.md`).
    pub fn write(&self, path: impl AsRef<Path>) -> Result<(), OutputError> {
        write_atomic_bytes(path, self.to_markdown().as_bytes())
    }
}
