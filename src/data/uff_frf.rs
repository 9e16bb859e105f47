//! The semantic layer over UFF58: FRF and coherence datasets -> [`FrfSet`] and back.
//!
//! Which datasets are FRFs: function type 4; function type 0 (general) too when the ordinate
//! denominator is an excitation force (spec type 13) and the values are complex (some exporters
//! write FRFs as "general"). Function type 6 datasets are coherences and are paired with the FRF
//! of the same response and reference DOF. Every other function type is ignored (listed by
//! `rfmlab inspect`).
//!
//! Quantity: (a) ordinate spec type 8/11/12 (displacement/velocity/acceleration, paper:
//! receptance/mobility/accelerance), else (b) the ordinate units label (`m/s^2`, `m/s²`, `(m/s)/N`,
//! `m/N`, `g`, `mm/...`), else (c) [`UffImportOptions::quantity`]. Units: values are converted to
//! SI as `H_SI = H_file * force / length` with the dataset 164 factors (file value / factor = SI),
//! times 9.80665 for `g` and 1e-3 for `mm` labels.
//!
//! DOFs: node and signed direction from record 6; when those are 0 the entity name is parsed
//! (`.1.Z-` -> node 1, -z; `.56.Z` -> 56, +z; `3+X`). Directions keep the file's sign (the FRF
//! values are not sign-flipped; `H_global = sign(rsp) sign(ref) H_file` is the caller's choice).

use std::collections::BTreeMap;
use std::path::Path;

use crate::common::{Direction, C64};
use crate::data::checks::check_level;
use crate::data::uff58::{
    read_uff, write_uff, AxisSpec, Ordinate, Precision, Uff58Dataset, UffFile,
};
use crate::data::{Channel, DataError, FrfLevel, FrfSet, Quantity};

/// Standard gravity (m/s^2) for labels in g.
pub const G_STANDARD: f64 = 9.80665;

/// Options of [`frf_set_from_uff`].
#[derive(Clone, Debug)]
pub struct UffImportOptions {
    /// Quantity assumed when neither spec types nor units labels tell it. Default None (error).
    pub quantity: Option<Quantity>,
    /// Accept function type 0 (general) complex datasets over a force (spec 13) as FRFs. Default true.
    pub accept_general_frf: bool,
    /// Read node and direction from the entity name when the node/direction fields are 0. Default true.
    pub dof_from_entity_name: bool,
    /// Relative tolerance (of the largest frequency) for two grids to be the same. Default 1e-6
    /// (single-precision abscissas).
    pub grid_rel_tol: f64,
}

impl Default for UffImportOptions {
    fn default() -> Self {
        UffImportOptions {
            quantity: None,
            accept_general_frf: true,
            dof_from_entity_name: true,
            grid_rel_tol: 1e-6,
        }
    }
}

/// Role of a dataset 58 in an FRF set.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    Frf,
    Coherence,
    Other,
}

/// FRF, coherence or other (see the module doc).
pub fn role(d: &Uff58Dataset, opts: &UffImportOptions) -> Role {
    match d.func_type {
        4 => Role::Frf,
        6 => Role::Coherence,
        0 if opts.accept_general_frf && d.denominator.spec_type == 13 && d.values.is_complex() => {
            Role::Frf
        }
        _ => Role::Other,
    }
}

/// Quantity from a units label, with the factor that takes the label's unit to SI.
pub fn quantity_from_label(label: &str) -> Option<(Quantity, f64)> {
    let l: String = label
        .to_lowercase()
        .replace('²', "^2")
        .replace("**2", "^2")
        .chars()
        .filter(|c| !c.is_whitespace())
        .collect();
    let l = l.replace("s2", "s^2");
    let scale = if l.contains("mm/") || l.contains("(mm)") {
        1e-3
    } else {
        1.0
    };
    if l.contains("m/s^2") || l.contains("m/s/s") {
        return Some((Quantity::Accelerance, scale));
    }
    if l.contains("m/s") {
        return Some((Quantity::Mobility, scale));
    }
    let words: Vec<&str> = l
        .split(|c: char| !c.is_ascii_alphanumeric())
        .filter(|w| !w.is_empty())
        .collect();
    if words.contains(&"g") {
        return Some((Quantity::Accelerance, G_STANDARD));
    }
    if l.contains("m/n")
        || words == ["m"]
        || words == ["mm"]
        || (words.contains(&"m") && words.contains(&"n"))
    {
        return Some((Quantity::Receptance, scale));
    }
    None
}

