//! Import and export of externally assembled models as Matrix Market files, so a user with an
//! ANSYS / Abaqus / Nastran model can skip the mesher.
//!
//! # Files
//! A model directory holds `M.mtx`, `K_b.mtx`, `S.mtx` (S = dK_adhesive/dE, the adhesive
//! stiffness at unit Young's modulus), optionally `C_b.mtx` (viscous damping) and `D_b.mtx`
//! (structural damping), and `dofmap.csv`. Matrices are over the FREE DOFs only (constrained
//! DOFs removed) and all must have the same size.
//!
//! Matrix Market: `%%MatrixMarket matrix coordinate real general` or `... real symmetric`
//! (`integer` is accepted as real). Indices are 1-based; lines starting with `%` are
//! comments; for `symmetric` only the lower triangle (row >= column) may be given and it is
//! mirrored. Repeated entries are summed (as in FE assembly). `pattern`, `complex` and dense
//! `array` files are rejected with a message saying so. Export writes `symmetric` when the
//! matrix is exactly symmetric, else `general`, with shortest round-trip decimal values, so
//! export followed by import reproduces the matrices bit for bit.
//!
//! # DOF map (`dofmap.csv`)
//! One observation point (measurement or excitation point) per `id` and `direction`; a row
//! per DOF contributing to it:
//!
//! ```text
//! id,direction,dof,weight
//! 1,+y,1234,1.0
//! 2,+y,2001,0.5
//! 2,+y,2004,0.5
//! ```
//! * `id`: point id (the node number used in the measured UFF files), non-negative integer.
//! * `direction`: `+x`, `y`, `-z`, ... or a UFF direction code `1..3`, `-1..-3`.
//! * `dof`: 1-based free-DOF index (the row of the matrices, as ANSYS/Abaqus number them in
//!   the exported matrices; map node/direction to equation number with the solver's DOF
//!   mapping file, e.g. ANSYS `*SMAT ... ,,,,,mapping` or HBMAT `.mapping`).
//! * `weight`: optional (default 1); include the direction's sign if the DOF points the
//!   other way. Several rows with the same (id, direction) form a weighted combination
//!   (e.g. shape-function weights of a point inside an element face).
//!
//! Blank lines and lines starting with `#` are ignored.
//!
//! # Harwell-Boeing (ANSYS HBMAT)
//! ANSYS writes Harwell-Boeing with `HBMAT`; Matrix Market directly with
//! `*SMAT,name,D,IMPORT,FULL,file.full,STIFF` followed by `*EXPORT,name,MMF,K_b.mtx`. An HB
//! file can be converted with SciPy (assembled real unsymmetric `RUA` files):
//! `python -c "import sys,scipy.io as s; s.mmwrite(sys.argv[2], s.hb_read(sys.argv[1]))" K.hb K_b.mtx`.

use crate::common::Direction;
use crate::fe::model::{ObservationPoint, SpMat, StructuralModel};
use faer::sparse::Triplet;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Errors of Matrix Market import and export.
#[derive(Debug, thiserror::Error)]
pub enum MmError {
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
    #[error("matrix sizes do not match: {0}")]
    SizeMismatch(String),
    #[error("{0}")]
    Invalid(String),
}

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> MmError + '_ {
    move |source| MmError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Read one Matrix Market coordinate real (general or symmetric) file.
pub fn read_mtx(path: &Path) -> Result<SpMat, MmError> {
    let text = std::fs::read_to_string(path).map_err(io_err(path))?;
    parse_mtx(&text, path)
}

