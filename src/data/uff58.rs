//! Universal File Format dataset 58 ("function at nodal DOF"), ASCII and binary (58b):
//! the raw layer. Reads every dataset 58 of a file with all its header records, the unit
//! factors of dataset 164, and skips (with a note) every other dataset.
//!
//! Format (SDRC / UC-SDRL spec, restated in `shared/data/README.md` §2-3):
//! records 1-5 ID lines; record 6 DOF identification `2(I5,I10),2(1X,10A1,I10,I4)`;
//! record 7 data form `3I10,3E13.5`; records 8-11 axis characteristics `I10,3I5,2(1X,20A1)`;
//! record 12 the values in one of eight layouts (real/complex x single/double x even/uneven).
//! Even abscissa: `x_k = x0 + k dx`, k = 0..num_pts-1.
//!
//! Quirks of real files handled here: numbers glued without blanks (fixed-width column
//! slicing), 2- or 3-digit and `D` exponents, header fields shifted by a column
//! (whitespace tokens first for numeric-only records), zero-padded or short last data line
//! (exactly `num_pts` points are kept; extra values give a note, missing values an error),
//! CRLF line ends, Latin-1 or UTF-8 labels, 58b id lines without the trailing zero fields,
//! wrong 58b byte counts (the byte count is taken from the layout, see [`parse_uff`]).
//!
//! Deliberately unsupported (skipped with a note in [`UffFile::skipped`]): every dataset
//! other than 58/58b and 164 (15, 18, 55, 82, 151, 1858, 2411, 2412, 2414, ... carry no
//! functions); 58b files whose floating-point format is not IEEE 754 (DEC VMS, IBM 370:
//! none exist in the test corpus) are an error.

use std::path::Path;

use crate::common::C64;
use crate::data::DataError;

/// Precision of the stored ordinate values.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub enum Precision {
    Single,
    Double,
}

/// Ordinate values of a dataset 58.
#[derive(Clone, Debug, PartialEq)]
pub enum Ordinate {
    Real(Vec<f64>),
    Complex(Vec<C64>),
}

impl Ordinate {
    pub fn len(&self) -> usize {
        match self {
            Ordinate::Real(v) => v.len(),
            Ordinate::Complex(v) => v.len(),
        }
    }
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    pub fn is_complex(&self) -> bool {
        matches!(self, Ordinate::Complex(_))
    }
    /// The values as complex numbers (a real ordinate with zero imaginary parts).
    pub fn to_complex(&self) -> Vec<C64> {
        match self {
            Ordinate::Real(v) => v.iter().map(|&x| C64::new(x, 0.0)).collect(),
            Ordinate::Complex(v) => v.clone(),
        }
    }
}

/// One of the axis records 8-11: specific data type, unit exponents, labels.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct AxisSpec {
    /// Specific data type (0 unknown, 1 general, 8 displacement, 11 velocity,
    /// 12 acceleration, 13 excitation force, 17 time, 18 frequency, ...).
    pub spec_type: i32,
    pub length_exp: i32,
    pub force_exp: i32,
    pub temperature_exp: i32,
    pub axis_label: String,
    pub units_label: String,
}

impl AxisSpec {
    /// A record with the given type and labels, exponents 0.
    pub fn new(spec_type: i32, axis_label: &str, units_label: &str) -> Self {
        AxisSpec {
            spec_type,
            axis_label: axis_label.to_string(),
            units_label: units_label.to_string(),
            ..Default::default()
        }
    }
}

/// One dataset 58 with all its header records and values.
#[derive(Clone, Debug, PartialEq)]
pub struct Uff58Dataset {
    /// Records 1-5 (ID lines 1..5), trimmed of trailing blanks.
    pub ids: [String; 5],
    /// Record 6: function type (4 FRF, 6 coherence, 1 time response, 9 PSD, ...).
    pub func_type: i32,
    pub func_id: i64,
    pub version: i64,
    pub load_case: i64,
    pub rsp_entity: String,
    pub rsp_node: i64,
    /// UFF direction code: 0 scalar, +-1..+-3 translations, +-4..+-6 rotations.
    pub rsp_dir: i32,
    pub ref_entity: String,
    pub ref_node: i64,
    pub ref_dir: i32,
    /// Record 7: ordinate data type as stored (2 real single, 4 real double, 5 complex single, 6 complex double).
    pub ord_data_type: i32,
    /// Number of points (a complex value counts as one).
    pub num_pts: usize,
    /// Even abscissa spacing (record 7 field 3 = 1).
    pub even: bool,
    /// First abscissa value and increment (even spacing; 0 when uneven).
    pub x0: f64,
    pub dx: f64,
    /// Z-axis value.
    pub z: f64,
    /// Records 8, 9, 10, 11: abscissa, ordinate numerator, ordinate denominator, z axis.
    pub abscissa: AxisSpec,
    pub ordinate: AxisSpec,
    pub denominator: AxisSpec,
    pub z_axis: AxisSpec,
    /// Abscissa values (even: `x0 + k dx`).
    pub x: Vec<f64>,
    pub values: Ordinate,
    pub precision: Precision,
    /// Stored as 58b.
    pub binary: bool,
    /// 0-based index of the dataset among all datasets of the file.
    pub index: usize,
    /// 1-based line number of the dataset's opening `-1`.
    pub line: usize,
    /// Warnings found while reading (kept values, byte counts, ...).
    pub notes: Vec<String>,
}