/// Quantity of an FRF dataset and the factor that takes its label unit to SI (before the
/// dataset 164 factors). See the module doc for the order of the rules.
pub fn detect_quantity(d: &Uff58Dataset) -> Option<(Quantity, f64)> {
    let from_label = quantity_from_label(&d.ordinate.units_label);
    let from_spec = match d.ordinate.spec_type {
        8 => Some(Quantity::Receptance),
        11 => Some(Quantity::Mobility),
        12 => Some(Quantity::Accelerance),
        _ => None,
    };
    match (from_spec, from_label) {
        (Some(q), Some((ql, f))) if q == ql => Some((q, f)),
        (Some(q), _) => Some((q, 1.0)),
        (None, l) => l,
    }
}

/// Node and signed direction from an entity name such as `.1.Z-`, `.56.Z`, `3+X`, `12:-y`.
pub fn dof_from_entity(name: &str) -> Option<(u32, Direction)> {
    let b: Vec<char> = name.trim().chars().collect();
    let ai = b
        .iter()
        .rposition(|c| matches!(c.to_ascii_lowercase(), 'x' | 'y' | 'z'))?;
    let mut sign = 1i8;
    if b.get(ai + 1) == Some(&'-') || (ai > 0 && b[ai - 1] == '-') {
        sign = -1;
    }
    let axis_s = b[ai].to_string();
    let dir = Direction::parse(&axis_s)?;
    let digits_end = b[..ai].iter().rposition(|c| c.is_ascii_digit())? + 1;
    let digits_start = b[..digits_end]
        .iter()
        .rposition(|c| !c.is_ascii_digit())
        .map_or(0, |p| p + 1);
    let node: u32 = b[digits_start..digits_end]
        .iter()
        .collect::<String>()
        .parse()
        .ok()?;
    Some((node, Direction::new(dir.axis, sign)))
}

/// Response and reference DOF of a dataset (record 6, else entity names).
pub fn dataset_dofs(
    d: &Uff58Dataset,
    opts: &UffImportOptions,
) -> Option<((u32, Direction), (u32, Direction))> {
    let one = |node: i64, dir: i32, ent: &str| -> Option<(u32, Direction)> {
        if dir == 0 && opts.dof_from_entity_name {
            if let Some(v) = dof_from_entity(ent) {
                return Some(v);
            }
        }
        let n = u32::try_from(node).ok()?;
        Some((n, Direction::from_uff_code(dir)?))
    };
    Some((
        one(d.rsp_node, d.rsp_dir, &d.rsp_entity)?,
        one(d.ref_node, d.ref_dir, &d.ref_entity)?,
    ))
}

fn parse_kv(ids: &[String; 5], key: &str) -> Option<f64> {
    ids.iter()
        .flat_map(|s| s.split_whitespace())
        .find_map(|t| t.strip_prefix(key)?.strip_prefix('=')?.parse().ok())
}

/// Whether two frequency grids hold the same lines: equal counts, every line within `rel` of
/// the largest |f| of both.
pub(crate) fn grids_match(a: &[f64], b: &[f64], rel: f64) -> bool {
    if a.len() != b.len() {
        return false;
    }
    let scale = a
        .iter()
        .chain(b.iter())
        .fold(0.0f64, |m, x| m.max(x.abs()))
        .max(1e-300);
    a.iter().zip(b).all(|(x, y)| (x - y).abs() <= rel * scale)
}

/// Multiply an FRF of quantity `from` at `f` Hz by `(j w)^(k_to - k_from)` (k: receptance 0,
/// mobility 1, accelerance 2), so accelerance = j w mobility = -w^2 receptance.
pub fn convert_value(h: C64, freq_hz: f64, from: Quantity, to: Quantity) -> C64 {
    let k = |q: Quantity| match q {
        Quantity::Receptance => 0i32,
        Quantity::Mobility => 1,
        Quantity::Accelerance => 2,
    };
    let jw = C64::new(0.0, 2.0 * std::f64::consts::PI * freq_hz);
    h * jw.powi(k(to) - k(from))
}

