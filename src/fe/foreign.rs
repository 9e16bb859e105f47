//! Models assembled by other programs: M, K_b and S (and optionally C_b, D_b) read from Matrix
//! Market ([`crate::fe::matrix_market`]), Harwell-Boeing ([`crate::fe::harwell_boeing`], ANSYS
//! `HBMAT`) or Abaqus matrix-output files ([`crate::fe::abaqus`]), with the DOF map of the
//! measurement points, into a [`StructuralModel`]:
//!
//! Z(w) = -w^2 M + K_b + j w C_b + j D_b + E*(w) S,   S = dK_adhesive/dE at fixed nu,
//!
//! so S is the adhesive's stiffness computed with Young's modulus 1 (in the model's stress
//! unit) and its Poisson's ratio fixed, K_b the stiffness of everything else, M the mass of
//! the whole joint (adhesive included).
//!
//! # Units
//! `Units::Si` (default): M in kg, K_b and D_b in N/m, C_b in N s/m, S in m (N/m per Pa).
//! `Units::MmTonneS` (the N-mm-t-s-MPa system common in ANSYS and Abaqus models): M in t,
//! K_b, D_b in N/mm, C_b in N s/mm, S in mm (N/mm per MPa); converted to SI on import
//! (M, K_b, C_b, D_b times 1e3, S times 1e-3). Other unit systems: convert before export.
//!
//! # Equations, constraints and their order
//! Harwell-Boeing and Abaqus `FORMAT=COORDINATE`: the files' own equation numbers (1-based) in
//! their order. Abaqus `FORMAT=MATRIX INPUT`: every (node, DOF) in any file, ordered by node
//! label, then DOF. Constrained DOFs are then removed: a DOF whose stiffness diagonal (K_b, S
//! or D_b) is at least [`CONSTRAINT_MARKER`] (Abaqus writes 1e36 for a DOF held by a boundary
//! condition), and a DOF that no matrix couples to any other DOF (a unit-diagonal placeholder
//! of a constrained or unused DOF; removing it does not change the response at other DOFs).
//! The number removed is in the model's description. Matrix Market files are read as they
//! are ([`crate::fe::matrix_market::import_model`]).
//!
//! # DOF map
//! A CSV file with one row per contributing DOF, in one of two forms chosen by its header:
//!
//! ```text
//! id,direction,dof,weight          equation form: dof = 1-based equation number of the files
//! id,direction,node,weight         node form: the DOF of `node` along `direction`'s axis
//! ```
//!
//! The equation form works with every format (a file without a header is read as the
//! equation form). The node form needs node labels: Abaqus `FORMAT=MATRIX INPUT` files carry
//! them; for Harwell-Boeing give the ANSYS mapping file (`mapping`). In the node form the
//! direction picks the DOF (x 1, y 2, z 3) and its sign multiplies the weight (default 1), so
//! `3,-y,1207` observes minus the y displacement of node 1207. Several rows with the same
//! (id, direction) form a weighted combination.

use crate::common::Direction;
use crate::fe::abaqus::{read_abaqus, AbaqusMatrix, AbqError, NodeDof, NodeLabel};
use crate::fe::harwell_boeing::{read_ansys_mapping, read_hb, HbError};
use crate::fe::matrix_market::{import_model, parse_dof_map, MmError, MmPaths};
use crate::fe::model::{ObservationPoint, SpMat, StructuralModel};
use faer::sparse::Triplet;
use std::collections::{BTreeSet, HashMap};
use std::path::{Path, PathBuf};

/// A stiffness diagonal at or above this marks a constrained DOF (Abaqus writes 1e36).
pub const CONSTRAINT_MARKER: f64 = 1e30;

/// The file format of an imported model (study key `structure.source`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ImportFormat {
    /// `matrix_market`: `.mtx` coordinate files.
    MatrixMarket,
    /// `harwell_boeing`: RSA / RUA files (ANSYS HBMAT, scipy.io.hb_write).
    HarwellBoeing,
    /// `abaqus`: `*MATRIX OUTPUT` text files (FORMAT=MATRIX INPUT or COORDINATE).
    Abaqus,
}

impl ImportFormat {
    /// The study-file name of the format.
    pub fn key(self) -> &'static str {
        match self {
            ImportFormat::MatrixMarket => "matrix_market",
            ImportFormat::HarwellBoeing => "harwell_boeing",
            ImportFormat::Abaqus => "abaqus",
        }
    }

    fn describe(self) -> &'static str {
        match self {
            ImportFormat::MatrixMarket => "Matrix Market",
            ImportFormat::HarwellBoeing => "Harwell-Boeing",
            ImportFormat::Abaqus => "Abaqus matrix",
        }
    }
}