impl Uff58Dataset {
    /// A dataset with default headers (`NONE` labels, spec types 0) for the given values on an
    /// even grid `x0 + k dx` (`x` filled), double precision.
    pub fn new_even(func_type: i32, x0: f64, dx: f64, values: Ordinate) -> Self {
        let n = values.len();
        let x = (0..n).map(|k| x0 + k as f64 * dx).collect();
        Uff58Dataset {
            ids: [
                "NONE".into(),
                "NONE".into(),
                "NONE".into(),
                "NONE".into(),
                "NONE".into(),
            ],
            func_type,
            func_id: 0,
            version: 0,
            load_case: 0,
            rsp_entity: "NONE".into(),
            rsp_node: 0,
            rsp_dir: 0,
            ref_entity: "NONE".into(),
            ref_node: 0,
            ref_dir: 0,
            ord_data_type: if values.is_complex() { 6 } else { 4 },
            num_pts: n,
            even: true,
            x0,
            dx,
            z: 0.0,
            abscissa: AxisSpec::new(18, "Frequency", "Hz"),
            ordinate: AxisSpec::new(0, "NONE", "NONE"),
            denominator: AxisSpec::new(0, "NONE", "NONE"),
            z_axis: AxisSpec::new(0, "NONE", "NONE"),
            x,
            values,
            precision: Precision::Double,
            binary: false,
            index: 0,
            line: 0,
            notes: Vec::new(),
        }
    }

    /// Same as [`Uff58Dataset::new_even`] with explicit (uneven) abscissa values.
    pub fn new_uneven(func_type: i32, x: Vec<f64>, values: Ordinate) -> Self {
        let mut d = Self::new_even(func_type, 0.0, 0.0, values);
        d.x = x;
        d.even = false;
        d
    }
}

/// Unit factors of a dataset 164: divide a file value by `length^l force^f` to get SI.
#[derive(Clone, Debug, PartialEq)]
pub struct UnitFactors {
    /// 0-based index of the dataset 164 in the file.
    pub index: usize,
    /// 1 SI, 2 BG, 3 MG, 4 BA, 5 MM, 6 CM, 7 IN, 8 GM, 9 user.
    pub code: i32,
    pub description: String,
    pub temperature_mode: i32,
    pub length: f64,
    pub force: f64,
    pub temperature: f64,
    pub temperature_offset: f64,
}

/// A dataset the reader did not load.
#[derive(Clone, Debug, PartialEq)]
pub struct SkippedDataset {
    pub number: i64,
    pub index: usize,
    pub line: usize,
    pub reason: String,
}

/// The contents of a UFF file relevant to rfmlab.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct UffFile {
    /// The path or label the file was read from (used in error messages).
    pub label: String,
    pub datasets: Vec<Uff58Dataset>,
    /// Unit factors of the (first) dataset 164, if any.
    pub units: Option<UnitFactors>,
    pub skipped: Vec<SkippedDataset>,
}

/// Read a UFF file. See [`parse_uff`].
pub fn read_uff(path: impl AsRef<Path>) -> Result<UffFile, DataError> {
    let path = path.as_ref();
    let label = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|e| {
        DataError::at(
            &label,
            None,
            None,
            format!("cannot read the file: {e}; check the path"),
        )
    })?;
    let f = parse_uff(&bytes, &label)?;
    if f.datasets.is_empty() && f.skipped.is_empty() && f.units.is_none() {
        return Err(DataError::at(&label, None, None, not_uff_reason(&bytes)));
    }
    Ok(f)
}

/// Why bytes without any UFF dataset are not a UFF file: empty, binary or other text.
pub(crate) fn not_uff_reason(bytes: &[u8]) -> String {
    let fix = "give a UFF58 file (datasets between lines holding \"-1\") or a CSV file with the extension .csv";
    if bytes.iter().all(|b| b.is_ascii_whitespace()) {
        return format!("the file is empty: {fix}");
    }
    let head = &bytes[..bytes.len().min(4096)];
    let binary = head.contains(&0)
        || head
            .iter()
            .filter(|&&b| b < 0x09 || (b > 0x0d && b < 0x20))
            .count()
            * 20
            > head.len();
    if binary {
        format!("this is a binary file, not a UFF text file: {fix}")
    } else {
        format!("this text holds no UFF dataset (no line with \"-1\" opening a dataset): {fix}")
    }
}

// ---------------------------------------------------------------------------------------
// low-level helpers

/// Decode header text: UTF-8 when valid, else Latin-1.
pub(crate) fn decode_text(b: &[u8]) -> String {
    match std::str::from_utf8(b) {
        Ok(s) => s.to_string(),
        Err(_) => b.iter().map(|&c| c as char).collect(),
    }
}

fn trim_bytes(b: &[u8]) -> &[u8] {
    let s = b
        .iter()
        .position(|c| !c.is_ascii_whitespace())
        .unwrap_or(b.len());
    let e = b
        .iter()
        .rposition(|c| !c.is_ascii_whitespace())
        .map_or(s, |p| p + 1);
    &b[s..e.max(s)]
}

/// Columns `start..start+width` (0-based) of a line, empty when past its end.
fn cols(line: &[u8], start: usize, width: usize) -> &[u8] {
    if start >= line.len() {
        return &[];
    }
    &line[start..(start + width).min(line.len())]
}

/// Parse a Fortran integer field; blank -> 0.
fn parse_int(b: &[u8]) -> Option<i64> {
    let t = trim_bytes(b);
    if t.is_empty() {
        return Some(0);
    }
    std::str::from_utf8(t).ok()?.parse().ok()
}

