//! A certified ROM saved to disk, keyed by everything it depends on.
//!
//! The key is the SHA-256 of the model's matrices (M, K_b, S, C_b, D_b: pattern and values),
//! the observation points (DOFs and weights), the inputs and the ROM settings, so a cached
//! ROM is reused only for the same structure, points, band, range and tolerance; any change
//! builds and certifies a new one. The file is JSON (matrices row-major as f64 bit patterns,
//! so the round trip is exact) and is written atomically.

use super::reduced::ReducedModel;
use super::{Certificate, ModulusRange, RomParams};
use crate::fe::model::{SpMat, StructuralModel};
use faer::Mat;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use std::path::Path;

/// Bump when the file layout or the ROM algorithm changes (old files are then ignored).
const FORMAT: u32 = 1;

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
    certificate: Certificate,
}

/// Save a ROM and its certificate under `key` (atomic write).
pub fn save(path: &Path, key: &str, rom: &ReducedModel, cert: &Certificate) -> std::io::Result<()> {
    let j = RomJson {
        format: FORMAT,
        key: key.to_string(),
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
        certificate: cert.clone(),
    };
    let text = serde_json::to_vec(&j).map_err(std::io::Error::other)?;
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir)?;
    }
    let tmp = path.with_extension("json.tmp");
    std::fs::write(&tmp, text)?;
    std::fs::rename(&tmp, path)
}

/// Load the ROM saved at `path` if it exists, parses and was saved under `key`; `None`
/// otherwise (a stale or damaged file is simply rebuilt).
pub fn load(path: &Path, key: &str) -> Option<(ReducedModel, Certificate)> {
    let bytes = std::fs::read(path).ok()?;
    let j: RomJson = serde_json::from_slice(&bytes).ok()?;
    if j.format != FORMAT || j.key != key {
        return None;
    }
    let n = j.n_r;
    let sq = |d: &DenseJson| d.to_mat().filter(|m| m.nrows() == n && m.ncols() == n);
    let tall = |d: &DenseJson| {
        d.to_mat()
            .filter(|m| m.nrows() == n && m.ncols() == j.n_out)
    };
    let opt = |d: &Option<DenseJson>| match d {
        None => Some(None),
        Some(d) => sq(d).map(Some),
    };
    let rom = ReducedModel {
        n_r: n,
        n_out: j.n_out,
        inputs: j.inputs.clone(),
        m_r: sq(&j.m_r)?,
        k_r: sq(&j.k_r)?,
        s_r: sq(&j.s_r)?,
        c_r: opt(&j.c_r)?,
        d_r: opt(&j.d_r)?,
        b_r: tall(&j.b_r)?,
        sb_r: tall(&j.sb_r)?,
        range: j.range,
        // Not cached: only mode classification uses it (the runner classifies by the points).
        m_axes_r: None,
    };
    Some((rom, j.certificate))
}
