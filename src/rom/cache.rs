//! A certified ROM saved to disk, keyed by everything it depends on.
//!
//! The key is the SHA-256 of the model's matrices (M, K_b, S, C_b, D_b: pattern and values),
//! the observation points (DOFs and weights), the inputs and the ROM settings, so a cached
//! ROM is reused only for the same structure, points, band, range and tolerance; any change
//! builds and certifies a new one. The file is JSON (matrices row-major as f64 bit patterns,
//! so the round trip is exact) and is written atomically.
//!
//! ROMs with terms (degraded bond strips, adherend damping, base springs; minutes to build,
//! certify and compress) are cached the same way ([`term_key`], [`save_terms`],
//! [`load_terms`]), their key adding every term's matrix and settings.
//!
//! Runs may share a cache folder (two studies of one joint, a test suite's threads). Through
//! [`load_or_build`], an entry missing from the cache is built by one of them while the others
//! that want the same key wait (an exclusive lock on its `.lock` file beside it) and then read
//! it, instead of each building it again.

use super::reduced::ReducedModel;
use super::terms::{pinvs, TermCertificate, TermMap, TermRom, TermSpec};
use super::{Certificate, ModulusRange, RomParams};
use crate::fe::model::{SpMat, StructuralModel};
use faer::Mat;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use std::path::Path;

/// Bump when the file layout or the ROM algorithm changes (old files are then ignored).
const FORMAT: u32 = 2;

fn hash_sp(h: &mut Sha256, tag: &str, a: Option<&SpMat>) {
    h.update(tag.as_bytes());
    let Some(a) = a else {
        h.update(b"none");
        return;
    };
    h.update((a.nrows() as u64).to_le_bytes());
    h.update((a.ncols() as u64).to_le_bytes());
    for t in a.triplet_iter() {
        h.update((t.row as u64).to_le_bytes());
        h.update((t.col as u64).to_le_bytes());
        h.update(t.val.to_bits().to_le_bytes());
    }
}

/// The cache key (hex SHA-256) of a ROM of `model` for `inputs` built with `params`.
pub fn key(model: &StructuralModel, inputs: &[usize], params: &RomParams) -> String {
    let mut h = Sha256::new();
    h.update(FORMAT.to_le_bytes());
    hash_sp(&mut h, "M", Some(&model.m));
    hash_sp(&mut h, "K", Some(&model.k_b));
    hash_sp(&mut h, "S", Some(&model.s));
    hash_sp(&mut h, "C", model.c_b.as_ref());
    hash_sp(&mut h, "D", model.d_b.as_ref());
    for p in &model.points {
        h.update(b"P");
        for &(d, w) in &p.dofs {
            h.update((d as u64).to_le_bytes());
            h.update(w.to_bits().to_le_bytes());
        }
    }
    for &i in inputs {
        h.update((i as u64).to_le_bytes());
    }
    let f = |h: &mut Sha256, x: f64| h.update(x.to_bits().to_le_bytes());
    h.update(b"params");
    f(&mut h, params.band_hz.0);
    f(&mut h, params.band_hz.1);
    f(&mut h, params.range.e_storage_pa.0);
    f(&mut h, params.range.e_storage_pa.1);
    f(&mut h, params.range.e_loss_pa.0);
    f(&mut h, params.range.e_loss_pa.1);
    f(&mut h, params.tolerance);
    f(&mut h, params.deflation_tol);
    for n in [
        params.allow_uncertified as usize,
        params.n_e_ref_initial,
        params.krylov_depth_initial,
        params.krylov_depth_step,
        params.max_levels,
        params.n_cert_moduli_per_axis,
        params.n_cert_lines,
    ] {
        h.update((n as u64).to_le_bytes());
    }
    match params.reference {
        crate::rom::Reference::SparseLu => h.update(b"reference LU"),
        crate::rom::Reference::Shifted => h.update(b"reference shifted Krylov"),
        crate::rom::Reference::Iterative {
            residual_tol,
            max_iter,
        } => {
            h.update(b"reference GMRES");
            f(&mut h, residual_tol);
            h.update((max_iter as u64).to_le_bytes());
        }
    }
    h.finalize().iter().map(|b| format!("{b:02x}")).collect()
}

#[derive(Serialize, Deserialize)]
struct DenseJson {
    rows: usize,
    cols: usize,
    /// Row-major values as IEEE-754 bit patterns (exact whatever the JSON float parser).
    bits: Vec<u64>,
}

