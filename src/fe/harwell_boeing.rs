//! Harwell-Boeing sparse matrices (what ANSYS `HBMAT` writes and SciPy's
//! `scipy.io.hb_read` / `hb_write` read and write), and the ANSYS equation-mapping file that
//! goes with them.
//!
//! # The format (assembled real matrices)
//! A fixed-format text file, column-compressed, 1-based:
//!
//! ```text
//! line 1   TITLE (cols 1-72)  KEY (cols 73-80)
//! line 2   TOTCRD PTRCRD INDCRD VALCRD [RHSCRD]       line counts of the blocks below
//! line 3   MXTYPE NROW NCOL NNZERO [NELTVL]            MXTYPE e.g. RSA, RUA
//! line 4   PTRFMT INDFMT VALFMT [RHSFMT]              Fortran formats, e.g. (8I10) (3E25.16)
//! line 5   RHSTYP NRHS NRHSIX                         only when RHSCRD > 0
//! PTRCRD lines: NCOL+1 column pointers (first 1, last NNZERO+1)
//! INDCRD lines: NNZERO row indices
//! VALCRD lines: NNZERO values
//! RHSCRD lines: right-hand sides (ignored)
//! ```
//!
//! MXTYPE letter 1: `R` real (`P` pattern and `C` complex are rejected); letter 2: `U`
//! unsymmetric, `S` symmetric or `H` (real Hermitian = symmetric), one triangle stored and
//! mirrored here (`Z` skew and `R` rectangular are rejected); letter 3: `A` assembled (`E`
//! elemental is rejected). Fields are read by the column widths of the Fortran formats
//! (`(nIw)`, `(nEw.d)`, `(nDw.d)`, `(nFw.d)`, `(nGw.d)`, an optional leading `kP` scale factor,
//! which does not change values that carry an exponent), so adjacent fields without a blank
//! between them are read correctly; a line whose blank-separated fields are exactly the
//! expected count of valid numbers is read by blanks (SciPy's `hb_write` writes 24-character
//! values under an `E25.16` format). `D` exponents and the exponent-without-letter form
//! `1.5-300` are accepted.
//!
//! Units and DOF order are the writer's: the rows are the writer's equation numbers (ANSYS: the
//! solver's equation order, listed by the `.mapping` file). rfmlab does not rescale; see
//! [`crate::fe::foreign`] for unit systems.
//!
//! # ANSYS mapping file (`HBMAT,...,Mapping=YES` writes `Fname.mapping`)
//! One line per equation: the equation number, the node number and the DOF label (`UX`, `UY`,
//! `UZ`, `ROTX`, `ROTY`, `ROTZ`, ...). Lines whose first two fields are not integers (headers)
//! are skipped; labels other than the six above are kept as unaddressable DOFs.

