//! FRF data as CSV.
//!
//! # rfmlab layout (read and written)
//! ```text
//! # rfmlab FRF CSV (SI units)
//! # level=L1 quantity=accelerance force_rms_n=3.3 n_averages=200
//! level,response_id,response_dir,reference_id,reference_dir,freq_hz,re,im,coherence
//! L1,1,+y,2,+y,1,-0.0123,0.00456,0.998
//! ```
//! One row per (level, channel, frequency line). Columns:
//! `level` level name (no commas); `response_id`, `reference_id` point ids (unsigned integers);
//! `response_dir`, `reference_dir` signed axes `+x`, `-y`, `+z` (also `x`, `Y-`);
//! `freq_hz` frequency in Hz; `re`, `im` the FRF in SI units of the level's quantity
//! (m/N, (m/s)/N or (m/s^2)/N); `coherence` in 0..1, empty when not measured.
//! Lines starting with `#` are comments; a comment `# level=NAME quantity=Q [force_rms_n=F]
//! [n_averages=N]` states a level's quantity (receptance | mobility | accelerance) and metadata;
//! levels without one take [`CsvOptions::quantity`]. Every channel of a level must have the same
//! frequency lines, in increasing order. The writer uses shortest round-trip number formatting,
//! so write -> read is exact.
//!
//! # Wide layout (read only)
//! `f_Hz,re_H11,im_H11,re_H12,im_H12,...[,coherence|coh_<name>]` as in
//! `shared/data/beam/beam_accelerance_3frf.csv`: first column the frequency (header starting with
//! `f`), then `re_<name>`/`im_<name>` pairs. A name `H<r><c>` (two digits) gives response point r
//! and reference point c; other names give response k+1 (k the pair index), reference 1. Directions
//! are [`CsvOptions::wide_direction`]; the level is [`CsvOptions::level`]; the quantity must come
//! from [`CsvOptions::quantity`] (the layout does not state it).

use std::collections::BTreeMap;
use std::path::Path;

use crate::common::{Direction, C64};
use crate::data::checks::check_level;
use crate::data::uff58::atomic_write;
use crate::data::{Channel, DataError, FrfLevel, FrfSet, Quantity};

/// The header of the rfmlab CSV layout.
pub const CSV_HEADER: &str =
    "level,response_id,response_dir,reference_id,reference_dir,freq_hz,re,im,coherence";

/// Options of [`read_csv`].
#[derive(Clone, Debug)]
pub struct CsvOptions {
    /// Quantity for levels without a `# level=... quantity=...` comment and for the wide layout.
    /// Default None (then such files are an error).
    pub quantity: Option<Quantity>,
    /// Level name for the wide layout. Default "L1".
    pub level: String,
    /// Direction of response and reference in the wide layout. Default +z.
    pub wide_direction: Direction,
}

impl Default for CsvOptions {
    fn default() -> Self {
        CsvOptions {
            quantity: None,
            level: "L1".into(),
            wide_direction: Direction::PZ,
        }
    }
}

/// Name of a quantity in CSV comments.
pub fn quantity_name(q: Quantity) -> &'static str {
    match q {
        Quantity::Receptance => "receptance",
        Quantity::Mobility => "mobility",
        Quantity::Accelerance => "accelerance",
    }
}

/// Parse a quantity name (case-insensitive).
pub fn parse_quantity(s: &str) -> Option<Quantity> {
    match s.trim().to_ascii_lowercase().as_str() {
        "receptance" | "compliance" => Some(Quantity::Receptance),
        "mobility" => Some(Quantity::Mobility),
        "accelerance" | "inertance" => Some(Quantity::Accelerance),
        _ => None,
    }
}

#[derive(Default)]
struct LevelMeta {
    quantity: Option<Quantity>,
    force_rms_n: Option<f64>,
    n_averages: Option<u32>,
}

/// Read a CSV file in the rfmlab layout or the wide layout (detected from the header).
pub fn read_csv(path: impl AsRef<Path>, opts: &CsvOptions) -> Result<FrfSet, DataError> {
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
    let head = &bytes[..bytes.len().min(4096)];
    if bytes.iter().all(|b| b.is_ascii_whitespace()) || head.contains(&0) {
        let why = crate::data::uff58::not_uff_reason(&bytes);
        let why = why.split(':').next().unwrap_or("unreadable");
        return Err(DataError::at(
            &label,
            None,
            None,
            format!("{why}: a CSV file holds a header line (freq_hz, response, reference, re, im ...) and one row per line"),
        ));
    }
    let text = crate::data::uff58::decode_text(&bytes);
    parse_csv(&text, &label, opts)
}