/// Build an [`FrfSet`] from UFF files, one `(path, level_name)` per file. Files with the same
/// level name form one level (their grids must agree); an empty level name takes the level from
/// each dataset's ID line 4 (load case name; `NONE` -> `L1`). RMS force and averages are read
/// from `force_rms_n=...` / `n_averages=...` tokens in the ID lines (written by
/// [`frf_set_to_uff`]). Each level is checked with [`check_level`] (no excitation, no band).
pub fn frf_set_from_uff<P: AsRef<Path>>(
    files: &[(P, String)],
    opts: &UffImportOptions,
) -> Result<FrfSet, DataError> {
    let mut loaded = Vec::new();
    for (p, lvl) in files {
        loaded.push((read_uff(p)?, lvl.clone()));
    }
    frf_set_from_uff_files(&loaded, opts)
}

/// [`frf_set_from_uff`] on files already read.
pub fn frf_set_from_uff_files(
    files: &[(UffFile, String)],
    opts: &UffImportOptions,
) -> Result<FrfSet, DataError> {
    let mut order: Vec<String> = Vec::new();
    let mut levels: BTreeMap<String, FrfLevel> = BTreeMap::new();
    // coherences are attached after all FRFs are in
    let mut coh: Vec<(String, &UffFile, &Uff58Dataset)> = Vec::new();
    for (f, lvl_name) in files {
        let length_force = f.units.as_ref().map_or(1.0, |u| u.force / u.length);
        for d in &f.datasets {
            let err = |m: String| DataError::at(&f.label, Some(d.index), Some(d.line), m);
            let name = if lvl_name.is_empty() {
                let t = d.ids[3].trim();
                if t.is_empty() || t == "NONE" {
                    "L1".to_string()
                } else {
                    t.to_string()
                }
            } else {
                lvl_name.clone()
            };
            match role(d, opts) {
                Role::Other => continue,
                Role::Coherence => {
                    crate::data::checks::check_dataset(&f.label, d, true)?;
                    coh.push((name, f, d));
                    continue;
                }
                Role::Frf => crate::data::checks::check_dataset(&f.label, d, false)?,
            }
            let Some(((rid, rdir), (fid, fdir))) = dataset_dofs(d, opts) else {
                return Err(err(format!(
                    "FRF with response {} {} dir {} / reference {} {} dir {}: not a translational DOF with a non-negative node; rfmlab needs translations (direction +-1..3)",
                    d.rsp_entity, d.rsp_node, d.rsp_dir, d.ref_entity, d.ref_node, d.ref_dir
                )));
            };
            let (q, label_factor) = match detect_quantity(d).or(opts.quantity.map(|q| (q, 1.0))) {
                Some(v) => v,
                None => {
                    return Err(err(format!(
                        "cannot tell whether this FRF is a receptance, mobility or accelerance (ordinate spec type {}, units label {:?}); set the quantity option",
                        d.ordinate.spec_type, d.ordinate.units_label
                    )))
                }
            };
            let scale = label_factor * length_force;
            let values: Vec<C64> = match &d.values {
                Ordinate::Complex(v) => v.iter().map(|h| h * scale).collect(),
                Ordinate::Real(v) => v.iter().map(|h| C64::new(h * scale, 0.0)).collect(),
            };
            if d.abscissa.spec_type == 17 {
                return Err(err(
                    "FRF over a time abscissa (spec type 17); expected frequency in Hz".into(),
                ));
            }
            let force_rms_n = parse_kv(&d.ids, "force_rms_n");
            if let Some(f) = force_rms_n.filter(|f| !(f.is_finite() && *f > 0.0)) {
                return Err(err(format!(
                    "force_rms_n={f} in the ID lines: the RMS force of a level is a positive number in N; fix it or remove the token"
                )));
            }
            let n_averages = parse_kv(&d.ids, "n_averages");
            if let Some(n) =
                n_averages.filter(|n| !(*n >= 1.0 && *n <= u32::MAX as f64 && n.fract() == 0.0))
            {
                return Err(err(format!(
                    "n_averages={n} in the ID lines: the number of averages is a whole number of at least 1; fix it or remove the token"
                )));
            }
            let level = levels.entry(name.clone()).or_insert_with(|| {
                order.push(name.clone());
                FrfLevel {
                    name: name.clone(),
                    force_rms_n,
                    n_averages: n_averages.map(|v| v as u32),
                    quantity: q,
                    freq_hz: d.x.clone(),
                    channels: Vec::new(),
                }
            });
            if !grids_match(&level.freq_hz, &d.x, opts.grid_rel_tol) {
                return Err(err(format!(
                    "mixed grids within level {name}: this FRF has {} lines {}..{} Hz, the level has {} lines {}..{} Hz; resample the data or put it in another level",
                    d.x.len(),
                    d.x.first().copied().unwrap_or(f64::NAN),
                    d.x.last().copied().unwrap_or(f64::NAN),
                    level.freq_hz.len(),
                    level.freq_hz.first().copied().unwrap_or(f64::NAN),
                    level.freq_hz.last().copied().unwrap_or(f64::NAN),
                )));
            }
            let values = if q == level.quantity {
                values
            } else {
                values
                    .iter()
                    .zip(&level.freq_hz)
                    .map(|(h, f)| convert_value(*h, *f, q, level.quantity))
                    .collect()
            };
            level.channels.push(Channel {
                response_id: rid,
                response_dir: rdir,
                reference_id: fid,
                reference_dir: fdir,
                values,
                coherence: None,
                source: Some((f.label.clone(), d.index)),
            });
        }
    }
    for (name, f, d) in coh {
        let err = |m: String| DataError::at(&f.label, Some(d.index), Some(d.line), m);
        let Some(level) = levels.get_mut(&name) else {
            continue;
        };
        let Some(((rid, rdir), (fid, fdir))) = dataset_dofs(d, opts) else {
            continue;
        };
        let Some(ch) = level.channels.iter_mut().find(|c| {
            c.response_id == rid
                && c.response_dir.axis == rdir.axis
                && c.reference_id == fid
                && c.reference_dir.axis == fdir.axis
        }) else {
            continue;
        };
        if !grids_match(&level.freq_hz, &d.x, opts.grid_rel_tol) {
            return Err(err(format!(
                "coherence grid ({} lines) differs from its FRF's grid ({} lines)",
                d.x.len(),
                level.freq_hz.len()
            )));
        }
        let c: Vec<f64> = match &d.values {
            Ordinate::Real(v) => v.clone(),
            Ordinate::Complex(v) => v.iter().map(|z| z.re).collect(),
        };
        if ch.coherence.is_some() {
            return Err(err(format!(
                "a second coherence for channel {rid}{rdir}/{fid}{fdir}; remove the duplicate"
            )));
        }
        ch.coherence = Some(c);
    }
    let mut set = FrfSet::default();
    for name in order {
        if let Some(l) = levels.remove(&name) {
            check_level(&l, None, None)?;
            set.levels.push(l);
        }
    }
    Ok(set)
}

