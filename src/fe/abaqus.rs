//! Abaqus/Standard matrix output: the text files written by a matrix-generation step,
//!
//! ```text
//! *STEP
//! *MATRIX GENERATE, STIFFNESS, MASS
//! *MATRIX OUTPUT, STIFFNESS, MASS, FORMAT=MATRIX INPUT     (or FORMAT=COORDINATE)
//! *END STEP
//! ```
//!
//! one file per matrix (`<job>_STIF<step>.mtx`, `<job>_MASS<step>.mtx`, `<job>_DMPV<step>.mtx`
//! viscous, `<job>_DMPS<step>.mtx` structural damping).
//!
//! # Formats read
//! * `FORMAT=MATRIX INPUT` (the default): one entry per line,
//!   `row node, row DOF, column node, column DOF, value`, comma-separated. Nodes are Abaqus
//!   node labels (negative labels are Abaqus-internal nodes; an `Instance.label` form is
//!   accepted too), DOFs are Abaqus DOF numbers (1, 2, 3 translations in x, y, z; 4, 5, 6
//!   rotations). The equations of an imported model are all (node, DOF) pairs that occur in any
//!   of its files, ordered by instance name, node label, then DOF. Because the files are keyed
//!   by node, matrices generated over different element sets (the adherends, the adhesive) may
//!   be combined: a (node, DOF) missing from one file is a zero row there.
//! * `FORMAT=COORDINATE`: `row, column, value` with 1-based equation numbers (commas or
//!   blanks). The files carry no node labels: all matrices must come from one generation over
//!   the whole model (the same equation numbering), and the DOF map must use equation numbers.
//!
//! A symmetric matrix is written as one triangle and mirrored here; a file that stores both
//! triangles (every off-diagonal entry with its mirror) is read as it is; a file that mixes
//! the two is refused. An entry repeated at the same position is refused (Abaqus writes each
//! once). Lines starting with `**` are comments; keyword lines (`*...`) are refused, since
//! they mean a substructure or element-matrix file, not a `*MATRIX OUTPUT` file.
//!
//! Boundary conditions: Abaqus keeps a constrained DOF in the generated matrices and marks it
//! with a very large stiffness diagonal (1e36); [`crate::fe::foreign`] removes such DOFs.
//! Units are the model's (no conversion here).

use std::cmp::Ordering;
use std::collections::HashMap;
use std::fmt;
use std::path::{Path, PathBuf};

/// Errors of Abaqus matrix-file reading.
#[derive(Debug, thiserror::Error)]
pub enum AbqError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}, line {line}: {msg}")]
    Parse {
        path: PathBuf,
        line: usize,
        msg: String,
    },
}

/// An Abaqus node label: `number`, or `instance.number` in assembly output.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct NodeLabel {
    pub instance: String,
    pub number: i64,
}

impl NodeLabel {
    /// Parse `12`, `-3` or `Part-1-1.12` (the label after the last dot).
    pub fn parse(s: &str) -> Option<NodeLabel> {
        let s = s.trim();
        if let Ok(n) = s.parse::<i64>() {
            return Some(NodeLabel {
                instance: String::new(),
                number: n,
            });
        }
        let (inst, num) = s.rsplit_once('.')?;
        let number = num.trim().parse::<i64>().ok()?;
        let instance = inst.trim();
        (!instance.is_empty()).then(|| NodeLabel {
            instance: instance.to_string(),
            number,
        })
    }
}

impl PartialOrd for NodeLabel {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for NodeLabel {
    fn cmp(&self, other: &Self) -> Ordering {
        (self.instance.as_str(), self.number).cmp(&(other.instance.as_str(), other.number))
    }
}

impl fmt::Display for NodeLabel {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.instance.is_empty() {
            write!(f, "{}", self.number)
        } else {
            write!(f, "{}.{}", self.instance, self.number)
        }
    }
}

/// A (node, DOF) key of a `FORMAT=MATRIX INPUT` entry.
pub type NodeDof = (NodeLabel, u32);