/// Parse a Fortran real: `E` or `D` exponent, any number of exponent digits, and the
/// exponent-letter-free form `1.234-105`. Blank -> None.
pub(crate) fn parse_fortran_f64(b: &[u8]) -> Option<f64> {
    let t = trim_bytes(b);
    if t.is_empty() || t.len() > 64 {
        return None;
    }
    let mut s: Vec<u8> = t
        .iter()
        .map(|&c| if c == b'D' || c == b'd' { b'E' } else { c })
        .collect();
    if !s.iter().any(|&c| c == b'E' || c == b'e') {
        // 1.234-105 -> 1.234E-105
        if let Some(p) = (1..s.len())
            .rev()
            .find(|&i| (s[i] == b'-' || s[i] == b'+') && s[i - 1].is_ascii_digit())
        {
            s.insert(p, b'E');
        }
    }
    let st = std::str::from_utf8(&s).ok()?;
    // Reject words Rust would accept (inf, nan) only when they are not numeric-looking.
    if !st
        .bytes()
        .all(|c| c.is_ascii_digit() || matches!(c, b'+' | b'-' | b'.' | b'E' | b'e'))
    {
        return None;
    }
    st.parse().ok()
}

fn parse_header_f64(b: &[u8]) -> Option<f64> {
    if trim_bytes(b).is_empty() {
        Some(0.0)
    } else {
        parse_fortran_f64(b)
    }
}

fn tokens(line: &[u8]) -> Vec<&[u8]> {
    line.split(|c| c.is_ascii_whitespace())
        .filter(|t| !t.is_empty())
        .collect()
}

/// A delimiter line: `-1` alone (any surrounding blanks).
fn is_delim(line: &[u8]) -> bool {
    trim_bytes(line) == b"-1"
}

/// A forward line reader over bytes that counts 1-based line numbers.
struct Cursor<'a> {
    b: &'a [u8],
    pos: usize,
    /// Number of the line that the last `next_line` returned.
    line: usize,
}

impl<'a> Cursor<'a> {
    fn next_line(&mut self) -> Option<&'a [u8]> {
        if self.pos >= self.b.len() {
            return None;
        }
        let rest = &self.b[self.pos..];
        let (content, adv) = match rest.iter().position(|&c| c == b'\n') {
            Some(p) => (&rest[..p], p + 1),
            None => (rest, rest.len()),
        };
        self.pos += adv;
        self.line += 1;
        let content = content.strip_suffix(b"\r").unwrap_or(content);
        Some(content)
    }
}

// ---------------------------------------------------------------------------------------
// reader

/// Parse the bytes of a UFF file. `file_label` names the file in errors.
///
/// Datasets are delimited by `-1` lines; the dataset number is in columns 1-6 of the line after
/// the opening delimiter (`b` in column 7 marks 58b). For 58b the binary block directly follows
/// the 11th header record; its length is taken from the layout,
/// `num_pts (v ord_size + (uneven ? 4 : 0))` (v = 1 real, 2 complex; uneven abscissa float32 as
/// the spec says), when a `-1` line follows it; else the writer stored the abscissa in the
/// ordinate precision (pyuff does that for doubles), else the header's byte count; a mismatch
/// with the header's byte count is noted. Never panics; a malformed dataset 58 is an error
/// naming the file, the dataset index and the line.
pub fn parse_uff(bytes: &[u8], file_label: &str) -> Result<UffFile, DataError> {
    // a UTF-8 byte-order mark (Windows editors) would hide the first delimiter, and with it
    // the first dataset
    let bytes: &[u8] = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
    let mut out = UffFile {
        label: file_label.to_string(),
        ..Default::default()
    };
    let mut cur = Cursor {
        b: bytes,
        pos: 0,
        line: 0,
    };
    let mut index = 0usize;
    let mut carried_delim: Option<usize> = None;
    loop {
        let open_line = match carried_delim.take() {
            Some(l) => l,
            None => {
                // find the next delimiter
                let mut found = None;
                while let Some(l) = cur.next_line() {
                    if is_delim(l) {
                        found = Some(cur.line);
                        break;
                    }
                }
                match found {
                    Some(l) => l,
                    None => break,
                }
            }
        };
        let Some(id_line) = cur.next_line() else {
            break;
        };
        if is_delim(id_line) {
            // consecutive delimiters: treat the second as the opening one
            carried_delim = Some(cur.line);
            continue;
        }
        if trim_bytes(id_line).is_empty() {
            continue;
        }
        let id_tok = trim_bytes(cols(id_line, 0, 6));
        let number = parse_int(id_tok).filter(|_| !id_tok.is_empty());
        let binary = id_line
            .get(6)
            .is_some_and(|c| c.eq_ignore_ascii_case(&b'b'));
        let number = match number {
            Some(n) => n,
            None => {
                // maybe a left-justified id such as "58b"
                let t = tokens(id_line);
                let first = t.first().copied().unwrap_or(&[]);
                let digits: Vec<u8> = first
                    .iter()
                    .copied()
                    .take_while(|c| c.is_ascii_digit())
                    .collect();
                match parse_int(&digits).filter(|_| !digits.is_empty()) {
                    Some(n) => n,
                    None => {
                        return Err(DataError::at(
                            file_label,
                            Some(index),
                            Some(cur.line),
                            format!(
                                "expected a dataset number after the '-1' delimiter, found {:?}; the file is not a valid UFF file",
                                decode_text(cols(id_line, 0, 40))
                            ),
                        ))
                    }
                }
            }
        };
        match number {
            58 => {
                let ds = parse_58(&mut cur, id_line, binary, file_label, index, open_line)?;
                out.datasets.push(ds);
            }
            164 => {
                let (mut u, closed) = parse_164(&mut cur);
                if let Some(u) = u.as_mut() {
                    u.index = index;
                }
                match u {
                    Some(u) if out.units.is_none() => out.units = Some(u),
                    Some(_) => out.skipped.push(SkippedDataset {
                        number,
                        index,
                        line: open_line,
                        reason: "second dataset 164 ignored (the first one sets the units)".into(),
                    }),
                    None => out.skipped.push(SkippedDataset {
                        number,
                        index,
                        line: open_line,
                        reason: "dataset 164 unreadable; units assumed SI".into(),
                    }),
                }
                if !closed {
                    break;
                }
            }
            _ => {
                let mut closed = false;
                while let Some(l) = cur.next_line() {
                    if is_delim(l) {
                        closed = true;
                        break;
                    }
                }
                out.skipped.push(SkippedDataset {
                    number,
                    index,
                    line: open_line,
                    reason: format!(
                        "dataset {number} carries no functions (only 58 and 164 are read)"
                    ),
                });
                if !closed {
                    break;
                }
            }
        }
        index += 1;
    }
    Ok(out)
}