/// Whether `f` is an even grid whose `f0` and `df` survive the header's `E13.5` format exactly.
fn even_grid(f: &[f64]) -> Option<(f64, f64)> {
    if f.len() < 2 {
        return f.first().map(|&x| (x, 0.0));
    }
    let n = f.len();
    let df = (f[n - 1] - f[0]) / (n - 1) as f64;
    let exact = |v: f64| {
        crate::data::uff58::parse_fortran_f64(crate::data::uff58::fmt_e(v, 13, 5).as_bytes())
            == Some(v)
    };
    let scale = f.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let ok = f
        .iter()
        .enumerate()
        .all(|(k, x)| (x - (f[0] + k as f64 * df)).abs() <= 1e-12 * scale);
    (ok && exact(f[0]) && exact(df)).then_some((f[0], df))
}

fn quantity_axis(q: Quantity) -> AxisSpec {
    match q {
        Quantity::Receptance => AxisSpec::new(8, "Displacement", "m"),
        Quantity::Mobility => AxisSpec::new(11, "Velocity", "m/s"),
        Quantity::Accelerance => AxisSpec::new(12, "Acceleration", "m/s^2"),
    }
}

/// The datasets 58 [`frf_set_to_uff`] writes: per level and channel an FRF (func 4, complex
/// double, ordinate spec 8/11/12 over 13, abscissa 18 Hz) and, when present, its coherence
/// (func 6, real double). ID line 4 holds the level name; ID line 5 `force_rms_n=` and
/// `n_averages=` when known. Even grids are written even when `f0` and `df` are exact in
/// `E13.5`, else uneven (abscissa single precision, as the format dictates).
pub fn frf_set_datasets(set: &FrfSet) -> Vec<Uff58Dataset> {
    let mut out = Vec::new();
    for level in &set.levels {
        let grid = even_grid(&level.freq_hz);
        let mut id5 = Vec::new();
        if let Some(f) = level.force_rms_n {
            id5.push(format!("force_rms_n={f}"));
        }
        if let Some(n) = level.n_averages {
            id5.push(format!("n_averages={n}"));
        }
        let id5 = if id5.is_empty() {
            "NONE".to_string()
        } else {
            id5.join(" ")
        };
        for ch in &level.channels {
            let mk = |func: i32, values: Ordinate| {
                let mut d = match grid {
                    Some((f0, df)) => Uff58Dataset::new_even(func, f0, df, values),
                    None => Uff58Dataset::new_uneven(func, level.freq_hz.clone(), values),
                };
                d.rsp_node = ch.response_id as i64;
                d.rsp_dir = ch.response_dir.uff_code();
                d.ref_node = ch.reference_id as i64;
                d.ref_dir = ch.reference_dir.uff_code();
                d.ids[3] = level.name.clone();
                d.ids[4] = id5.clone();
                d.precision = Precision::Double;
                d
            };
            let mut frf = mk(4, Ordinate::Complex(ch.values.clone()));
            frf.ids[0] = format!(
                "{:?} {}{}/{}{}",
                level.quantity, ch.response_id, ch.response_dir, ch.reference_id, ch.reference_dir
            );
            frf.ordinate = quantity_axis(level.quantity);
            frf.denominator = AxisSpec::new(13, "Force", "N");
            out.push(frf);
            if let Some(c) = &ch.coherence {
                let mut d = mk(6, Ordinate::Real(c.clone()));
                d.ids[0] = format!(
                    "Coherence {}{}/{}{}",
                    ch.response_id, ch.response_dir, ch.reference_id, ch.reference_dir
                );
                d.ordinate = AxisSpec::new(0, "Coherence", "NONE");
                out.push(d);
            }
        }
    }
    out
}