/// One Abaqus matrix file as read, entries already made full (both triangles).
#[derive(Clone, Debug)]
pub enum AbaqusMatrix {
    /// `FORMAT=MATRIX INPUT`: (row key, column key, value).
    Labelled(Vec<(NodeDof, NodeDof, f64)>),
    /// `FORMAT=COORDINATE`: (row, column, value), 0-based equation numbers.
    Coordinate(Vec<(usize, usize, f64)>),
}

/// Read one Abaqus matrix file.
pub fn read_abaqus(path: &Path) -> Result<AbaqusMatrix, AbqError> {
    let text = std::fs::read_to_string(path).map_err(|source| AbqError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse_abaqus(&text, path)
}

/// Make a one-triangle entry list full, or check a full one (see the module docs). `line` of
/// each entry is used in errors.
fn symmetrise<K: Clone + Eq + std::hash::Hash>(
    entries: Vec<(K, K, f64, usize)>,
    path: &Path,
    show: impl Fn(&K) -> String,
) -> Result<Vec<(K, K, f64)>, AbqError> {
    let mut at: HashMap<(K, K), usize> = HashMap::with_capacity(entries.len());
    for (k, (r, c, _, ln)) in entries.iter().enumerate() {
        if let Some(prev) = at.insert((r.clone(), c.clone()), k) {
            return Err(AbqError::Parse {
                path: path.to_path_buf(),
                line: *ln,
                msg: format!(
                    "entry (row {}, column {}) is given twice (also on line {}): each position \
                     may appear once",
                    show(r),
                    show(c),
                    entries[prev].3
                ),
            });
        }
    }
    let (mut with_mirror, mut without) = (None::<usize>, None::<usize>);
    for (r, c, _, ln) in &entries {
        if r == c {
            continue;
        }
        if at.contains_key(&(c.clone(), r.clone())) {
            with_mirror.get_or_insert(*ln);
        } else {
            without.get_or_insert(*ln);
        }
    }
    match (with_mirror, without) {
        (Some(a), Some(b)) => Err(AbqError::Parse {
            path: path.to_path_buf(),
            line: a.max(b),
            msg: format!(
                "the file mixes one-triangle storage (line {b}: an entry without its mirror) and \
                 full storage (line {a}: an entry with its mirror); write one triangle (Abaqus \
                 default for symmetric matrices) or the full matrix"
            ),
        }),
        (None, _) => {
            // one triangle (or diagonal only): mirror
            let mut out = Vec::with_capacity(2 * entries.len());
            for (r, c, v, _) in entries {
                if r != c {
                    out.push((c.clone(), r.clone(), v));
                }
                out.push((r, c, v));
            }
            Ok(out)
        }
        (Some(_), None) => Ok(entries.into_iter().map(|(r, c, v, _)| (r, c, v)).collect()),
    }
}

/// Parse the text of an Abaqus matrix file (`path` is used in error messages only).
pub fn parse_abaqus(text: &str, path: &Path) -> Result<AbaqusMatrix, AbqError> {
    let perr = |line: usize, msg: String| AbqError::Parse {
        path: path.to_path_buf(),
        line,
        msg,
    };
    let mut labelled: Vec<(NodeDof, NodeDof, f64, usize)> = Vec::new();
    let mut coord: Vec<(usize, usize, f64, usize)> = Vec::new();
    let mut kind: Option<(usize, usize)> = None; // (field count, first line)
    for (i, line) in text.lines().enumerate() {
        let ln = i + 1;
        let t = line.trim();
        if t.is_empty() || t.starts_with("**") {
            continue;
        }
        if t.starts_with('*') {
            return Err(perr(
                ln,
                format!(
                    "keyword line '{t}': expected the data lines of a *MATRIX OUTPUT file \
                     (FORMAT=MATRIX INPUT: 'node, DOF, node, DOF, value'; FORMAT=COORDINATE: \
                     'row, column, value'); substructure and element-matrix files are not read"
                ),
            ));
        }
        let f: Vec<&str> = if t.contains(',') {
            t.split(',').map(str::trim).collect()
        } else {
            t.split_whitespace().collect()
        };
        // a trailing comma leaves an empty last field
        let f: Vec<&str> = match f.last() {
            Some(&"") => f[..f.len() - 1].to_vec(),
            _ => f,
        };
        match kind {
            None => {
                if f.len() != 5 && f.len() != 3 {
                    return Err(perr(
                        ln,
                        format!(
                            "expected 'node, DOF, node, DOF, value' (FORMAT=MATRIX INPUT) or \
                             'row, column, value' (FORMAT=COORDINATE), got '{t}' ({} fields)",
                            f.len()
                        ),
                    ));
                }
                kind = Some((f.len(), ln));
            }
            Some((n, first)) if n != f.len() => {
                return Err(perr(
                    ln,
                    format!(
                        "{} fields, but line {first} has {n}: one file holds one format",
                        f.len()
                    ),
                ))
            }
            _ => {}
        }
        let value_str = f[f.len() - 1];
        let v = value_str
            .replace(['D', 'd'], "E")
            .parse::<f64>()
            .map_err(|_| perr(ln, format!("value '{value_str}' is not a number")))?;
        if !v.is_finite() {
            return Err(perr(ln, format!("value '{value_str}' is not finite")));
        }
        if f.len() == 5 {
            let node = |s: &str| {
                NodeLabel::parse(s).ok_or_else(|| {
                    perr(
                        ln,
                        format!("node '{s}' is not a node label (an integer or instance.label)"),
                    )
                })
            };
            let dof = |s: &str| {
                s.parse::<u32>()
                    .ok()
                    .filter(|&d| d >= 1)
                    .ok_or_else(|| perr(ln, format!("DOF '{s}' is not a positive integer")))
            };
            labelled.push(((node(f[0])?, dof(f[1])?), (node(f[2])?, dof(f[3])?), v, ln));
        } else {
            let eq = |s: &str, what: &str| {
                s.parse::<usize>().ok().filter(|&e| e >= 1).ok_or_else(|| {
                    perr(
                        ln,
                        format!("{what} '{s}' is not a positive (1-based) equation number"),
                    )
                })
            };
            coord.push((eq(f[0], "row")? - 1, eq(f[1], "column")? - 1, v, ln));
        }
    }
    match kind {
        None => Err(perr(
            text.lines().count().max(1),
            "no matrix entries: the file is empty or holds only comments".into(),
        )),
        Some((5, _)) => Ok(AbaqusMatrix::Labelled(symmetrise(labelled, path, |k| {
            format!("node {} DOF {}", k.0, k.1)
        })?)),
        Some(_) => Ok(AbaqusMatrix::Coordinate(symmetrise(coord, path, |k| {
            format!("{}", k + 1)
        })?)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matrix_input_lower_triangle_is_mirrored() {
        let text = "** comment\n1,1, 1,1, 4.0\n2,2, 1,1, -1.5\nPart-1.3,1, Part-1.3,1, 2.0\n";
        let AbaqusMatrix::Labelled(e) = parse_abaqus(text, Path::new("a.mtx")).unwrap() else {
            panic!("not labelled")
        };
        assert_eq!(e.len(), 4);
        let n1 = NodeLabel::parse("1").unwrap();
        let n2 = NodeLabel::parse("2").unwrap();
        assert!(e.contains(&((n1.clone(), 1), (n2.clone(), 2), -1.5)));
        assert!(e.contains(&((n2, 2), (n1, 1), -1.5)));
        assert_eq!(NodeLabel::parse("Part-1.3").unwrap().instance, "Part-1");
    }

    #[test]
    fn errors_name_the_line() {
        let e = parse_abaqus("1,1,1,1,2.0\n1,1,1,1,3.0\n", Path::new("K.mtx"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("K.mtx, line 2") && e.contains("twice"), "{e}");
        let e = parse_abaqus("1 1 2.0\n2 1 1.0\n1 2 1.0\n3 1 5.0\n", Path::new("K.mtx"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("mixes"), "{e}");
        let e = parse_abaqus("*MATRIX,TYPE=STIFFNESS\n", Path::new("K.mtx"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 1") && e.contains("keyword"), "{e}");
        let e = parse_abaqus("1,1,1,1,x\n", Path::new("K.mtx"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 1") && e.contains("'x'"), "{e}");
        let e = parse_abaqus("1,1,1,1,1.0\n1 1 2.0\n", Path::new("K.mtx"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 2") && e.contains("one format"), "{e}");
    }
}