/// Dataset 164: R1 `I10,20A1,I10`, then four reals (length, force, temperature, offset).
/// Consumes through the closing delimiter; returns (units, closed).
fn parse_164(cur: &mut Cursor) -> (Option<UnitFactors>, bool) {
    let mut lines = Vec::new();
    let mut closed = false;
    while let Some(l) = cur.next_line() {
        if is_delim(l) {
            closed = true;
            break;
        }
        lines.push(l);
    }
    let Some(r1) = lines.first() else {
        return (None, closed);
    };
    let code = parse_int(cols(r1, 0, 10)).unwrap_or(0) as i32;
    let description = decode_text(trim_bytes(cols(r1, 10, 20)));
    let temperature_mode = parse_int(cols(r1, 30, 10)).unwrap_or(0) as i32;
    let vals: Vec<f64> = lines[1..]
        .iter()
        .flat_map(|l| tokens(l))
        .filter_map(parse_fortran_f64)
        .collect();
    if vals.len() < 3 || vals[..3].iter().any(|v| !v.is_finite() || *v <= 0.0) {
        return (None, closed);
    }
    let u = UnitFactors {
        index: 0,
        code,
        description,
        temperature_mode,
        length: vals[0],
        force: vals[1],
        temperature: vals[2],
        temperature_offset: vals.get(3).copied().unwrap_or(0.0),
    };
    (Some(u), closed)
}

fn parse_axis(l: &[u8]) -> Option<AxisSpec> {
    let widths = [(0, 10), (10, 5), (15, 5), (20, 5)];
    let mut ints = [0i64; 4];
    let mut ok = true;
    for (k, (s, w)) in widths.iter().enumerate() {
        match parse_int(cols(l, *s, *w)) {
            Some(v) => ints[k] = v,
            None => ok = false,
        }
    }
    if !ok {
        let t = tokens(l);
        if t.len() < 4 {
            return None;
        }
        for (dst, tok) in ints.iter_mut().zip(&t) {
            *dst = parse_int(tok)?;
        }
    }
    Some(AxisSpec {
        spec_type: ints[0] as i32,
        length_exp: ints[1] as i32,
        force_exp: ints[2] as i32,
        temperature_exp: ints[3] as i32,
        axis_label: decode_text(trim_bytes(cols(l, 25, 21))),
        units_label: decode_text(trim_bytes(cols(l, 46, 21))),
    })
}

/// Values per point and the fixed widths of one ASCII data line for a layout.
fn layout(ord_type: i32, even: bool) -> (usize, &'static [usize]) {
    match (ord_type, even) {
        (2, true) => (1, &[13; 6]),
        (2, false) => (2, &[13; 6]),
        (5, true) => (2, &[13; 6]),
        (5, false) => (3, &[13; 6]),
        (4, true) => (1, &[20; 4]),
        (4, false) => (2, &[13, 20, 13, 20]),
        (6, true) => (2, &[20; 4]),
        _ => (3, &[13, 20, 20]),
    }
}

/// Parse one ASCII data line: whitespace tokens when they all parse, else fixed-width columns
/// (fields glued together).
fn parse_data_line(l: &[u8], widths: &[usize], out: &mut Vec<f64>) -> bool {
    let t = tokens(l);
    if t.is_empty() {
        return true;
    }
    let parsed: Vec<Option<f64>> = t.iter().map(|x| parse_fortran_f64(x)).collect();
    if parsed.iter().all(|v| v.is_some()) {
        out.extend(parsed.into_iter().flatten());
        return true;
    }
    let mut vals = Vec::new();
    let mut s = 0;
    let mut k = 0;
    while s < l.len() {
        let w = widths[k % widths.len()];
        let f = cols(l, s, w);
        if trim_bytes(f).is_empty() {
            break;
        }
        match parse_fortran_f64(f) {
            Some(v) => vals.push(v),
            None => return false,
        }
        s += w;
        k += 1;
    }
    if s < l.len() && !trim_bytes(&l[s..]).is_empty() {
        return false;
    }
    out.extend(vals);
    true
}