/// [`read_csv`] on text; `label` names the file in errors.
pub fn parse_csv(text: &str, label: &str, opts: &CsvOptions) -> Result<FrfSet, DataError> {
    // a UTF-8 byte-order mark (spreadsheets write one) is not part of the first line
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let err = |line: usize, m: String| DataError::at(label, None, Some(line), m);
    let mut meta: BTreeMap<String, LevelMeta> = BTreeMap::new();
    let mut header: Option<(usize, Vec<String>)> = None;
    let mut rows: Vec<(usize, Vec<&str>)> = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let ln = i + 1;
        let line = raw.trim();
        if line.is_empty() {
            continue;
        }
        if let Some(c) = line.strip_prefix('#') {
            let kv: BTreeMap<&str, &str> = c
                .split_whitespace()
                .filter_map(|t| t.split_once('='))
                .collect();
            if let Some(name) = kv.get("level") {
                let m = meta.entry(name.to_string()).or_default();
                if let Some(q) = kv.get("quantity") {
                    m.quantity = Some(parse_quantity(q).ok_or_else(|| {
                        err(
                            ln,
                            format!(
                                "unknown quantity {q:?}; use receptance, mobility or accelerance"
                            ),
                        )
                    })?);
                }
                m.force_rms_n = match kv.get("force_rms_n") {
                    None => None,
                    Some(v) => match v.parse::<f64>() {
                        Ok(f) if f.is_finite() && f > 0.0 => Some(f),
                        _ => return Err(err(ln, format!("force_rms_n={v}: the RMS force of a level is a positive number in N; fix it or remove the token"))),
                    },
                };
                m.n_averages = match kv.get("n_averages") {
                    None => None,
                    Some(v) => match v.parse::<u32>() {
                        Ok(n) if n > 0 => Some(n),
                        _ => return Err(err(ln, format!("n_averages={v}: the number of averages is a whole number of at least 1; fix it or remove the token"))),
                    },
                };
            }
            continue;
        }
        let fields: Vec<&str> = line.split(',').map(|s| s.trim()).collect();
        if header.is_none() {
            header = Some((ln, fields.iter().map(|s| s.to_ascii_lowercase()).collect()));
        } else {
            rows.push((ln, fields));
        }
    }
    let Some((hl, h)) = header else {
        return Err(err(1, "no header line; expected ".to_string() + CSV_HEADER));
    };
    let set = if h.first().is_some_and(|c| c == "level") {
        let want: Vec<&str> = CSV_HEADER.split(',').collect();
        if h.len() < 8 || h.iter().zip(&want).any(|(a, b)| a != b) {
            return Err(err(
                hl,
                format!(
                    "header {:?} is not the rfmlab layout {CSV_HEADER}",
                    h.join(",")
                ),
            ));
        }
        parse_long(&rows, &meta, label, opts)?
    } else if h.first().is_some_and(|c| c.starts_with('f')) {
        parse_wide(hl, &h, &rows, label, opts)?
    } else {
        return Err(err(
            hl,
            format!(
                "unrecognised header {:?}; expected {CSV_HEADER} or f_Hz,re_<name>,im_<name>,...",
                h.join(",")
            ),
        ));
    };
    for l in &set.levels {
        check_level(l, None, None)?;
    }
    Ok(set)
}

fn num(s: &str, what: &str, ln: usize, label: &str) -> Result<f64, DataError> {
    s.parse::<f64>().map_err(|_| {
        DataError::at(
            label,
            None,
            Some(ln),
            format!("column {what}: {s:?} is not a number"),
        )
    })
}

type Key = (u32, Direction, u32, Direction);