use crate::fe::model::SpMat;
use faer::sparse::Triplet;
use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Errors of Harwell-Boeing and mapping-file reading.
#[derive(Debug, thiserror::Error)]
pub enum HbError {
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

/// A Fortran edit descriptor of one block: fields per line and field width.
#[derive(Clone, Copy, Debug, PartialEq)]
struct FieldFormat {
    per_line: usize,
    width: usize,
    integer: bool,
    /// `F` format with a nonzero scale factor: values without an exponent would be scaled.
    scaled_fixed: bool,
}

/// Parse `(8I10)`, `(1P,3E25.16)`, `(1P3D26.18)`, `(5F16.8)`, `(4G20.12)`, case-insensitive.
fn parse_format(s: &str) -> Option<FieldFormat> {
    let t: String = s
        .trim()
        .trim_start_matches('(')
        .trim_end_matches(')')
        .chars()
        .filter(|c| !c.is_whitespace())
        .collect::<String>()
        .to_ascii_uppercase();
    // optional scale factor kP (possibly followed by a comma)
    let (scale, rest) = match t.find('P') {
        Some(p) => {
            let k: i32 = t[..p].parse().ok()?;
            (k, t[p + 1..].trim_start_matches(','))
        }
        None => (0, t.as_str()),
    };
    let letter_pos = rest.find(|c: char| c.is_ascii_alphabetic())?;
    let per_line: usize = if letter_pos == 0 {
        1
    } else {
        rest[..letter_pos].parse().ok()?
    };
    let letter = rest.as_bytes()[letter_pos] as char;
    let after = &rest[letter_pos + 1..];
    let width_str = after.split('.').next()?;
    let width: usize = width_str.parse().ok()?;
    if per_line == 0 || width == 0 {
        return None;
    }
    match letter {
        'I' => Some(FieldFormat {
            per_line,
            width,
            integer: true,
            scaled_fixed: false,
        }),
        'E' | 'D' | 'G' | 'F' => Some(FieldFormat {
            per_line,
            width,
            integer: false,
            scaled_fixed: letter == 'F' && scale != 0,
        }),
        _ => None,
    }
}

/// A Fortran real field: `1.5E+03`, `1.5D+03`, `1.5+300` (exponent letter dropped), `-.5`.
fn parse_real(field: &str) -> Option<f64> {
    let t = field.trim().replace(['D', 'd'], "E");
    if let Ok(v) = t.parse::<f64>() {
        return Some(v);
    }
    // exponent without its letter: a sign after the mantissa
    let b = t.as_bytes();
    let pos = (1..b.len()).rev().find(|&i| {
        (b[i] == b'+' || b[i] == b'-') && (b[i - 1].is_ascii_digit() || b[i - 1] == b'.')
    })?;
    format!("{}E{}", &t[..pos], &t[pos..]).parse().ok()
}

/// Cut one line into its fixed-width fields (a short last line gives fewer fields).
fn fields(line: &str, f: FieldFormat) -> Vec<&str> {
    let mut out = Vec::with_capacity(f.per_line);
    let line = line.trim_end_matches(['\r', '\n']);
    for k in 0..f.per_line {
        let a = k * f.width;
        if a >= line.len() {
            break;
        }
        let b = (a + f.width).min(line.len());
        let s = line.get(a..b).unwrap_or("");
        if s.trim().is_empty() {
            // trailing blank fields end the line; interior blanks are read as missing values
            if line[a..].trim().is_empty() {
                break;
            }
        }
        out.push(s);
    }
    out
}

/// Read a Harwell-Boeing file.
pub fn read_hb(path: &Path) -> Result<SpMat, HbError> {
    let text = std::fs::read_to_string(path).map_err(|source| HbError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse_hb(&text, path)
}

/// Parse Harwell-Boeing text (`path` is used in error messages only).
pub fn parse_hb(text: &str, path: &Path) -> Result<SpMat, HbError> {
    let perr = |line: usize, msg: String| HbError::Parse {
        path: path.to_path_buf(),
        line,
        msg,
    };
    let lines: Vec<&str> = text.lines().collect();
    if lines.len() < 4 {
        return Err(perr(
            lines.len().max(1),
            "a Harwell-Boeing file has at least 4 header lines (title, line counts, type and \
             sizes, formats)"
                .into(),
        ));
    }
    // line 2: card counts
    let counts: Vec<usize> = lines[1]
        .split_whitespace()
        .map(|s| s.parse::<usize>())
        .collect::<Result<_, _>>()
        .map_err(|_| {
            perr(
                2,
                format!(
                    "expected the line counts 'TOTCRD PTRCRD INDCRD VALCRD [RHSCRD]', got '{}'",
                    lines[1].trim()
                ),
            )
        })?;
    if counts.len() < 4 {
        return Err(perr(
            2,
            format!(
                "expected at least 4 line counts 'TOTCRD PTRCRD INDCRD VALCRD', got '{}'",
                lines[1].trim()
            ),
        ));
    }
    let rhscrd = counts.get(4).copied().unwrap_or(0);
    // line 3: type and sizes
    let l3 = lines[2];
    let mxtype: String = l3.chars().take(3).collect::<String>().to_ascii_uppercase();
    let sizes: Vec<usize> = l3
        .get(3..)
        .unwrap_or("")
        .split_whitespace()
        .map(|s| s.parse::<usize>())
        .collect::<Result<_, _>>()
        .map_err(|_| {
            perr(
                3,
                format!(
                    "expected 'MXTYPE NROW NCOL NNZERO [NELTVL]', got '{}'",
                    l3.trim()
                ),
            )
        })?;
    if sizes.len() < 3 {
        return Err(perr(
            3,
            format!(
                "expected 'MXTYPE NROW NCOL NNZERO [NELTVL]', got '{}'",
                l3.trim()
            ),
        ));
    }
    let (nrow, ncol, nnz) = (sizes[0], sizes[1], sizes[2]);
    let t = mxtype.as_bytes();
    if t.len() != 3 {
        return Err(perr(
            3,
            format!("matrix type '{mxtype}' must have 3 letters (e.g. RSA, RUA)"),
        ));
    }
    match t[0] {
        b'R' => {}
        b'P' => {
            return Err(perr(
                3,
                format!("matrix type {mxtype}: a pattern-only file has no values; write the values (ANSYS HBMAT, SciPy hb_write do)"),
            ))
        }
        b'C' => return Err(perr(3, format!("matrix type {mxtype}: complex matrices are not supported (M, K and S are real)"))),
        _ => return Err(perr(3, format!("matrix type {mxtype}: the first letter must be R (real)"))),
    }
    let symmetric = match t[1] {
        b'S' | b'H' => true,
        b'U' => false,
        _ => {
            return Err(perr(
                3,
                format!(
                    "matrix type {mxtype}: only symmetric (S) and unsymmetric (U) square matrices \
                     are supported"
                ),
            ))
        }
    };
    if t[2] != b'A' {
        return Err(perr(
            3,
            format!(
                "matrix type {mxtype}: only assembled matrices (third letter A) are supported, \
                 not elemental ones"
            ),
        ));
    }
    if nrow != ncol {
        return Err(perr(
            3,
            format!("the matrix is {nrow}x{ncol}: M, K and S must be square"),
        ));
    }
    // line 4: formats
    let l4 = lines[3];
    let groups: Vec<&str> = l4
        .split('(')
        .skip(1)
        .filter_map(|g| g.split(')').next())
        .collect();
    if groups.len() < 3 {
        return Err(perr(
            4,
            format!(
                "expected the Fortran formats 'PTRFMT INDFMT VALFMT', e.g. '(8I10) (8I10) \
                 (3E25.16)', got '{}'",
                l4.trim()
            ),
        ));
    }
    let fmt = |k: usize, what: &str, integer: bool| -> Result<FieldFormat, HbError> {
        let f = parse_format(groups[k]).ok_or_else(|| {
            perr(
                4,
                format!(
                    "{what} format '({})' is not a Fortran format such as (8I10) or (3E25.16)",
                    groups[k]
                ),
            )
        })?;
        if f.integer != integer {
            return Err(perr(
                4,
                format!(
                    "{what} format '({})' must be {}",
                    groups[k],
                    if integer {
                        "an integer format (nIw)"
                    } else {
                        "a real format (nEw.d, nDw.d, nFw.d)"
                    }
                ),
            ));
        }
        if f.scaled_fixed {
            return Err(perr(
                4,
                format!(
                    "{what} format '({})': a scale factor with F fields is not supported",
                    groups[k]
                ),
            ));
        }
        Ok(f)
    };
    let ptrfmt = fmt(0, "pointer", true)?;
    let indfmt = fmt(1, "row-index", true)?;
    let valfmt = fmt(2, "value", false)?;
    let mut at = 4 + usize::from(rhscrd > 0);

    // Read `count` fields of format f starting at line index `at`; returns (value, line number).
    let mut read_block =
        |count: usize, f: FieldFormat, what: &str| -> Result<Vec<(String, usize)>, HbError> {
            let mut out = Vec::with_capacity(count);
            while out.len() < count {
                let Some(line) = lines.get(at) else {
                    return Err(perr(
                        lines.len(),
                        format!("the file ends after {} of the {count} {what}", out.len()),
                    ));
                };
                // Blank-separated fields are read as such (SciPy's hb_write writes 24-character
                // values under an E25.16 format); fields that run together are cut by width.
                let want = f.per_line.min(count - out.len());
                let tokens: Vec<&str> = line.split_whitespace().collect();
                let separated = tokens.len() == want
                    && tokens.iter().all(|t| {
                        if f.integer {
                            t.parse::<usize>().is_ok()
                        } else {
                            parse_real(t).is_some()
                        }
                    });
                let cut = if separated { tokens } else { fields(line, f) };
                for s in cut {
                    if out.len() < count {
                        out.push((s.trim().to_string(), at + 1));
                    }
                }
                at += 1;
            }
            Ok(out)
        };
    let ptr_raw = read_block(ncol + 1, ptrfmt, "column pointers")?;
    let ind_raw = read_block(nnz, indfmt, "row indices")?;
    let val_raw = read_block(nnz, valfmt, "values")?;

    let int = |(s, ln): &(String, usize), what: &str| -> Result<usize, HbError> {
        s.parse::<usize>()
            .map_err(|_| perr(*ln, format!("{what} '{s}' is not a non-negative integer")))
    };
    let mut ptr = Vec::with_capacity(ncol + 1);
    for p in &ptr_raw {
        ptr.push(int(p, "column pointer")?);
    }
    if ptr[0] != 1 {
        return Err(perr(
            ptr_raw[0].1,
            format!("the first column pointer is {}, expected 1", ptr[0]),
        ));
    }
    for k in 1..ptr.len() {
        if ptr[k] < ptr[k - 1] {
            return Err(perr(
                ptr_raw[k].1,
                format!(
                    "column pointer {} ({}) is smaller than the one before ({})",
                    k + 1,
                    ptr[k],
                    ptr[k - 1]
                ),
            ));
        }
    }
    if ptr[ncol] != nnz + 1 {
        return Err(perr(
            ptr_raw[ncol].1,
            format!(
                "the last column pointer is {}, expected NNZERO + 1 = {}",
                ptr[ncol],
                nnz + 1
            ),
        ));
    }
    let mut triplets: Vec<Triplet<usize, usize, f64>> =
        Vec::with_capacity(if symmetric { 2 * nnz } else { nnz });
    // for symmetric files: which unordered pairs were seen (to refuse both triangles)
    let mut seen: HashMap<(usize, usize), usize> = HashMap::new();
    for j in 0..ncol {
        for k in ptr[j] - 1..ptr[j + 1] - 1 {
            let i = int(&ind_raw[k], "row index")?;
            let ln = ind_raw[k].1;
            if i == 0 || i > nrow {
                return Err(perr(
                    ln,
                    format!("row index {i} outside 1..={nrow} (column {})", j + 1),
                ));
            }
            let (vs, vln) = &val_raw[k];
            let v = parse_real(vs)
                .ok_or_else(|| perr(*vln, format!("value '{vs}' is not a number")))?;
            if !v.is_finite() {
                return Err(perr(*vln, format!("value '{vs}' is not finite")));
            }
            let r = i - 1;
            triplets.push(Triplet::new(r, j, v));
            if symmetric && r != j {
                let key = (r.min(j), r.max(j));
                if let Some(prev) = seen.insert(key, ln) {
                    return Err(perr(
                        ln,
                        format!(
                            "entry ({}, {}) of a symmetric ({mxtype}) file is stored twice (also \
                             on line {prev}): store one triangle only",
                            r + 1,
                            j + 1
                        ),
                    ));
                }
                triplets.push(Triplet::new(j, r, v));
            }
        }
    }
    SpMat::try_new_from_triplets(nrow, ncol, &triplets).map_err(|e| {
        perr(
            3,
            format!("cannot build the {nrow}x{ncol} sparse matrix: {e:?}"),
        )
    })
}

/// Harwell-Boeing text of `a`: `RSA` (lower triangle) when exactly symmetric, else `RUA`;
/// values with 17 significant digits, so a write-read round trip is exact.
pub fn format_hb(a: &SpMat, title: &str, key: &str) -> String {
    let sym = a.nrows() == a.ncols() && crate::linalg::asymmetry(a) == 0.0;
    let n = a.ncols();
    // columns: (row, value), duplicates summed, sorted
    let mut cols: Vec<std::collections::BTreeMap<usize, f64>> = vec![Default::default(); n];
    for t in a.triplet_iter() {
        if !sym || t.row >= t.col {
            *cols[t.col].entry(t.row).or_insert(0.0) += *t.val;
        }
    }
    let nnz: usize = cols.iter().map(|c| c.len()).sum();
    let iw = format!("{}", nnz + 1)
        .len()
        .max(format!("{}", a.nrows()).len())
        + 1;
    let per_int = (80 / iw).max(1);
    let (per_val, vw) = (3usize, 26usize);
    let lines_for = |count: usize, per: usize| count.div_ceil(per);
    let ptrcrd = lines_for(n + 1, per_int);
    let indcrd = lines_for(nnz, per_int);
    let valcrd = lines_for(nnz, per_val);
    let mut s = String::new();
    let title: String = title.chars().take(72).collect();
    let key: String = key.chars().take(8).collect();
    let _ = writeln!(s, "{title:<72}{key:<8}");
    let _ = writeln!(
        s,
        "{:>14}{:>14}{:>14}{:>14}{:>14}",
        ptrcrd + indcrd + valcrd,
        ptrcrd,
        indcrd,
        valcrd,
        0
    );
    let _ = writeln!(
        s,
        "{:<3}{:>11}{:>14}{:>14}{:>14}{:>14}",
        if sym { "RSA" } else { "RUA" },
        "",
        a.nrows(),
        n,
        nnz,
        0
    );
    let ifmt = format!("({per_int}I{iw})");
    let _ = writeln!(s, "{ifmt:<16}{ifmt:<16}{:<20}{:<20}", "(3E26.17)", "");
    let write_ints = |s: &mut String, v: &[usize]| {
        for chunk in v.chunks(per_int) {
            for x in chunk {
                let _ = write!(s, "{x:>iw$}");
            }
            s.push('\n');
        }
    };
    let mut ptr = Vec::with_capacity(n + 1);
    let mut p = 1usize;
    ptr.push(p);
    for c in &cols {
        p += c.len();
        ptr.push(p);
    }
    write_ints(&mut s, &ptr);
    let rows: Vec<usize> = cols.iter().flat_map(|c| c.keys().map(|r| r + 1)).collect();
    write_ints(&mut s, &rows);
    let vals: Vec<f64> = cols.iter().flat_map(|c| c.values().copied()).collect();
    for chunk in vals.chunks(per_val) {
        for v in chunk {
            let _ = write!(s, "{:>vw$}", format!("{v:.17E}"));
        }
        s.push('\n');
    }
    s
}

/// Abaqus/ANSYS DOF number of an ANSYS DOF label (UX 1, UY 2, UZ 3, ROTX 4, ROTY 5, ROTZ 6);
/// 0 for other labels.
pub fn ansys_dof_code(label: &str) -> u32 {
    match label.to_ascii_uppercase().as_str() {
        "UX" => 1,
        "UY" => 2,
        "UZ" => 3,
        "ROTX" => 4,
        "ROTY" => 5,
        "ROTZ" => 6,
        _ => 0,
    }
}

/// One equation of an ANSYS mapping file: (1-based equation, node number, DOF code 1..6 or 0).
pub type MappingRow = (usize, i64, u32);

/// Read an ANSYS equation-mapping file (see the module docs).
pub fn read_ansys_mapping(path: &Path) -> Result<Vec<MappingRow>, HbError> {
    let text = std::fs::read_to_string(path).map_err(|source| HbError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse_ansys_mapping(&text, path)
}

/// Parse the text of an ANSYS equation-mapping file.
pub fn parse_ansys_mapping(text: &str, path: &Path) -> Result<Vec<MappingRow>, HbError> {
    let perr = |line: usize, msg: String| HbError::Parse {
        path: path.to_path_buf(),
        line,
        msg,
    };
    let mut rows = Vec::new();
    let mut seen: HashMap<usize, usize> = HashMap::new();
    for (i, line) in text.lines().enumerate() {
        let f: Vec<&str> = line
            .split(|c: char| c.is_whitespace() || c == ',')
            .filter(|s| !s.is_empty())
            .collect();
        let (Some(eq), Some(node)) = (
            f.first().and_then(|s| s.parse::<usize>().ok()),
            f.get(1).and_then(|s| s.parse::<i64>().ok()),
        ) else {
            continue;
        };
        let Some(label) = f.get(2) else {
            return Err(perr(
                i + 1,
                format!(
                    "expected 'equation node DOF-label' (e.g. '12  5  UY'), got '{}'",
                    line.trim()
                ),
            ));
        };
        if eq == 0 {
            return Err(perr(i + 1, "equation numbers start at 1".into()));
        }
        if let Some(prev) = seen.insert(eq, i + 1) {
            return Err(perr(
                i + 1,
                format!("equation {eq} is listed twice (also on line {prev})"),
            ));
        }
        rows.push((eq, node, ansys_dof_code(label)));
    }
    if rows.is_empty() {
        return Err(perr(
            1,
            "no 'equation node DOF-label' lines found: is this the HBMAT mapping file?".into(),
        ));
    }
    Ok(rows)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn formats_and_reals() {
        let f = parse_format("(8I10)").unwrap();
        assert_eq!((f.per_line, f.width, f.integer), (8, 10, true));
        let f = parse_format("(1P,3E25.16)").unwrap();
        assert_eq!((f.per_line, f.width, f.integer), (3, 25, false));
        let f = parse_format("(1P4D20.12)").unwrap();
        assert_eq!((f.per_line, f.width), (4, 20));
        assert!(parse_format("(8A10)").is_none());
        assert_eq!(parse_real("1.5D+03"), Some(1500.0));
        assert_eq!(parse_real(" 1.5-300"), Some(1.5e-300));
        assert_eq!(parse_real("-.25E1"), Some(-2.5));
        assert_eq!(parse_real("abc"), None);
    }

    #[test]
    fn adjacent_integer_fields() {
        // row indices 10 and 11 written as "1011" by (2I2): no blank between the fields
        let text = "t\n 3 1 1 1 0\nRUA 11 11 2 0\n(12I1) (2I2) (2E10.3)\n111111111123\n1011\n 1.000E+00 2.000E+00\n";
        let a = parse_hb(text, Path::new("x.hb")).unwrap();
        let d = crate::fe::synthetic::to_dense(&a);
        assert_eq!((d[(9, 9)], d[(10, 10)], d[(0, 0)]), (1.0, 2.0, 0.0));
        // a file that ends early names the block and the line
        let text = "t\n 3 1 1 1 0\nRUA 11 11 2 0\n(12I1) (2I2) (2E10.3)\n111111111123\n1011\n";
        let e = parse_hb(text, Path::new("x.hb")).unwrap_err().to_string();
        assert!(e.contains("x.hb, line 6") && e.contains("values"), "{e}");
    }
}