/// The unit system of the imported matrices (study key `structure.import.units`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Units {
    /// m, kg, s, N, Pa (`"SI"`).
    #[default]
    Si,
    /// mm, t, s, N, MPa (`"mm-t-s"`).
    MmTonneS,
}

impl Units {
    /// Parse the study-file value.
    pub fn parse(s: &str) -> Option<Units> {
        match s.trim().to_ascii_lowercase().as_str() {
            "si" | "m-kg-s" => Some(Units::Si),
            "mm-t-s" | "n-mm-t-s" | "mm-tonne-s" => Some(Units::MmTonneS),
            _ => None,
        }
    }

    /// Factors (mass, stiffness and damping, adhesive sensitivity) to SI.
    fn factors(self) -> (f64, f64, f64) {
        match self {
            Units::Si => (1.0, 1.0, 1.0),
            Units::MmTonneS => (1e3, 1e3, 1e-3),
        }
    }
}

/// The files of an imported model.
#[derive(Clone, Debug, PartialEq)]
pub struct ImportFiles {
    pub format: ImportFormat,
    pub mass: PathBuf,
    pub stiffness: PathBuf,
    pub adhesive_sensitivity: PathBuf,
    pub viscous_damping: Option<PathBuf>,
    pub structural_damping: Option<PathBuf>,
    /// DOF map (see the module docs); None gives a model without observation points.
    pub dof_map: Option<PathBuf>,
    /// ANSYS equation-mapping file (Harwell-Boeing only): enables the node form of the map.
    pub mapping: Option<PathBuf>,
    pub units: Units,
}