fn parse_long(
    rows: &[(usize, Vec<&str>)],
    meta: &BTreeMap<String, LevelMeta>,
    label: &str,
    opts: &CsvOptions,
) -> Result<FrfSet, DataError> {
    let err = |line: usize, m: String| DataError::at(label, None, Some(line), m);
    // level -> (channel order, channel -> (freqs, values, coherence, first line))
    type Acc = (Vec<f64>, Vec<C64>, Vec<Option<f64>>, usize);
    let mut levels: Vec<(String, Vec<Key>, BTreeMap<Key, Acc>)> = Vec::new();
    for (ln, f) in rows {
        let ln = *ln;
        if f.len() < 8 || f.len() > 9 {
            return Err(err(
                ln,
                format!("{} columns; expected 9 ({CSV_HEADER})", f.len()),
            ));
        }
        let id = |s: &str, what: &str| {
            s.parse::<u32>().map_err(|_| {
                err(
                    ln,
                    format!("column {what}: {s:?} is not a point id (unsigned integer)"),
                )
            })
        };
        let dir = |s: &str, what: &str| {
            Direction::parse(s).ok_or_else(|| {
                err(
                    ln,
                    format!("column {what}: {s:?} is not a direction like +x, -y, z"),
                )
            })
        };
        let key = (
            id(f[1], "response_id")?,
            dir(f[2], "response_dir")?,
            id(f[3], "reference_id")?,
            dir(f[4], "reference_dir")?,
        );
        let fr = num(f[5], "freq_hz", ln, label)?;
        let h = C64::new(num(f[6], "re", ln, label)?, num(f[7], "im", ln, label)?);
        let coh = match f.get(8) {
            Some(s) if !s.is_empty() => Some(num(s, "coherence", ln, label)?),
            _ => None,
        };
        let li = match levels.iter().position(|l| l.0 == f[0]) {
            Some(i) => i,
            None => {
                levels.push((f[0].to_string(), Vec::new(), BTreeMap::new()));
                levels.len() - 1
            }
        };
        let lv = &mut levels[li];
        if !lv.2.contains_key(&key) {
            lv.1.push(key);
        }
        let acc =
            lv.2.entry(key)
                .or_insert_with(|| (Vec::new(), Vec::new(), Vec::new(), ln));
        acc.0.push(fr);
        acc.1.push(h);
        acc.2.push(coh);
    }
    let mut set = FrfSet::default();
    for (name, order, mut chans) in levels {
        let m = meta.get(&name);
        let quantity = m.and_then(|m| m.quantity).or(opts.quantity).ok_or_else(|| {
            DataError::at(label, None, None, format!("level {name}: quantity unknown; add a comment '# level={name} quantity=accelerance' or set the quantity option"))
        })?;
        let mut level = FrfLevel {
            name: name.clone(),
            force_rms_n: m.and_then(|m| m.force_rms_n),
            n_averages: m.and_then(|m| m.n_averages),
            quantity,
            freq_hz: Vec::new(),
            channels: Vec::new(),
        };
        for (k, key) in order.iter().enumerate() {
            let Some((fr, vals, coh, line)) = chans.remove(key) else {
                continue;
            };
            if k == 0 {
                level.freq_hz = fr;
            } else if fr != level.freq_hz {
                return Err(err(line, format!("mixed grids within level {name}: channel {}{}/{}{} has {} lines, the level's first channel {}; give every channel the same lines", key.0, key.1, key.2, key.3, fr.len(), level.freq_hz.len())));
            }
            let coherence = if coh.iter().all(|c| c.is_some()) {
                Some(coh.into_iter().flatten().collect())
            } else if coh.iter().all(|c| c.is_none()) {
                None
            } else {
                return Err(err(line, format!("channel {}{}/{}{}: coherence given on some lines only; give it on all or none", key.0, key.1, key.2, key.3)));
            };
            level.channels.push(Channel {
                response_id: key.0,
                response_dir: key.1,
                reference_id: key.2,
                reference_dir: key.3,
                values: vals,
                coherence,
                source: Some((label.to_string(), 0)),
            });
        }
        set.levels.push(level);
    }
    Ok(set)
}