impl DenseJson {
    fn from(m: &Mat<f64>) -> Self {
        DenseJson {
            rows: m.nrows(),
            cols: m.ncols(),
            bits: (0..m.nrows())
                .flat_map(|i| (0..m.ncols()).map(move |j| m[(i, j)].to_bits()))
                .collect(),
        }
    }
    fn to_mat(&self) -> Option<Mat<f64>> {
        (self.bits.len() == self.rows * self.cols).then(|| {
            Mat::from_fn(self.rows, self.cols, |i, j| {
                f64::from_bits(self.bits[i * self.cols + j])
            })
        })
    }
}

#[derive(Serialize, Deserialize)]
struct RomJson {
    format: u32,
    key: String,
    #[serde(flatten)]
    model: ModelJson,
    certificate: Certificate,
}

/// The matrices of a [`ReducedModel`].
#[derive(Serialize, Deserialize)]
struct ModelJson {
    n_r: usize,
    n_out: usize,
    inputs: Vec<usize>,
    m_r: DenseJson,
    k_r: DenseJson,
    s_r: DenseJson,
    c_r: Option<DenseJson>,
    d_r: Option<DenseJson>,
    b_r: DenseJson,
    sb_r: DenseJson,
    range: ModulusRange,
}

impl ModelJson {
    fn from(rom: &ReducedModel) -> Self {
        ModelJson {
            n_r: rom.n_r,
            n_out: rom.n_out,
            inputs: rom.inputs.clone(),
            m_r: DenseJson::from(&rom.m_r),
            k_r: DenseJson::from(&rom.k_r),
            s_r: DenseJson::from(&rom.s_r),
            c_r: rom.c_r.as_ref().map(DenseJson::from),
            d_r: rom.d_r.as_ref().map(DenseJson::from),
            b_r: DenseJson::from(&rom.b_r),
            sb_r: DenseJson::from(&rom.sb_r),
            range: rom.range,
        }
    }

    /// The model, or None when a matrix has the wrong shape.
    fn to_model(&self) -> Option<ReducedModel> {
        let n = self.n_r;
        let sq = |d: &DenseJson| d.to_mat().filter(|m| m.nrows() == n && m.ncols() == n);
        let tall = |d: &DenseJson| {
            d.to_mat()
                .filter(|m| m.nrows() == n && m.ncols() == self.n_out)
        };
        let opt = |d: &Option<DenseJson>| match d {
            None => Some(None),
            Some(d) => sq(d).map(Some),
        };
        Some(ReducedModel {
            n_r: n,
            n_out: self.n_out,
            inputs: self.inputs.clone(),
            m_r: sq(&self.m_r)?,
            k_r: sq(&self.k_r)?,
            s_r: sq(&self.s_r)?,
            c_r: opt(&self.c_r)?,
            d_r: opt(&self.d_r)?,
            b_r: tall(&self.b_r)?,
            sb_r: tall(&self.sb_r)?,
            range: self.range,
            // Not cached: only mode classification uses it (a run classifies by the points).
            m_axes_r: None,
        })
    }
}

/// Write `value` as JSON to `path` atomically ([`crate::fs_atomic`]: a temporary file named
/// for this process and call, fsynced and renamed, so two runs sharing a cache folder may save
/// the same key), creating the cache folder if needed.
fn write_atomic<T: Serialize>(path: &Path, value: &T) -> std::io::Result<()> {
    let text = serde_json::to_vec(value).map_err(std::io::Error::other)?;
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)?;
    }
    crate::fs_atomic::write_atomic_bytes(path, &text)
}

/// The cached entry at `path` if `load` reads it, else the one `build` makes, saved with
/// `save`; and whether it came from the cache. Between the first miss and the save, the
/// entry's lock (`path` with the extension `lock`, created beside it) is held exclusively: a
/// run, in this process or another, that misses the same entry meanwhile waits and then reads
/// what this one saved. Where the lock cannot be taken (a read-only folder, a file system
/// without locks) each run builds its own, as without it. The lock is released when the build
/// ends, also by an error or a panic (and by the system when a process dies).
pub fn load_or_build<T, E>(
    path: &Path,
    load: impl Fn(&Path) -> Option<T>,
    build: impl FnOnce() -> Result<T, E>,
    save: impl FnOnce(&Path, &T),
) -> Result<(T, bool), E> {
    if let Some(hit) = load(path) {
        return Ok((hit, true));
    }
    let _lock = lock_entry(path);
    // Built by another run while this one waited for the lock.
    if let Some(hit) = load(path) {
        return Ok((hit, true));
    }
    let value = build()?;
    save(path, &value);
    Ok((value, false))
}