/// Parse Matrix Market text (`path` is only used in error messages).
pub fn parse_mtx(text: &str, path: &Path) -> Result<SpMat, MmError> {
    let perr = |line: usize, msg: String| MmError::Parse {
        path: path.to_path_buf(),
        line,
        msg,
    };
    let mut lines = text.lines().enumerate().map(|(i, l)| (i + 1, l));
    let (ln, header) = lines
        .next()
        .ok_or_else(|| perr(1, "empty file: expected a %%MatrixMarket header".into()))?;
    let h: Vec<String> = header
        .split_whitespace()
        .map(|s| s.to_ascii_lowercase())
        .collect();
    if h.len() < 5 || h[0] != "%%matrixmarket" || h[1] != "matrix" {
        return Err(perr(
            ln,
            format!("expected '%%MatrixMarket matrix coordinate real general|symmetric', got '{header}'"),
        ));
    }
    if h[2] != "coordinate" {
        return Err(perr(
            ln,
            format!(
                "only sparse 'coordinate' files are supported, not '{}'",
                h[2]
            ),
        ));
    }
    if h[3] != "real" && h[3] != "integer" && h[3] != "double" {
        return Err(perr(
            ln,
            format!(
                "only 'real' (or 'integer') values are supported, not '{}'",
                h[3]
            ),
        ));
    }
    let symmetric = match h[4].as_str() {
        "general" => false,
        "symmetric" => true,
        other => {
            return Err(perr(
                ln,
                format!("only 'general' and 'symmetric' storage are supported, not '{other}'"),
            ))
        }
    };
    // size line
    let mut size: Option<(usize, usize, usize)> = None;
    let mut triplets: Vec<Triplet<usize, usize, f64>> = Vec::new();
    let mut count = 0usize;
    for (ln, line) in lines {
        let t = line.trim();
        if t.is_empty() || t.starts_with('%') {
            continue;
        }
        let f: Vec<&str> = t.split_whitespace().collect();
        match size {
            None => {
                if f.len() != 3 {
                    return Err(perr(
                        ln,
                        format!("expected the size line 'rows cols entries', got '{t}'"),
                    ));
                }
                let p = |s: &str, what: &str| {
                    s.parse::<usize>().map_err(|_| {
                        perr(ln, format!("{what} '{s}' is not a non-negative integer"))
                    })
                };
                let (r, c, nnz) = (
                    p(f[0], "row count")?,
                    p(f[1], "column count")?,
                    p(f[2], "entry count")?,
                );
                if symmetric && r != c {
                    return Err(perr(
                        ln,
                        format!("a symmetric matrix must be square, got {r}x{c}"),
                    ));
                }
                size = Some((r, c, nnz));
                triplets.reserve(if symmetric { 2 * nnz } else { nnz });
            }
            Some((r, c, nnz)) => {
                if f.len() != 3 {
                    return Err(perr(ln, format!("expected 'row column value', got '{t}'")));
                }
                count += 1;
                if count > nnz {
                    return Err(perr(
                        ln,
                        format!("more entries than the {nnz} announced in the size line"),
                    ));
                }
                let i = f[0].parse::<usize>().map_err(|_| {
                    perr(
                        ln,
                        format!("row index '{}' is not a positive integer", f[0]),
                    )
                })?;
                let j = f[1].parse::<usize>().map_err(|_| {
                    perr(
                        ln,
                        format!("column index '{}' is not a positive integer", f[1]),
                    )
                })?;
                let v = f[2]
                    .parse::<f64>()
                    .map_err(|_| perr(ln, format!("value '{}' is not a number", f[2])))?;
                if i == 0 || j == 0 || i > r || j > c {
                    return Err(perr(
                        ln,
                        format!(
                            "index ({i}, {j}) outside the {r}x{c} matrix (indices are 1-based)"
                        ),
                    ));
                }
                if !v.is_finite() {
                    return Err(perr(ln, format!("value '{}' is not finite", f[2])));
                }
                if symmetric && i < j {
                    return Err(perr(ln, format!("entry ({i}, {j}) above the diagonal in a 'symmetric' file: only the lower triangle may be stored")));
                }
                triplets.push(Triplet::new(i - 1, j - 1, v));
                if symmetric && i != j {
                    triplets.push(Triplet::new(j - 1, i - 1, v));
                }
            }
        }
    }
    let (r, c, nnz) = size.ok_or_else(|| {
        perr(
            text.lines().count().max(1),
            "missing the size line 'rows cols entries'".into(),
        )
    })?;
    if count != nnz {
        return Err(perr(
            text.lines().count().max(1),
            format!("the size line announces {nnz} entries but the file has {count}"),
        ));
    }
    SpMat::try_new_from_triplets(r, c, &triplets).map_err(|e| {
        MmError::Invalid(format!(
            "{}: cannot build the sparse matrix: {e:?}",
            path.display()
        ))
    })
}

/// True when A_ij == A_ji exactly for all stored entries (duplicates summed).
fn exactly_symmetric(a: &SpMat) -> bool {
    a.nrows() == a.ncols() && crate::linalg::asymmetry(a) == 0.0
}