fn parse_wide(
    hl: usize,
    h: &[String],
    rows: &[(usize, Vec<&str>)],
    label: &str,
    opts: &CsvOptions,
) -> Result<FrfSet, DataError> {
    let err = |line: usize, m: String| DataError::at(label, None, Some(line), m);
    let quantity = opts.quantity.ok_or_else(|| {
        err(hl, "wide CSV layout does not state the quantity; set it (e.g. accelerance for the bundled beam data)".into())
    })?;
    // pairs re_<name>, im_<name>
    let mut pairs: Vec<(String, usize, usize, Option<usize>)> = Vec::new();
    for (i, c) in h.iter().enumerate() {
        if let Some(n) = c.strip_prefix("re_") {
            let im = h
                .iter()
                .position(|x| x.strip_prefix("im_") == Some(n))
                .ok_or_else(|| err(hl, format!("column re_{n} has no im_{n}")))?;
            let coh = h.iter().position(|x| x.strip_prefix("coh_") == Some(n));
            pairs.push((n.to_string(), i, im, coh));
        }
    }
    if pairs.is_empty() {
        return Err(err(
            hl,
            "no re_<name>/im_<name> column pairs in the header".into(),
        ));
    }
    let shared_coh = h.iter().position(|x| x == "coherence");
    let wd = opts.wide_direction;
    let mut level = FrfLevel {
        name: opts.level.clone(),
        force_rms_n: None,
        n_averages: None,
        quantity,
        freq_hz: Vec::new(),
        channels: Vec::new(),
    };
    for (k, (name, _, _, coh)) in pairs.iter().enumerate() {
        let b = name.as_bytes();
        let (r, c) =
            if b.len() == 3 && (b[0] == b'h') && b[1].is_ascii_digit() && b[2].is_ascii_digit() {
                ((b[1] - b'0') as u32, (b[2] - b'0') as u32)
            } else {
                (k as u32 + 1, 1)
            };
        let has_coh = coh.is_some() || (shared_coh.is_some() && pairs.len() == 1);
        level.channels.push(Channel {
            response_id: r,
            response_dir: wd,
            reference_id: c,
            reference_dir: wd,
            values: Vec::new(),
            coherence: has_coh.then(Vec::new),
            source: Some((label.to_string(), 0)),
        });
    }
    for (ln, f) in rows {
        if f.len() != h.len() {
            return Err(err(
                *ln,
                format!("{} columns, the header has {}", f.len(), h.len()),
            ));
        }
        level.freq_hz.push(num(f[0], &h[0], *ln, label)?);
        for (k, (_, re, im, coh)) in pairs.iter().enumerate() {
            let v = C64::new(
                num(f[*re], &h[*re], *ln, label)?,
                num(f[*im], &h[*im], *ln, label)?,
            );
            level.channels[k].values.push(v);
            if let Some(cv) = level.channels[k].coherence.as_mut() {
                let ci = coh.or(shared_coh).unwrap_or(0);
                cv.push(num(f[ci], &h[ci], *ln, label)?);
            }
        }
    }
    Ok(FrfSet {
        levels: vec![level],
    })
}

/// The CSV text of a set (rfmlab layout).
pub fn csv_string(set: &FrfSet) -> Result<String, DataError> {
    use std::fmt::Write as _;
    let mut s = String::from("# rfmlab FRF CSV (SI units)\n");
    for l in &set.levels {
        if l.name.contains(',') || l.name.contains(char::is_whitespace) || l.name.is_empty() {
            return Err(DataError::at(
                format!("level {}", l.name),
                None,
                None,
                "a level name for CSV must be non-empty without commas or blanks; rename the level",
            ));
        }
        let _ = write!(
            s,
            "# level={} quantity={}",
            l.name,
            quantity_name(l.quantity)
        );
        if let Some(f) = l.force_rms_n {
            let _ = write!(s, " force_rms_n={f}");
        }
        if let Some(n) = l.n_averages {
            let _ = write!(s, " n_averages={n}");
        }
        s.push('\n');
    }
    s.push_str(CSV_HEADER);
    s.push('\n');
    for l in &set.levels {
        for c in &l.channels {
            for (k, f) in l.freq_hz.iter().enumerate() {
                let h = c
                    .values
                    .get(k)
                    .copied()
                    .unwrap_or(C64::new(f64::NAN, f64::NAN));
                let _ = write!(
                    s,
                    "{},{},{},{},{},{:?},{:?},{:?},",
                    l.name,
                    c.response_id,
                    c.response_dir,
                    c.reference_id,
                    c.reference_dir,
                    f,
                    h.re,
                    h.im
                );
                if let Some(g) = c.coherence.as_ref().and_then(|g| g.get(k)) {
                    let _ = write!(s, "{g:?}");
                }
                s.push('\n');
            }
        }
    }
    Ok(s)
}

/// Write a set as CSV (rfmlab layout), atomically.
pub fn write_csv(set: &FrfSet, path: impl AsRef<Path>) -> Result<(), DataError> {
    let s = csv_string(set)?;
    atomic_write(path.as_ref(), s.as_bytes())
}