fn parse_58(
    cur: &mut Cursor,
    id_line: &[u8],
    binary: bool,
    file: &str,
    index: usize,
    open_line: usize,
) -> Result<Uff58Dataset, DataError> {
    let err = |line: usize, msg: String| DataError::at(file, Some(index), Some(line), msg);
    let mut notes = Vec::new();
    // 58b id line: byte order, fp format, n ascii lines, n bytes (trailing fields optional)
    let mut byte_order = 1i64;
    let mut n_bytes_hdr: Option<usize> = None;
    if binary {
        let rest = id_line.get(7..).unwrap_or(&[]);
        let t = tokens(rest);
        let f: Vec<Option<i64>> = t.iter().map(|x| parse_int(x)).collect();
        if f.len() < 4 || f[..4].iter().any(|v| v.is_none()) {
            return Err(err(cur.line, "58b identifier line lacks byte order, float format, line count or byte count; the header is damaged".into()));
        }
        byte_order = f[0].unwrap_or(1);
        let fp = f[1].unwrap_or(2);
        if fp != 2 {
            return Err(err(cur.line, format!("58b floating-point format {fp} is not IEEE 754 (2); convert the file to IEEE or ASCII")));
        }
        if byte_order != 1 && byte_order != 2 {
            return Err(err(
                cur.line,
                format!(
                    "58b byte order {byte_order} is neither 1 (little endian) nor 2 (big endian)"
                ),
            ));
        }
        if f[2] != Some(11) {
            notes.push(format!(
                "58b header says {} ASCII lines (expected 11)",
                f[2].unwrap_or(0)
            ));
        }
        n_bytes_hdr = f[3].and_then(|v| usize::try_from(v).ok());
    }
    // records 1-11
    let mut rec: Vec<&[u8]> = Vec::with_capacity(11);
    for k in 0..11 {
        match cur.next_line() {
            Some(l) if !is_delim(l) => rec.push(l),
            _ => {
                return Err(err(
                    cur.line,
                    format!("dataset 58 ends after record {k} of 11 header records; the file is truncated or the dataset incomplete"),
                ))
            }
        }
    }
    let hdr_line0 = cur.line - 10; // line of record 1
    let ids = [0, 1, 2, 3, 4].map(|k| decode_text(rec[k]).trim_end().to_string());
    // record 6
    let r6 = rec[5];
    let w6 = [5usize, 10, 5, 10, 11, 10, 4, 11, 10, 4];
    let mut fields6: Vec<&[u8]> = Vec::new();
    let mut s = 0;
    for w in w6 {
        fields6.push(cols(r6, s, w));
        s += w;
    }
    let ints_at = [0usize, 1, 2, 3, 5, 6, 8, 9];
    let fixed_ok = ints_at.iter().all(|&k| parse_int(fields6[k]).is_some());
    let (
        func_type,
        func_id,
        version,
        load_case,
        rsp_entity,
        rsp_node,
        rsp_dir,
        ref_entity,
        ref_node,
        ref_dir,
    ) = if fixed_ok {
        let g = |k: usize| parse_int(fields6[k]).unwrap_or(0);
        (
            g(0),
            g(1),
            g(2),
            g(3),
            decode_text(trim_bytes(fields6[4])),
            g(5),
            g(6),
            decode_text(trim_bytes(fields6[7])),
            g(8),
            g(9),
        )
    } else {
        let t = tokens(r6);
        let gi = |k: usize| t.get(k).and_then(|x| parse_int(x));
        match (
            t.len(),
            gi(0),
            gi(1),
            gi(2),
            gi(3),
            gi(5),
            gi(6),
            gi(8),
            gi(9),
        ) {
            (10, Some(a), Some(b), Some(c), Some(d), Some(e), Some(f), Some(g), Some(h)) => {
                (a, b, c, d, decode_text(t[4]), e, f, decode_text(t[7]), g, h)
            }
            _ => {
                return Err(err(
                    hdr_line0 + 5,
                    format!(
                        "record 6 (DOF identification) unreadable: {:?}",
                        decode_text(r6).trim_end()
                    ),
                ))
            }
        }
    };
    // record 7
    let r7 = rec[6];
    let t7 = tokens(r7);
    let tok_vals: Option<Vec<f64>> = if t7.len() == 6 {
        t7.iter().map(|x| parse_header_f64(x)).collect()
    } else {
        None
    };
    let vals7: Vec<f64> = match tok_vals {
        Some(v) => v,
        None => {
            let w7 = [(0, 10), (10, 10), (20, 10), (30, 13), (43, 13), (56, 13)];
            let v: Option<Vec<f64>> = w7
                .iter()
                .map(|(s, w)| parse_header_f64(cols(r7, *s, *w)))
                .collect();
            v.ok_or_else(|| {
                err(
                    hdr_line0 + 6,
                    format!(
                        "record 7 (data form) unreadable: {:?}",
                        decode_text(r7).trim_end()
                    ),
                )
            })?
        }
    };
    let as_int =
        |v: f64| -> Option<i64> { (v.fract() == 0.0 && v.abs() < 1e15).then_some(v as i64) };
    let ord_data_type = as_int(vals7[0]).unwrap_or(-1);
    let num_pts = as_int(vals7[1]).unwrap_or(-1);
    let spacing = as_int(vals7[2]).unwrap_or(-1);
    if ![2, 4, 5, 6].contains(&ord_data_type) {
        return Err(err(
            hdr_line0 + 6,
            format!(
                "record 7: ordinate data type {} is not 2, 4, 5 or 6 (real/complex, single/double)",
                vals7[0]
            ),
        ));
    }
    if num_pts < 0 {
        return Err(err(
            hdr_line0 + 6,
            format!(
                "record 7: number of points {} is not a non-negative integer",
                vals7[1]
            ),
        ));
    }
    if spacing != 0 && spacing != 1 {
        return Err(err(
            hdr_line0 + 6,
            format!(
                "record 7: abscissa spacing {} is neither 0 (uneven) nor 1 (even)",
                vals7[2]
            ),
        ));
    }
    let num_pts = num_pts as usize;
    let even = spacing == 1;
    let (x0, dx, z) = (vals7[3], vals7[4], vals7[5]);
    let mut axes = Vec::with_capacity(4);
    for k in 0..4 {
        axes.push(parse_axis(rec[7 + k]).ok_or_else(|| {
            err(
                hdr_line0 + 7 + k,
                format!(
                    "record {} (axis data) unreadable: {:?}",
                    8 + k,
                    decode_text(rec[7 + k]).trim_end()
                ),
            )
        })?);
    }
    let ord_type = ord_data_type as i32;
    let complex = ord_type == 5 || ord_type == 6;
    let precision = if ord_type == 2 || ord_type == 5 {
        Precision::Single
    } else {
        Precision::Double
    };
    let (per_pt, widths) = layout(ord_type, even);
    let n_want = num_pts
        .checked_mul(per_pt)
        .ok_or_else(|| err(hdr_line0 + 6, "record 7: number of points too large".into()))?;

    // record 12
    let mut raw: Vec<f64>;
    let data_line;
    let mut abscissa_f64_in_binary = false;
    if binary {
        data_line = cur.line + 1;
        let start = cur.pos;
        let avail = cur.b.len() - start;
        let ord_size = if precision == Precision::Single { 4 } else { 8 };
        let nv = if complex { 2 } else { 1 };
        let spec = num_pts.saturating_mul(nv * ord_size + if even { 0 } else { 4 });
        let alt = num_pts.saturating_mul((nv + 1) * ord_size);
        let closes_at = |n: usize| -> bool {
            if n > avail {
                return false;
            }
            let mut p = start + n;
            let mut skipped = 0;
            while p < cur.b.len() && (cur.b[p] == b'\r' || cur.b[p] == b'\n') && skipped < 3 {
                p += 1;
                skipped += 1;
            }
            let rest = &cur.b[p..];
            let end = rest.iter().position(|&c| c == b'\n').unwrap_or(rest.len());
            is_delim(&rest[..end])
        };
        let mut cands = vec![spec];
        if !even {
            cands.push(alt);
        }
        if let Some(h) = n_bytes_hdr {
            cands.push(h);
        }
        let chosen = cands.iter().copied().find(|&n| closes_at(n));
        let n_used = match chosen {
            Some(n) => n,
            None if spec <= avail => {
                notes.push("no '-1' delimiter right after the binary data; searched forward for it".into());
                spec
            }
            None => {
                return Err(err(
                    data_line,
                    format!(
                        "58b data truncated: {num_pts} points need {spec} bytes but only {avail} remain in the file"
                    ),
                ))
            }
        };
        if n_used != spec {
            if !even && n_used == alt {
                abscissa_f64_in_binary = ord_size == 8;
                notes.push("58b uneven abscissa stored in ordinate precision (not float32 as the spec says); decoded that way".into());
            } else {
                notes.push(format!(
                    "58b: using {n_used} bytes from the header; the layout needs {spec}"
                ));
            }
        }
        if let Some(h) = n_bytes_hdr {
            if h != n_used {
                notes.push(format!("58b header byte count {h} differs from the {n_used} bytes of data; header ignored"));
            }
        }
        let all: &[u8] = cur.b;
        let blob = &all[start..start + n_used.min(avail)];
        raw = Vec::with_capacity(n_want);
        let le = byte_order == 1;
        let mut p = 0usize;
        let rd4 = |p: usize| -> f64 {
            let a = [blob[p], blob[p + 1], blob[p + 2], blob[p + 3]];
            (if le {
                f32::from_le_bytes(a)
            } else {
                f32::from_be_bytes(a)
            }) as f64
        };
        let rd8 = |p: usize| -> f64 {
            let mut a = [0u8; 8];
            a.copy_from_slice(&blob[p..p + 8]);
            if le {
                f64::from_le_bytes(a)
            } else {
                f64::from_be_bytes(a)
            }
        };
        let x_size = if even {
            0
        } else if abscissa_f64_in_binary || (n_used == alt && ord_size == 4) {
            ord_size
        } else {
            4
        };
        let pt_size = x_size + nv * ord_size;
        for _ in 0..num_pts {
            if p + pt_size > blob.len() {
                break;
            }
            if !even {
                raw.push(if x_size == 8 { rd8(p) } else { rd4(p) });
                p += x_size;
            }
            for _ in 0..nv {
                raw.push(if ord_size == 8 { rd8(p) } else { rd4(p) });
                p += ord_size;
            }
        }
        // advance the cursor past the data, counting newlines inside it for line numbers
        cur.line += blob.iter().filter(|&&c| c == b'\n').count();
        cur.pos = start + blob.len();
        // consume up to the closing delimiter
        let mut closed = false;
        while let Some(l) = cur.next_line() {
            if is_delim(l) {
                closed = true;
                break;
            }
            if !trim_bytes(l).is_empty() && chosen.is_some() {
                break;
            }
        }
        if !closed {
            notes.push("no closing '-1' after the binary data".into());
        }
        if raw.len() < n_want {
            return Err(err(
                data_line,
                format!(
                    "58b data truncated: {} of {} values present",
                    raw.len(),
                    n_want
                ),
            ));
        }
    } else {
        data_line = cur.line + 1;
        raw = Vec::with_capacity(n_want.min(1 << 24));
        let mut closed = false;
        while let Some(l) = cur.next_line() {
            if is_delim(l) {
                closed = true;
                break;
            }
            if raw.len() >= n_want {
                if !trim_bytes(l).is_empty() {
                    // count what is beyond num_pts for the note
                    let mut extra = Vec::new();
                    parse_data_line(l, widths, &mut extra);
                    raw.extend(extra);
                }
                continue;
            }
            if !parse_data_line(l, widths, &mut raw) {
                return Err(err(
                    cur.line,
                    format!(
                        "record 12: garbage in data line {:?}; expected numbers",
                        decode_text(cols(l, 0, 80)).trim_end()
                    ),
                ));
            }
        }
        if raw.len() < n_want {
            let what = if closed {
                "inconsistent num_pts"
            } else {
                "truncated dataset (no closing '-1')"
            };
            return Err(err(
                cur.line,
                format!(
                    "{what}: record 7 says {num_pts} points ({n_want} values) but only {} values are present; fix num_pts or complete the data",
                    raw.len()
                ),
            ));
        }
        if !closed {
            notes.push("file ends without the closing '-1'".into());
        }
        if raw.len() > n_want {
            let pts_found = raw.len() as f64 / per_pt as f64;
            notes.push(format!(
                "num_pts {num_pts} but {pts_found} values present; kept {num_pts}"
            ));
            raw.truncate(n_want);
        }
    }
    let _ = data_line;
    // assemble
    let mut x = Vec::with_capacity(num_pts);
    let values = if complex {
        let v = raw
            .chunks_exact(per_pt)
            .map(|c| {
                if even {
                    C64::new(c[0], c[1])
                } else {
                    x.push(c[0]);
                    C64::new(c[1], c[2])
                }
            })
            .collect();
        Ordinate::Complex(v)
    } else {
        let v = raw
            .chunks_exact(per_pt)
            .map(|c| {
                if even {
                    c[0]
                } else {
                    x.push(c[0]);
                    c[1]
                }
            })
            .collect();
        Ordinate::Real(v)
    };
    if even {
        x = (0..num_pts).map(|k| x0 + k as f64 * dx).collect();
    }
    let [abscissa, ordinate, denominator, z_axis]: [AxisSpec; 4] = axes
        .try_into()
        .map_err(|_| err(hdr_line0, "internal: axis records".into()))?;
    Ok(Uff58Dataset {
        ids,
        func_type: func_type as i32,
        func_id,
        version,
        load_case,
        rsp_entity,
        rsp_node,
        rsp_dir: rsp_dir as i32,
        ref_entity,
        ref_node,
        ref_dir: ref_dir as i32,
        ord_data_type: ord_type,
        num_pts,
        even,
        x0: if even { x0 } else { 0.0 },
        dx: if even { dx } else { 0.0 },
        z,
        abscissa,
        ordinate,
        denominator,
        z_axis,
        x,
        values,
        precision,
        binary,
        index,
        line: open_line,
        notes,
    })
}