/// Matrix Market text of `a`: `symmetric` (lower triangle) when exactly symmetric, else
/// `general`; values in shortest round-trip form.
pub fn format_mtx(a: &SpMat, comment: &str) -> String {
    let sym = exactly_symmetric(a);
    // sum duplicates, sorted by (col, row)
    let mut map: BTreeMap<(usize, usize), f64> = BTreeMap::new();
    for t in a.triplet_iter() {
        if !sym || t.row >= t.col {
            *map.entry((t.col, t.row)).or_insert(0.0) += *t.val;
        }
    }
    let mut s = String::with_capacity(map.len() * 40 + 200);
    let _ = writeln!(
        s,
        "%%MatrixMarket matrix coordinate real {}",
        if sym { "symmetric" } else { "general" }
    );
    for c in comment.lines() {
        let _ = writeln!(s, "% {c}");
    }
    let _ = writeln!(s, "{} {} {}", a.nrows(), a.ncols(), map.len());
    for ((j, i), v) in map {
        let _ = writeln!(s, "{} {} {:e}", i + 1, j + 1, v);
    }
    s
}

/// Write `contents` to `path` atomically ([`crate::fs_atomic`]: a uniquely named temporary
/// file in the same folder, fsynced, then renamed).
fn write_atomic(path: &Path, contents: &str) -> Result<(), MmError> {
    crate::fs_atomic::write_atomic_bytes(path, contents.as_bytes()).map_err(io_err(path))
}

/// Write one matrix as a Matrix Market file.
pub fn write_mtx(path: &Path, a: &SpMat, comment: &str) -> Result<(), MmError> {
    write_atomic(path, &format_mtx(a, comment))
}

/// Paths of the files of an imported model.
#[derive(Clone, Debug)]
pub struct MmPaths {
    pub m: PathBuf,
    pub k_b: PathBuf,
    pub s: PathBuf,
    pub c_b: Option<PathBuf>,
    pub d_b: Option<PathBuf>,
    /// DOF map (see the module docs); None gives a model without observation points.
    pub dof_map: Option<PathBuf>,
}

impl MmPaths {
    /// The standard names in `dir`: M.mtx, K_b.mtx, S.mtx, and C_b.mtx, D_b.mtx,
    /// dofmap.csv when they exist.
    pub fn in_dir(dir: &Path) -> Self {
        let opt = |name: &str| {
            let p = dir.join(name);
            p.exists().then_some(p)
        };
        MmPaths {
            m: dir.join("M.mtx"),
            k_b: dir.join("K_b.mtx"),
            s: dir.join("S.mtx"),
            c_b: opt("C_b.mtx"),
            d_b: opt("D_b.mtx"),
            dof_map: opt("dofmap.csv"),
        }
    }
}

/// Parse a DOF map (see the module docs) for a model with `n_dof` free DOFs.
pub fn read_dof_map(path: &Path, n_dof: usize) -> Result<Vec<ObservationPoint>, MmError> {
    let text = std::fs::read_to_string(path).map_err(io_err(path))?;
    parse_dof_map(&text, path, n_dof)
}

/// Parse DOF-map text (`path` is only used in error messages).
pub fn parse_dof_map(
    text: &str,
    path: &Path,
    n_dof: usize,
) -> Result<Vec<ObservationPoint>, MmError> {
    let perr = |line: usize, msg: String| MmError::Parse {
        path: path.to_path_buf(),
        line,
        msg,
    };
    let mut points: Vec<ObservationPoint> = Vec::new();
    let mut header_seen = false;
    for (i, line) in text.lines().enumerate() {
        let ln = i + 1;
        let t = line.trim();
        if t.is_empty() || t.starts_with('#') {
            continue;
        }
        let f: Vec<&str> = t.split(',').map(|s| s.trim()).collect();
        if !header_seen {
            header_seen = true;
            if f.first()
                .map(|s| s.eq_ignore_ascii_case("id"))
                .unwrap_or(false)
            {
                let want = ["id", "direction", "dof", "weight"];
                if f.len() < 3 || f.iter().zip(want).any(|(a, b)| !a.eq_ignore_ascii_case(b)) {
                    return Err(perr(
                        ln,
                        format!("header must be 'id,direction,dof,weight', got '{t}'"),
                    ));
                }
                continue;
            }
        }
        if f.len() < 3 || f.len() > 4 {
            return Err(perr(
                ln,
                format!("expected 'id,direction,dof[,weight]', got '{t}'"),
            ));
        }
        let id = f[0]
            .parse::<u32>()
            .map_err(|_| perr(ln, format!("id '{}' is not a non-negative integer", f[0])))?;
        let direction = Direction::parse(f[1])
            .or_else(|| f[1].parse::<i32>().ok().and_then(Direction::from_uff_code))
            .ok_or_else(|| {
                perr(
                    ln,
                    format!(
                        "direction '{}' is not one of +x, -y, z, ... or a UFF code 1..3, -1..-3",
                        f[1]
                    ),
                )
            })?;
        let dof = f[2]
            .parse::<usize>()
            .map_err(|_| perr(ln, format!("dof '{}' is not a positive integer", f[2])))?;
        if dof == 0 || dof > n_dof {
            return Err(perr(
                ln,
                format!(
                    "dof {dof} is outside 1..={n_dof} (1-based free-DOF numbers of the matrices)"
                ),
            ));
        }
        let weight = match f.get(3) {
            Some(w) if !w.is_empty() => w
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| perr(ln, format!("weight '{w}' is not a finite number")))?,
            _ => 1.0,
        };
        match points
            .iter_mut()
            .find(|p| p.id == id && p.direction == direction)
        {
            Some(p) => p.dofs.push((dof - 1, weight)),
            None => points.push(ObservationPoint {
                id,
                position: None,
                direction,
                dofs: vec![(dof - 1, weight)],
                note: format!("from {}", path.display()),
            }),
        }
    }
    Ok(points)
}