/// The exclusive lock of the entry at `path` (held while the file is open); None where it
/// cannot be taken.
fn lock_entry(path: &Path) -> Option<std::fs::File> {
    let lock = path.with_extension("lock");
    if let Some(dir) = lock.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).ok()?;
    }
    let file = std::fs::OpenOptions::new()
        .create(true)
        .truncate(false)
        .write(true)
        .open(&lock)
        .ok()?;
    file.lock().ok()?;
    Some(file)
}

/// Save a ROM and its certificate under `key` (atomic write).
pub fn save(path: &Path, key: &str, rom: &ReducedModel, cert: &Certificate) -> std::io::Result<()> {
    write_atomic(
        path,
        &RomJson {
            format: FORMAT,
            key: key.to_string(),
            model: ModelJson::from(rom),
            certificate: cert.clone(),
        },
    )
}

/// Load the ROM saved at `path` if it exists, parses and was saved under `key`; `None`
/// otherwise (a stale or damaged file is simply rebuilt).
pub fn load(path: &Path, key: &str) -> Option<(ReducedModel, Certificate)> {
    let bytes = std::fs::read(path).ok()?;
    let j: RomJson = serde_json::from_slice(&bytes).ok()?;
    if j.format != FORMAT || j.key != key {
        return None;
    }
    Some((j.model.to_model()?, j.certificate))
}

/// The certified ROM of `model` for `inputs` built with `params`, from the cache folder `dir`
/// (its entry `rom-<key>.json`) when it holds it, else the one `build` makes, saved there
/// ([`load_or_build`]: runs that want it at the same time build it once); and the entry it
/// was read from (None: built). Without a folder the ROM is built. A cache that cannot be
/// written costs time next run, nothing else.
pub fn certified_rom<E>(
    dir: Option<&Path>,
    model: &StructuralModel,
    inputs: &[usize],
    params: &RomParams,
    build: impl FnOnce() -> Result<(ReducedModel, Certificate), E>,
) -> Result<((ReducedModel, Certificate), Option<std::path::PathBuf>), E> {
    let Some(dir) = dir else {
        return Ok((build()?, None));
    };
    let key = key(model, inputs, params);
    let file = dir.join(format!("rom-{}.json", &key[..16]));
    let (rc, hit) = load_or_build(
        &file,
        |f| load(f, &key),
        build,
        |f, rc| {
            let _ = save(f, &key, &rc.0, &rc.1);
        },
    )?;
    Ok((rc, hit.then_some(file)))
}

/// The cache key of a ROM with terms ([`crate::rom::term_build::build_term_rom`]): the plain ROM's
/// [`key`] plus every term (name, matrix, coefficient, map, enrichment and certificate values)
/// and the settings the plain key leaves out (the certificate's reference solver, the
/// compression).
pub fn term_key(
    model: &StructuralModel,
    inputs: &[usize],
    params: &RomParams,
    specs: &[TermSpec],
) -> String {
    let mut h = Sha256::new();
    h.update(b"terms");
    h.update(key(model, inputs, params).as_bytes());
    let f = |h: &mut Sha256, x: f64| h.update(x.to_bits().to_le_bytes());
    for s in specs {
        h.update(b"T");
        h.update(s.name.as_bytes());
        hash_sp(&mut h, "G", Some(&s.matrix));
        if let Some(held) = &s.held {
            hash_sp(&mut h, "held", Some(held));
        }
        f(&mut h, s.offset.re);
        f(&mut h, s.offset.im);
        f(&mut h, s.per_modulus);
        h.update(b"enrich");
        s.enrich_values.iter().for_each(|v| f(&mut h, *v));
        h.update(b"cert");
        s.cert_values.iter().for_each(|v| f(&mut h, *v));
        match s.map {
            TermMap::Linear => h.update(b"linear"),
            TermMap::Inertia => h.update(b"inertia"),
            TermMap::Compliance { v_ref, v_floor } => {
                // (its POD keeps the springs' null space apart: compress::pod_basis_split)
                h.update(b"compliance-split-pod");
                f(&mut h, v_ref);
                f(&mut h, v_floor);
            }
        }
    }
    // Debug of f64 is the shortest text that reads back to the same value: exact.
    h.update(format!("{:?}|{:?}", params.reference, params.compress).as_bytes());
    h.finalize().iter().map(|b| format!("{b:02x}")).collect()
}