// ---------------------------------------------------------------------------------------
// writer

/// C/Fortran `%W.Pe`: mantissa with P decimals, signed exponent of at least 2 digits,
/// right-justified in W columns.
pub fn fmt_e(v: f64, width: usize, prec: usize) -> String {
    let s = format!("{v:.prec$e}");
    let body = match s.split_once('e') {
        Some((m, e)) => {
            let exp: i32 = e.parse().unwrap_or(0);
            format!(
                "{m}e{}{:02}",
                if exp < 0 { '-' } else { '+' },
                exp.unsigned_abs()
            )
        }
        None => s,
    };
    format!("{body:>width$}")
}

fn truncate_chars(s: &str, n: usize) -> String {
    s.chars().take(n).collect()
}

fn id_text(s: &str) -> String {
    let t = truncate_chars(s.trim_end(), 80);
    if t.trim().is_empty() {
        "NONE".into()
    } else {
        t
    }
}

/// Encode text for the file: Latin-1 when every char fits, else UTF-8.
fn encode_text(s: &str, out: &mut Vec<u8>) {
    if s.chars().all(|c| (c as u32) < 256) {
        out.extend(s.chars().map(|c| c as u8));
    } else {
        out.extend_from_slice(s.as_bytes());
    }
}

fn push_line(out: &mut Vec<u8>, s: &str) {
    encode_text(s, out);
    out.push(b'\n');
}