/// DOF-map text of the model's observation points.
pub fn format_dof_map(points: &[ObservationPoint]) -> String {
    let mut s = String::from("id,direction,dof,weight\n");
    for p in points {
        for &(d, w) in &p.dofs {
            let _ = writeln!(s, "{},{},{},{:e}", p.id, p.direction, d + 1, w);
        }
    }
    s
}

/// Import a model from Matrix Market files and a DOF map. All matrices must be square and of
/// the same size; a mismatch is an error naming the files.
pub fn import_model(paths: &MmPaths) -> Result<StructuralModel, MmError> {
    let m = read_mtx(&paths.m)?;
    let k_b = read_mtx(&paths.k_b)?;
    let s = read_mtx(&paths.s)?;
    let c_b = paths.c_b.as_deref().map(read_mtx).transpose()?;
    let d_b = paths.d_b.as_deref().map(read_mtx).transpose()?;
    let n = m.nrows();
    let mut problems = Vec::new();
    if m.ncols() != n {
        problems.push(format!(
            "{} is {}x{} (not square)",
            paths.m.display(),
            n,
            m.ncols()
        ));
    }
    let mut check = |p: &Path, a: &SpMat| {
        if a.nrows() != n || a.ncols() != n {
            problems.push(format!(
                "{} is {}x{} but {} is {n}x{n}",
                p.display(),
                a.nrows(),
                a.ncols(),
                paths.m.display()
            ));
        }
    };
    check(&paths.k_b, &k_b);
    check(&paths.s, &s);
    if let (Some(p), Some(a)) = (&paths.c_b, &c_b) {
        check(p, a);
    }
    if let (Some(p), Some(a)) = (&paths.d_b, &d_b) {
        check(p, a);
    }
    if !problems.is_empty() {
        return Err(MmError::SizeMismatch(format!(
            "{}; all matrices must be over the same free DOFs",
            problems.join("; ")
        )));
    }
    let points = match &paths.dof_map {
        Some(p) => read_dof_map(p, n)?,
        None => Vec::new(),
    };
    Ok(StructuralModel {
        m,
        k_b,
        s,
        c_b,
        d_b,
        points,
        description: format!("imported from Matrix Market files ({})", paths.m.display()),
    })
}

/// Export a model: M.mtx, K_b.mtx, S.mtx (C_b.mtx, D_b.mtx if present) and dofmap.csv in
/// `dir` (created if needed).
pub fn export_model(model: &StructuralModel, dir: &Path) -> Result<(), MmError> {
    std::fs::create_dir_all(dir).map_err(io_err(dir))?;
    let note = format!("rfmlab export: {}", model.description);
    write_mtx(
        &dir.join("M.mtx"),
        &model.m,
        &format!("{note}\nmass matrix M (kg)"),
    )?;
    write_mtx(
        &dir.join("K_b.mtx"),
        &model.k_b,
        &format!("{note}\nadherend stiffness K_b (N/m)"),
    )?;
    write_mtx(
        &dir.join("S.mtx"),
        &model.s,
        &format!("{note}\nadhesive stiffness per unit Young's modulus S (m)"),
    )?;
    if let Some(c) = &model.c_b {
        write_mtx(
            &dir.join("C_b.mtx"),
            c,
            &format!("{note}\nviscous damping C_b (N s/m)"),
        )?;
    }
    if let Some(d) = &model.d_b {
        write_mtx(
            &dir.join("D_b.mtx"),
            d,
            &format!("{note}\nstructural damping D_b (N/m)"),
        )?;
    }
    write_atomic(&dir.join("dofmap.csv"), &format_dof_map(&model.points))
}