/// Write an [`FrfSet`] as UFF58 (58b when `binary`), atomically. See [`frf_set_datasets`].
pub fn frf_set_to_uff(set: &FrfSet, path: impl AsRef<Path>, binary: bool) -> Result<(), DataError> {
    write_uff(path, &frf_set_datasets(set), binary)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::common::Axis;

    #[test]
    fn entity_names() {
        assert_eq!(
            dof_from_entity(".1.Z-"),
            Some((1, Direction::new(Axis::Z, -1)))
        );
        assert_eq!(dof_from_entity(".56.Z"), Some((56, Direction::PZ)));
        assert_eq!(dof_from_entity("3+X"), Some((3, Direction::PX)));
        assert_eq!(dof_from_entity("NONE"), None);
    }

    #[test]
    fn labels() {
        assert_eq!(
            quantity_from_label("(m/s)/N"),
            Some((Quantity::Mobility, 1.0))
        );
        assert_eq!(
            quantity_from_label("(1/N)*(m/s²)"),
            Some((Quantity::Accelerance, 1.0))
        );
        assert_eq!(
            quantity_from_label("(m/s\u{b2})/N"),
            Some((Quantity::Accelerance, 1.0))
        );
        assert_eq!(
            quantity_from_label("g/N"),
            Some((Quantity::Accelerance, G_STANDARD))
        );
        assert_eq!(
            quantity_from_label("m/N"),
            Some((Quantity::Receptance, 1.0))
        );
        assert_eq!(quantity_from_label("NONE"), None);
    }

    #[test]
    fn conversion_identities() {
        let h = C64::new(0.3, -1.2);
        let f = 17.5;
        let w = 2.0 * std::f64::consts::PI * f;
        let a = convert_value(h, f, Quantity::Receptance, Quantity::Accelerance);
        assert!((a - h * (-w * w)).norm() < 1e-12 * a.norm());
        let m = convert_value(h, f, Quantity::Receptance, Quantity::Mobility);
        assert!(
            (convert_value(m, f, Quantity::Mobility, Quantity::Accelerance) - a).norm()
                < 1e-12 * a.norm()
        );
        assert!(
            (convert_value(a, f, Quantity::Accelerance, Quantity::Receptance) - h).norm() < 1e-12
        );
    }
}