/// Serialise datasets 58 (pyuff 2.5.8 byte-compatible ASCII; 58b little-endian per spec).
///
/// ASCII: single precision `6E13.5`; double even `4E20.11`; double uneven real
/// `2(E13.5,E20.11)`; double uneven complex `E13.5,2E20.11`, exactly as pyuff writes. 58b: the
/// ordinate in its precision (float32/float64), uneven abscissa as float32 as the spec says,
/// the header byte count equal to the data length. Non-finite values are an error.
pub fn serialize_uff(
    datasets: &[Uff58Dataset],
    binary: bool,
    file_label: &str,
) -> Result<Vec<u8>, DataError> {
    let mut out = Vec::new();
    for (k, d) in datasets.iter().enumerate() {
        let err = |m: String| DataError::at(file_label, Some(k), None, m);
        let n = d.values.len();
        if !d.even && d.x.len() != n {
            return Err(err(format!(
                "uneven dataset has {} abscissa values for {n} ordinate values",
                d.x.len()
            )));
        }
        let finite = match &d.values {
            Ordinate::Real(v) => v.iter().all(|x| x.is_finite()),
            Ordinate::Complex(v) => v.iter().all(|x| x.re.is_finite() && x.im.is_finite()),
        };
        if !finite || (!d.even && d.x.iter().any(|x| !x.is_finite())) {
            return Err(err(
                "non-finite values cannot be written to UFF; remove or replace them first".into(),
            ));
        }
        let complex = d.values.is_complex();
        let single = d.precision == Precision::Single;
        let ord_type = match (complex, single) {
            (false, true) => 2,
            (false, false) => 4,
            (true, true) => 5,
            (true, false) => 6,
        };
        let ord_size = if single { 4 } else { 8 };
        let nv = if complex { 2 } else { 1 };
        let n_bytes = n * (nv * ord_size + if d.even { 0 } else { 4 });
        push_line(&mut out, "    -1");
        if binary {
            push_line(
                &mut out,
                &format!(
                    "    58b{:6}{:6}{:12}{:12}{:6}{:6}{:12}{:12}",
                    1, 2, 11, n_bytes, 0, 0, 0, 0
                ),
            );
        } else {
            push_line(&mut out, &format!("    58{:74}", ""));
        }
        for id in &d.ids {
            push_line(&mut out, &format!("{:<80}", id_text(id)));
        }
        let name = |s: &str| {
            let t = truncate_chars(s.trim(), 10);
            if t.is_empty() {
                "NONE".to_string()
            } else {
                t
            }
        };
        push_line(
            &mut out,
            &format!(
                "{:5}{:10}{:5}{:10} {:>10}{:10}{:4} {:>10}{:10}{:4}",
                d.func_type,
                d.func_id,
                d.version,
                d.load_case,
                name(&d.rsp_entity),
                d.rsp_node,
                d.rsp_dir,
                name(&d.ref_entity),
                d.ref_node,
                d.ref_dir
            ),
        );
        let (x0, dx) = if d.even { (d.x0, d.dx) } else { (0.0, 0.0) };
        push_line(
            &mut out,
            &format!(
                "{:10}{:10}{:10}{}{}{}",
                ord_type,
                n,
                if d.even { 1 } else { 0 },
                fmt_e(x0, 13, 5),
                fmt_e(dx, 13, 5),
                fmt_e(d.z, 13, 5)
            ),
        );
        for a in [&d.abscissa, &d.ordinate, &d.denominator, &d.z_axis] {
            let lab = |s: &str| {
                let t = truncate_chars(s.trim(), 20);
                if t.is_empty() {
                    "NONE".to_string()
                } else {
                    t
                }
            };
            push_line(
                &mut out,
                &format!(
                    "{:10}{:5}{:5}{:5} {:<20} {:<20}",
                    a.spec_type,
                    a.length_exp,
                    a.force_exp,
                    a.temperature_exp,
                    lab(&a.axis_label),
                    lab(&a.units_label)
                ),
            );
        }
        // flat value list in record-12 order
        let mut flat: Vec<f64> = Vec::with_capacity(n * (nv + 1));
        for i in 0..n {
            if !d.even {
                flat.push(d.x[i]);
            }
            match &d.values {
                Ordinate::Real(v) => flat.push(v[i]),
                Ordinate::Complex(v) => {
                    flat.push(v[i].re);
                    flat.push(v[i].im);
                }
            }
        }
        if binary {
            let per = if d.even { nv } else { nv + 1 };
            for (j, v) in flat.iter().enumerate() {
                let is_x = !d.even && j % per == 0;
                if is_x || single {
                    out.extend_from_slice(&(*v as f32).to_le_bytes());
                } else {
                    out.extend_from_slice(&v.to_le_bytes());
                }
            }
        } else {
            let (fmts, per_line): (Vec<(usize, usize)>, usize) = if single {
                (vec![(13, 5)], 6)
            } else {
                match (complex, d.even) {
                    (_, true) => (vec![(20, 11)], 4),
                    (false, false) => (vec![(13, 5), (20, 11)], 4),
                    (true, false) => (vec![(13, 5), (20, 11), (20, 11)], 3),
                }
            };
            for chunk in flat.chunks(per_line) {
                let mut line = String::with_capacity(80);
                for (j, v) in chunk.iter().enumerate() {
                    let (w, p) = fmts[j % fmts.len()];
                    line.push_str(&fmt_e(*v, w, p));
                }
                push_line(&mut out, &line);
            }
        }
        push_line(&mut out, "    -1");
    }
    Ok(out)
}