/// Errors of importing a model from other programs' files.
#[derive(Debug, thiserror::Error)]
pub enum ForeignError {
    #[error(transparent)]
    MatrixMarket(#[from] MmError),
    #[error(transparent)]
    HarwellBoeing(#[from] HbError),
    #[error(transparent)]
    Abaqus(#[from] AbqError),
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
    #[error("{0}")]
    Invalid(String),
}

/// What an equation of the files is, for messages and the node form of the DOF map.
type Labels = Vec<Option<NodeDof>>;

/// Import a model (see the module docs).
pub fn import_model_files(f: &ImportFiles) -> Result<StructuralModel, ForeignError> {
    if f.format == ImportFormat::MatrixMarket {
        if let Some(p) = &f.mapping {
            return Err(ForeignError::Invalid(format!(
                "{}: a mapping file is read with Harwell-Boeing matrices only; Matrix Market \
                 models take an equation-form DOF map",
                p.display()
            )));
        }
        let mut m = import_model(&MmPaths {
            m: f.mass.clone(),
            k_b: f.stiffness.clone(),
            s: f.adhesive_sensitivity.clone(),
            c_b: f.viscous_damping.clone(),
            d_b: f.structural_damping.clone(),
            dof_map: f.dof_map.clone(),
        })?;
        let (fm, fk, fs) = f.units.factors();
        if f.units != Units::Si {
            m.m = scale(&m.m, fm);
            m.k_b = scale(&m.k_b, fk);
            m.s = scale(&m.s, fs);
            m.c_b = m.c_b.as_ref().map(|a| scale(a, fk));
            m.d_b = m.d_b.as_ref().map(|a| scale(a, fk));
        }
        return Ok(m);
    }
    // (name, path) of every matrix in the order M, K_b, S, C_b, D_b
    let mut files: Vec<(&str, &Path)> = vec![
        ("mass", &f.mass),
        ("stiffness", &f.stiffness),
        ("adhesive_sensitivity", &f.adhesive_sensitivity),
    ];
    if let Some(p) = &f.viscous_damping {
        files.push(("viscous_damping", p));
    }
    if let Some(p) = &f.structural_damping {
        files.push(("structural_damping", p));
    }
    let (n, mats, labels) = match f.format {
        ImportFormat::HarwellBoeing => read_hb_set(&files, f.mapping.as_deref())?,
        ImportFormat::Abaqus => {
            if let Some(p) = &f.mapping {
                return Err(ForeignError::Invalid(format!(
                    "{}: a mapping file is read with Harwell-Boeing matrices only; Abaqus \
                     FORMAT=MATRIX INPUT files carry their node labels",
                    p.display()
                )));
            }
            read_abaqus_set(&files)?
        }
        ImportFormat::MatrixMarket => unreachable!("handled above"),
    };
    assemble(f, &files, n, mats, labels)
}

fn scale(a: &SpMat, factor: f64) -> SpMat {
    let t: Vec<Triplet<usize, usize, f64>> = a
        .triplet_iter()
        .map(|t| Triplet::new(t.row, t.col, factor * *t.val))
        .collect();
    SpMat::try_new_from_triplets(a.nrows(), a.ncols(), &t).expect("same pattern")
}

type Entries = Vec<(usize, usize, f64)>;

fn read_hb_set(
    files: &[(&str, &Path)],
    mapping: Option<&Path>,
) -> Result<(usize, Vec<Entries>, Option<Labels>), ForeignError> {
    let mut mats = Vec::with_capacity(files.len());
    let mut n = None::<(usize, &Path)>;
    for (_, p) in files {
        let a = read_hb(p)?;
        match n {
            None => n = Some((a.nrows(), p)),
            Some((n0, p0)) if n0 != a.nrows() => {
                return Err(ForeignError::Invalid(format!(
                    "{} is {}x{} but {} is {n0}x{n0}: all matrices must be over the same \
                     equations",
                    p.display(),
                    a.nrows(),
                    a.ncols(),
                    p0.display()
                )))
            }
            _ => {}
        }
        mats.push(
            a.triplet_iter()
                .map(|t| (t.row, t.col, *t.val))
                .collect::<Entries>(),
        );
    }
    let n = n.map(|x| x.0).unwrap_or(0);
    let labels = match mapping {
        None => None,
        Some(p) => {
            let rows = read_ansys_mapping(p)?;
            let mut l: Labels = vec![None; n];
            for (eq, node, code) in rows {
                if eq > n {
                    return Err(ForeignError::Invalid(format!(
                        "{}: equation {eq} is beyond the matrices' {n} equations: is this the \
                         mapping file of these matrices?",
                        p.display()
                    )));
                }
                if code > 0 {
                    l[eq - 1] = Some((
                        NodeLabel {
                            instance: String::new(),
                            number: node,
                        },
                        code,
                    ));
                }
            }
            Some(l)
        }
    };
    Ok((n, mats, labels))
}

fn read_abaqus_set(
    files: &[(&str, &Path)],
) -> Result<(usize, Vec<Entries>, Option<Labels>), ForeignError> {
    let read: Vec<AbaqusMatrix> = files
        .iter()
        .map(|(_, p)| read_abaqus(p))
        .collect::<Result<_, _>>()?;
    let labelled = read
        .iter()
        .map(|m| matches!(m, AbaqusMatrix::Labelled(_)))
        .collect::<Vec<_>>();
    if labelled.iter().any(|&l| l) && labelled.iter().any(|&l| !l) {
        let name = |want: bool| {
            files
                .iter()
                .zip(&labelled)
                .filter(|(_, &l)| l == want)
                .map(|((_, p), _)| p.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        };
        return Err(ForeignError::Invalid(format!(
            "{} are FORMAT=MATRIX INPUT (node-keyed) but {} are FORMAT=COORDINATE: write all \
             matrices in one format",
            name(true),
            name(false)
        )));
    }
    if labelled[0] {
        let mut keys: BTreeSet<NodeDof> = BTreeSet::new();
        for m in &read {
            if let AbaqusMatrix::Labelled(e) = m {
                for (r, c, _) in e {
                    keys.insert(r.clone());
                    keys.insert(c.clone());
                }
            }
        }
        let keys: Vec<NodeDof> = keys.into_iter().collect();
        let index: HashMap<&NodeDof, usize> =
            keys.iter().enumerate().map(|(i, k)| (k, i)).collect();
        let mats = read
            .iter()
            .map(|m| match m {
                AbaqusMatrix::Labelled(e) => {
                    e.iter().map(|(r, c, v)| (index[r], index[c], *v)).collect()
                }
                AbaqusMatrix::Coordinate(_) => unreachable!("checked above"),
            })
            .collect();
        let n = keys.len();
        Ok((n, mats, Some(keys.into_iter().map(Some).collect())))
    } else {
        let mats: Vec<Entries> = read
            .into_iter()
            .map(|m| match m {
                AbaqusMatrix::Coordinate(e) => e,
                AbaqusMatrix::Labelled(_) => unreachable!("checked above"),
            })
            .collect();
        let n = mats
            .iter()
            .flat_map(|e| e.iter().map(|&(r, c, _)| r.max(c) + 1))
            .max()
            .unwrap_or(0);
        Ok((n, mats, None))
    }
}

fn describe_eq(e: usize, labels: &Option<Labels>) -> String {
    match labels.as_ref().and_then(|l| l[e].as_ref()) {
        Some((node, dof)) => format!("equation {} (node {node}, DOF {dof})", e + 1),
        None => format!("equation {}", e + 1),
    }
}

/// Remove constrained DOFs, convert units, read the DOF map.
fn assemble(
    f: &ImportFiles,
    files: &[(&str, &Path)],
    n: usize,
    mats: Vec<Entries>,
    labels: Option<Labels>,
) -> Result<StructuralModel, ForeignError> {
    if n == 0 {
        return Err(ForeignError::Invalid(format!(
            "{}: the matrices are empty",
            f.mass.display()
        )));
    }
    // constrained: a huge stiffness diagonal in K_b (1), S (2) or D_b (4)
    let mut constrained = vec![false; n];
    let mut coupled = vec![false; n];
    for (k, e) in mats.iter().enumerate() {
        let stiffness_like = matches!(
            files[k].0,
            "stiffness" | "adhesive_sensitivity" | "structural_damping"
        );
        for &(r, c, v) in e {
            if r == c {
                if stiffness_like && v.abs() >= CONSTRAINT_MARKER {
                    constrained[r] = true;
                }
            } else if v != 0.0 {
                coupled[r] = true;
                coupled[c] = true;
            }
        }
    }
    let mut free_of = vec![usize::MAX; n];
    let mut n_free = 0;
    for e in 0..n {
        if !constrained[e] && coupled[e] {
            free_of[e] = n_free;
            n_free += 1;
        }
    }
    let n_marked = constrained.iter().filter(|&&c| c).count();
    let n_uncoupled = (0..n).filter(|&e| !constrained[e] && !coupled[e]).count();
    if n_free == 0 {
        return Err(ForeignError::Invalid(format!(
            "{}: every DOF is constrained or uncoupled; nothing is left to solve",
            f.stiffness.display()
        )));
    }
    let (fm, fk, fs) = f.units.factors();
    let mut out: Vec<SpMat> = Vec::with_capacity(mats.len());
    for (k, e) in mats.iter().enumerate() {
        let factor = match files[k].0 {
            "mass" => fm,
            "adhesive_sensitivity" => fs,
            _ => fk,
        };
        let t: Vec<Triplet<usize, usize, f64>> = e
            .iter()
            .filter(|&&(r, c, _)| free_of[r] != usize::MAX && free_of[c] != usize::MAX)
            .map(|&(r, c, v)| Triplet::new(free_of[r], free_of[c], factor * v))
            .collect();
        out.push(
            SpMat::try_new_from_triplets(n_free, n_free, &t).map_err(|e| {
                ForeignError::Invalid(format!(
                    "{}: cannot build the sparse matrix: {e:?}",
                    files[k].1.display()
                ))
            })?,
        );
    }
    let points = match &f.dof_map {
        None => Vec::new(),
        Some(p) => read_foreign_dof_map(p, n, &labels, &free_of, f.mapping.as_deref())?,
    };
    let mut it = out.into_iter();
    let (m, k_b, s) = (
        it.next().expect("M"),
        it.next().expect("K_b"),
        it.next().expect("S"),
    );
    let mut c_b = None;
    let mut d_b = None;
    for (name, _) in &files[3..] {
        let a = it.next().expect("matrix");
        if *name == "viscous_damping" {
            c_b = Some(a);
        } else {
            d_b = Some(a);
        }
    }
    Ok(StructuralModel {
        m,
        k_b,
        s,
        c_b,
        d_b,
        points,
        description: format!(
            "imported from {} files ({}): {n} equations, {n_marked} constrained (stiffness \
             diagonal >= {CONSTRAINT_MARKER:.0e}) and {n_uncoupled} uncoupled removed, \
             {n_free} free DOFs, units {}",
            f.format.describe(),
            f.mass.display(),
            match f.units {
                Units::Si => "SI",
                Units::MmTonneS => "mm-t-s (converted to SI)",
            }
        ),
    })
}

/// Read a DOF map in the equation or node form (see the module docs) and renumber it to the
/// free DOFs.
fn read_foreign_dof_map(
    path: &Path,
    n: usize,
    labels: &Option<Labels>,
    free_of: &[usize],
    mapping: Option<&Path>,
) -> Result<Vec<ObservationPoint>, ForeignError> {
    let text = std::fs::read_to_string(path).map_err(|source| ForeignError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let header = text
        .lines()
        .map(str::trim)
        .find(|l| !l.is_empty() && !l.starts_with('#'))
        .unwrap_or("");
    let cols: Vec<String> = header
        .split(',')
        .map(|s| s.trim().to_ascii_lowercase())
        .collect();
    let node_form =
        cols.first().is_some_and(|c| c == "id") && cols.get(2).is_some_and(|c| c == "node");
    let perr = |line: usize, msg: String| ForeignError::Parse {
        path: path.to_path_buf(),
        line,
        msg,
    };
    // (point, [(equation, weight, line)])
    let mut raw: Vec<(ObservationPoint, Vec<usize>)> = Vec::new();
    if node_form {
        let Some(labels) = labels else {
            return Err(perr(
                1,
                "the node form (id,direction,node,weight) needs node labels: Abaqus FORMAT=MATRIX \
                 INPUT files carry them; for Harwell-Boeing set structure.import.mapping to the \
                 ANSYS .mapping file; else use the equation form (id,direction,dof,weight)"
                    .into(),
            ));
        };
        let index: HashMap<&NodeDof, usize> = labels
            .iter()
            .enumerate()
            .filter_map(|(e, l)| l.as_ref().map(|k| (k, e)))
            .collect();
        let mut header_seen = false;
        for (i, line) in text.lines().enumerate() {
            let ln = i + 1;
            let t = line.trim();
            if t.is_empty() || t.starts_with('#') {
                continue;
            }
            if !header_seen {
                header_seen = true;
                let want = ["id", "direction", "node", "weight"];
                if cols.len() < 3 || cols.iter().zip(want).any(|(a, b)| a != b) {
                    return Err(perr(
                        ln,
                        format!("header must be 'id,direction,node,weight', got '{t}'"),
                    ));
                }
                continue;
            }
            let fl: Vec<&str> = t.split(',').map(str::trim).collect();
            if fl.len() < 3 || fl.len() > 4 {
                return Err(perr(
                    ln,
                    format!("expected 'id,direction,node[,weight]', got '{t}'"),
                ));
            }
            let id = fl[0]
                .parse::<u32>()
                .map_err(|_| perr(ln, format!("id '{}' is not a non-negative integer", fl[0])))?;
            let direction = Direction::parse(fl[1])
                .or_else(|| fl[1].parse::<i32>().ok().and_then(Direction::from_uff_code))
                .ok_or_else(|| {
                    perr(
                        ln,
                        format!(
                            "direction '{}' is not one of +x, -y, z, ... or a UFF code 1..3, -1..-3",
                            fl[1]
                        ),
                    )
                })?;
            let node = NodeLabel::parse(fl[2]).ok_or_else(|| {
                perr(
                    ln,
                    format!(
                        "node '{}' is not a node label (an integer or instance.label)",
                        fl[2]
                    ),
                )
            })?;
            let weight = match fl.get(3) {
                Some(w) if !w.is_empty() => w
                    .parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite())
                    .ok_or_else(|| perr(ln, format!("weight '{w}' is not a finite number")))?,
                _ => 1.0,
            };
            let key = (node, direction.axis.index() as u32 + 1);
            let eq = *index.get(&key).ok_or_else(|| {
                perr(
                    ln,
                    format!(
                        "node {} has no DOF {} in the matrices{}: check the node number",
                        key.0,
                        key.1,
                        match mapping {
                            Some(m) => format!(" (mapping file {})", m.display()),
                            None => String::new(),
                        }
                    ),
                )
            })?;
            let w = weight * direction.sign as f64;
            match raw
                .iter_mut()
                .find(|(p, _)| p.id == id && p.direction == direction)
            {
                Some((p, lines)) => {
                    p.dofs.push((eq, w));
                    lines.push(ln);
                }
                None => raw.push((
                    ObservationPoint {
                        id,
                        position: None,
                        direction,
                        dofs: vec![(eq, w)],
                        note: format!("from {}", path.display()),
                    },
                    vec![ln],
                )),
            }
        }
    } else {
        let pts = parse_dof_map(&text, path, n)?;
        for p in pts {
            let k = p.dofs.len();
            raw.push((p, vec![0; k]));
        }
    }
    let mut points = Vec::with_capacity(raw.len());
    for (mut p, lines) in raw {
        for (k, (e, _)) in p.dofs.iter_mut().enumerate() {
            let free = free_of[*e];
            if free == usize::MAX {
                let what = describe_eq(*e, labels);
                let at = if lines[k] > 0 {
                    format!("{}, line {}", path.display(), lines[k])
                } else {
                    path.display().to_string()
                };
                return Err(ForeignError::Invalid(format!(
                    "{at}: point {} ({}) uses {what}, which was removed as constrained or \
                     uncoupled: measure at a free DOF",
                    p.id, p.direction
                )));
            }
            *e = free;
        }
        points.push(p);
    }
    Ok(points)
}