#[derive(Serialize, Deserialize)]
struct TermRomJson {
    format: u32,
    key: String,
    model: ModelJson,
    g_r: Vec<DenseJson>,
    names: Vec<String>,
    maps: Vec<TermMap>,
    /// The held springs each compliance term replaces (TermSpec::held).
    #[serde(default)]
    g_held: Vec<Option<DenseJson>>,
    certificate: TermCertificate,
}

/// Save a ROM with terms and its certificate under `key` (atomic write).
pub fn save_terms(
    path: &Path,
    key: &str,
    rom: &TermRom,
    cert: &TermCertificate,
) -> std::io::Result<()> {
    write_atomic(
        path,
        &TermRomJson {
            format: FORMAT,
            key: key.to_string(),
            model: ModelJson::from(&rom.rom),
            g_r: rom.g_r.iter().map(DenseJson::from).collect(),
            names: rom.names.clone(),
            maps: rom.maps.clone(),
            g_held: rom
                .g_held
                .iter()
                .map(|h| h.as_ref().map(DenseJson::from))
                .collect(),
            certificate: cert.clone(),
        },
    )
}

/// Load the ROM with terms saved at `path` if it exists, parses and was saved under `key`
/// (the compliance terms' pseudo-inverses are recomputed); `None` otherwise.
pub fn load_terms(path: &Path, key: &str) -> Option<(TermRom, TermCertificate)> {
    let bytes = std::fs::read(path).ok()?;
    let j: TermRomJson = serde_json::from_slice(&bytes).ok()?;
    if j.format != FORMAT || j.key != key || j.g_r.len() != j.names.len() {
        return None;
    }
    let rom = j.model.to_model()?;
    let n = rom.n_r;
    let g_r = j
        .g_r
        .iter()
        .map(|d| d.to_mat().filter(|m| m.nrows() == n && m.ncols() == n))
        .collect::<Option<Vec<_>>>()?;
    let g_pinv = pinvs(&g_r, &j.maps);
    let g_held = if j.g_held.is_empty() {
        vec![None; g_r.len()]
    } else if j.g_held.len() == g_r.len() {
        j.g_held
            .iter()
            .map(|h| match h {
                Some(d) => d
                    .to_mat()
                    .filter(|m| m.nrows() == n && m.ncols() == n)
                    .map(Some),
                None => Some(None),
            })
            .collect::<Option<Vec<_>>>()?
    } else {
        return None;
    };
    Some((
        TermRom {
            rom,
            g_r,
            names: j.names,
            maps: j.maps,
            g_pinv,
            g_held,
            memo: Default::default(),
        },
        j.certificate,
    ))
}

#[cfg(test)]
mod tests {
    use super::load_or_build;
    use std::sync::atomic::{AtomicUsize, Ordering};

    #[test]
    fn a_missing_entry_is_built_once_by_runs_that_want_it_at_the_same_time() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("cache").join("rom-0123456789abcdef.json");
        let builds = AtomicUsize::new(0);
        let from_cache = AtomicUsize::new(0);
        std::thread::scope(|s| {
            for _ in 0..4 {
                s.spawn(|| {
                    let (value, hit) = load_or_build(
                        &path,
                        |p| std::fs::read_to_string(p).ok(),
                        || {
                            builds.fetch_add(1, Ordering::SeqCst);
                            std::thread::sleep(std::time::Duration::from_millis(200));
                            Ok::<_, String>("the entry".to_string())
                        },
                        |p, v| crate::fs_atomic::write_atomic_bytes(p, v.as_bytes()).unwrap(),
                    )
                    .unwrap();
                    assert_eq!(value, "the entry");
                    if hit {
                        from_cache.fetch_add(1, Ordering::SeqCst);
                    }
                });
            }
        });
        assert_eq!(builds.load(Ordering::SeqCst), 1, "built once");
        assert_eq!(from_cache.load(Ordering::SeqCst), 3, "read by the others");
        assert!(path.with_extension("lock").is_file());
        // A build that fails saves nothing and leaves the entry to the next run.
        let other = dir.path().join("cache").join("rom-fedcba9876543210.json");
        let failed = load_or_build(
            &other,
            |p| std::fs::read_to_string(p).ok(),
            || Err::<String, _>("no basis".to_string()),
            |_, _| unreachable!(),
        );
        assert_eq!(failed.unwrap_err(), "no basis");
        assert!(!other.exists());
    }
}