/// Write datasets 58 to `path` (ASCII, or 58b when `binary`), atomically (temporary file in the
/// same folder, then rename). See [`serialize_uff`] for the layout.
pub fn write_uff(
    path: impl AsRef<Path>,
    datasets: &[Uff58Dataset],
    binary: bool,
) -> Result<(), DataError> {
    let path = path.as_ref();
    let label = path.display().to_string();
    let bytes = serialize_uff(datasets, binary, &label)?;
    atomic_write(path, &bytes)
}

/// Write bytes to `path` atomically ([`crate::fs_atomic`]: a uniquely named temporary file
/// beside it, fsynced, then renamed over it).
pub(crate) fn atomic_write(path: &Path, bytes: &[u8]) -> Result<(), DataError> {
    crate::fs_atomic::write_atomic_bytes(path, bytes).map_err(|err| {
        DataError::at(
            path.display().to_string(),
            None,
            None,
            format!("cannot write the file: {err}; check that the folder exists and is writable"),
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fortran_numbers() {
        assert_eq!(parse_fortran_f64(b"1.0000000000000000D+00"), Some(1.0));
        assert_eq!(parse_fortran_f64(b"-3.09944E-004"), Some(-3.09944e-4));
        assert_eq!(parse_fortran_f64(b" 1.234-105"), Some(1.234e-105));
        assert_eq!(parse_fortran_f64(b"nan"), None);
        assert_eq!(parse_fortran_f64(b""), None);
    }

    #[test]
    fn c_style_exponent() {
        assert_eq!(fmt_e(1.0, 13, 5), "  1.00000e+00");
        assert_eq!(fmt_e(-0.000123456789, 20, 11), "  -1.23456789000e-04");
        assert_eq!(fmt_e(1e-100, 13, 5), " 1.00000e-100");
        assert_eq!(fmt_e(0.0, 13, 5), "  0.00000e+00");
    }

    #[test]
    fn glued_fields() {
        let mut v = Vec::new();
        assert!(parse_data_line(
            b"-3.09944E-004-2.74181E-004  -0.00115633",
            &[13; 6],
            &mut v
        ));
        assert_eq!(v, vec![-3.09944e-4, -2.74181e-4, -0.00115633]);
    }
}
