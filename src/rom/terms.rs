//! A reduced model with extra structural terms: effects that need new
//! matrices in the ROM (a degraded bond region, a structural damping of the beam, base
//! springs, a sensor's inertia in x, y and z).
//!
//! ```text
//!   Z(w, E*; v) = Z(w, E*) + sum_k c_k G_k,     c_k = f_k(v_k) r_k(w) (p_k + q_k E*)
//!   Z_r         = V^T Z V,   G_k,r = V^T G_k V,   X = Z_r^-1 B_r,   H_ij = b_i^T x_j
//!   dH_ij/dE'   = -x_i^T (S_r + sum_k f_k r_k q_k G_k,r) x_j
//!   dH_ij/dv_k  = -f_k'(v_k) r_k(w) (p_k + q_k E*) x_i^T G_k,r x_j   (-H_oG G_k H_Gi, reduced)
//! ```
//!
//! `f_k` is [`TermMap::f`] (the value itself, or a compliance's stiffness) and `r_k` its
//! [`TermMap::line_factor`]: 1, or `-w^2` for a mass (an inertia term's `G` is a mass matrix).
//!
//! The basis is the certified ROM's (block Krylov of (K_b + e S, M) at log-spaced e,
//! [`super::basis`]) enriched, at every enrichment level, with the Krylov vectors of the full
//! model with each term on at a few values (`TermSpec::enrich_values`: the real part of
//! `c_k G_k` added to K_b and S, the imaginary part to D_b), so that the responses of the
//! modified structure lie in V. The certificate compares the reduced receptances with the
//! full model with the same term on (`TermSpec::cert_values`; solved by one complex LU per
//! modulus and the shifted Krylov space of its lines, `rom::term_reference`) on a grid of
//! moduli x lines and enriches (deeper Krylov, more e) until the error relative to the peak
//! of each FRF is at most the tolerance, as [`super::certify::build_rom`] does for the
//! effect-free model. A sweep is a dense LU of the n_r x n_r reduced system per line (the
//! pencil path of [`super::pencil`] stays the engine of the effect-free model).
//! `sh` (b_i^T S x_j, the RFM fill) is that of the effect-free S.

use super::reduced::ReducedModel;
use super::RomError;
use crate::common::C64;
use crate::fe::model::SpMat;
use crate::frf::{FrfEngine, FrfError, Sweep, TermCoef};
use faer::Mat;
use rayon::prelude::*;

/// Column `p` of a dense matrix as a slice (faer stores columns contiguously).
fn column(a: &Mat<f64>, p: usize) -> &[f64] {
    a.col(p)
        .try_as_col_major()
        .expect("a dense matrix's columns are contiguous")
        .as_slice()
}

/// Complex columns as one real matrix `[Re X | Im X]` (n x 2m), for products with real
/// matrices as a single real matrix product.
struct SplitCols {
    ri: Mat<f64>,
    m: usize,
}

impl SplitCols {
    fn new(cols: &[&[C64]], n: usize) -> Self {
        let m = cols.len();
        let ri = Mat::from_fn(n, 2 * m, |k, c| {
            if c < m {
                cols[c][k].re
            } else {
                cols[c - m][k].im
            }
        });
        SplitCols { ri, m }
    }

    /// `A X` for a real `A` (n x n).
    fn times(&self, a: &Mat<f64>) -> SplitProduct {
        let mut out = Mat::<f64>::zeros(a.nrows(), self.ri.ncols());
        faer::linalg::matmul::matmul(
            out.as_mut(),
            faer::Accum::Replace,
            a.as_ref(),
            self.ri.as_ref(),
            1.0,
            faer::Par::Seq,
        );
        SplitProduct { ri: out, m: self.m }
    }
}

/// The product of a real matrix with [`SplitCols`], read back as complex columns.
struct SplitProduct {
    ri: Mat<f64>,
    m: usize,
}

impl SplitProduct {
    /// Entry `k` of complex column `c`.
    fn col(&self, k: usize, c: usize) -> C64 {
        C64::new(self.ri[(k, c)], self.ri[(k, self.m + c)])
    }
}

/// A compliance term's derivative is a forward difference below this fraction of `v_ref`
/// (see [`TermRom`]'s line solve) ...
pub const COMPLIANCE_FD_BELOW: f64 = 1e-2;
/// ... over this fraction of `v_ref`.
pub const COMPLIANCE_FD_STEP: f64 = 1e-4;

/// How a term's value `v` enters its coefficient: `c = f(v) (offset + per_modulus E*)`.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum TermMap {
    /// `f(v) = v`.
    #[default]
    Linear,
    /// `f(v) = 1 / max(v, v_floor) - 1 / v_ref`: `v` a compliance (e.g. of base springs,
    /// `G` their stiffness matrix per unit stiffness) over a model that already holds the
    /// term at `1 / v_ref`; `v -> 0` is the rigid limit, kept finite by `v_floor`.
    Compliance { v_ref: f64, v_floor: f64 },
    /// `f(v) = v` times `-w^2`: `v` a mass (kg) and `G` its mass matrix per unit mass (the
    /// term `-w^2 v G` of `Z = K - w^2 (M + v G)`), e.g. a sensor's inertia in x, y and z.
    Inertia,
}

impl TermMap {
    /// Whether the term is a compliance ([`TermMap::Compliance`]).
    pub fn is_compliance(&self) -> bool {
        matches!(self, TermMap::Compliance { .. })
    }
    /// The factor of the line at `omega` (rad/s) on `f(v)`: `-w^2` for an inertia term, 1
    /// for the others.
    pub fn line_factor(&self, omega: f64) -> f64 {
        match self {
            TermMap::Inertia => -omega * omega,
            _ => 1.0,
        }
    }
    /// `f(v)` at the line `omega`: `f(v) r(w)`, the factor of `(offset + per_modulus E*) G`.
    pub fn f_at(&self, v: f64, omega: f64) -> f64 {
        self.f(v) * self.line_factor(omega)
    }
    /// Its derivative in `v`, `f'(v) r(w)`.
    pub fn df_at(&self, v: f64, omega: f64) -> f64 {
        self.df(v) * self.line_factor(omega)
    }
    /// `f(v)`.
    pub fn f(&self, v: f64) -> f64 {
        match *self {
            TermMap::Linear | TermMap::Inertia => v,
            TermMap::Compliance { v_ref, v_floor } => 1.0 / v.max(v_floor) - 1.0 / v_ref,
        }
    }
    /// `df/dv` (at the floor below it).
    pub fn df(&self, v: f64) -> f64 {
        match *self {
            TermMap::Linear | TermMap::Inertia => 1.0,
            TermMap::Compliance { v_floor, .. } => -1.0 / v.max(v_floor).powi(2),
        }
    }
}

/// One extra term `c G` with `c = f(v) (offset + per_modulus E*)` ([`TermMap`]; `f(v) = v`
/// by default).
#[derive(Clone, Debug)]
pub struct TermSpec {
    /// Name (what [`FrfEngine::term_names`] returns), e.g. "bond_x0.000-0.010".
    pub name: String,
    /// G (full model, n x n, symmetric).
    pub matrix: SpMat,
    pub offset: C64,
    /// Real: a term proportional to E* scales the adhesive's stiffness.
    pub per_modulus: f64,
    /// Values v at which the basis takes the Krylov vectors of the full model with the term on.
    pub enrich_values: Vec<f64>,
    /// Values v at which the certificate compares with the full model (0 checks the effect-free
    /// model).
    pub cert_values: Vec<f64>,
    /// How v enters the coefficient.
    pub map: TermMap,
    /// A compliance term whose matrix differs from the springs the model holds at `1 / v_ref`
    /// (another shape of the same springs): those held springs, replaced by `G / v` when the
    /// term is on (`c G = G / v - H / v_ref`). None: the model holds `G` itself.
    pub held: Option<SpMat>,
}

impl TermSpec {
    pub(crate) fn coef(&self, index: usize, value: f64) -> TermCoef {
        TermCoef {
            index,
            value,
            offset: self.offset,
            per_modulus: self.per_modulus,
        }
    }
}

/// The certificate of a ROM with terms: the largest error relative to the peak of each FRF
/// over (term, value) x moduli x lines.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct TermCertificate {
    pub max_rel_error: f64,
    /// Largest error per (term name, value).
    pub per_case: Vec<(String, f64, f64)>,
    /// The basis size of the sweeps: after the compression ([`super::compress`]) when it
    /// was kept, else the enriched basis's.
    pub basis_size: usize,
    /// The enriched basis's size (before the compression).
    #[serde(default)]
    pub enriched_basis_size: usize,
    /// The compressed ROM's error against the enriched one on the check samples (None: not
    /// compressed). The compressed ROM is kept when this is at most the tolerance and it
    /// passes the certificate.
    #[serde(default)]
    pub compression_error: Option<f64>,
    pub levels: usize,
    pub n_moduli: usize,
    pub n_lines: usize,
    pub seconds_basis: f64,
    pub seconds_certify: f64,
    #[serde(default)]
    pub seconds_compress: f64,
    pub passed: bool,
    /// The full-model solver of the certificate: "shifted Krylov" (one complex LU per case and
    /// modulus, `rom::term_reference`) or "sparse LU" (at every point; empty in a
    /// certificate from before this field, made by sparse LU).
    #[serde(default)]
    pub reference: String,
    /// Shifted Krylov: the largest final relative residual of a line and the largest Krylov
    /// space (vectors) over all cases and moduli.
    #[serde(default)]
    pub reference_residual: Option<f64>,
    #[serde(default)]
    pub reference_krylov_vectors: Option<usize>,
    /// Validation points (over all cases) whose reference is a sparse-LU solve: every point
    /// with the sparse LU reference; with the shifted Krylov one those it did not resolve and
    /// those where the ROM missed its solution by more than the tolerance.
    #[serde(default)]
    pub reference_direct_points: usize,
}

/// One line of a sweep with terms: (h, dh/dE', sh, dh/dv_k per term).
type TermLine = (Vec<C64>, Vec<C64>, Vec<C64>, Vec<Vec<C64>>);

/// A reduced model with extra projected terms.
#[derive(Clone, Debug)]
pub struct TermRom {
    pub(crate) rom: ReducedModel,
    pub(crate) g_r: Vec<Mat<f64>>,
    pub(crate) names: Vec<String>,
    pub(crate) maps: Vec<TermMap>,
    /// Pseudo-inverse of `G_k,r` for compliance terms (see [`TermRom::line`]).
    pub(crate) g_pinv: Vec<Option<Mat<f64>>>,
    /// `H_k,r` of a compliance term that replaces held springs of another shape
    /// ([`TermSpec::held`]); None where the model holds `G_k` itself.
    pub(crate) g_held: Vec<Option<Mat<f64>>>,
    /// The last sweeps' results (see [`SweepMemo`]).
    pub(crate) memo: SweepMemo,
}

/// The last four sweeps of a [`TermRom`] (the data's lines and the measurement model's grid),
/// keyed by their arguments (lines, moduli, terms, derivatives). The closed loop's score tests
/// sweep the same model once per candidate (every candidate that is not a term of its own
/// leaves the sweep's arguments as they are), and a sweep with terms costs a dense LU per line.
/// A copy of the ROM starts empty.
pub(crate) type SweepMemo =
    crate::common::Recent<(Vec<f64>, Vec<C64>, Vec<TermCoef>, bool), (Sweep, Vec<Vec<C64>>), 4>;

/// Pseudo-inverse of a symmetric positive semi-definite matrix (eigenvalues below 1e-6 of
/// the largest dropped: the forces `y` it acts on carry relative errors near 1e-10, which
/// smaller eigenvalues would amplify; tests/suite/base_springs.rs: dH/dc at the rigid limit
/// within 0.3 % of a difference quotient, at 1e-11 m^3/N within 1e-7).
fn psd_pinv(g: &Mat<f64>) -> Option<Mat<f64>> {
    let n = g.nrows();
    let sym = super::basis::symmetric_part(g);
    let evd = sym.self_adjoint_eigen(faer::Side::Lower).ok()?;
    let lmax = (0..n).map(|i| evd.S()[i].abs()).fold(0.0, f64::max);
    let u = evd.U();
    let inv: Vec<f64> = (0..n)
        .map(|i| {
            let l = evd.S()[i];
            if l > 1e-6 * lmax {
                1.0 / l
            } else {
                0.0
            }
        })
        .collect();
    Some(Mat::from_fn(n, n, |i, j| {
        (0..n).map(|k| u[(i, k)] * inv[k] * u[(j, k)]).sum()
    }))
}

pub(crate) fn pinvs(g_r: &[Mat<f64>], maps: &[TermMap]) -> Vec<Option<Mat<f64>>> {
    g_r.iter()
        .zip(maps)
        .map(|(g, m)| match m {
            TermMap::Linear | TermMap::Inertia => None,
            TermMap::Compliance { .. } => psd_pinv(g),
        })
        .collect()
}

impl TermRom {
    /// Basis size n_r.
    pub fn basis_size(&self) -> usize {
        self.rom.n_r
    }
    /// The same model with fewer inputs (see [`ReducedModel::with_inputs`]).
    pub fn with_inputs(&self, inputs: &[usize]) -> Result<TermRom, RomError> {
        Ok(TermRom {
            rom: self.rom.with_inputs(inputs)?,
            g_r: self.g_r.clone(),
            names: self.names.clone(),
            maps: self.maps.clone(),
            g_pinv: self.g_pinv.clone(),
            g_held: self.g_held.clone(),
            memo: SweepMemo::default(),
        })
    }

    fn check(&self, terms: &[TermCoef]) -> Result<(), FrfError> {
        if let Some(t) = terms.iter().find(|t| t.index >= self.g_r.len()) {
            return Err(FrfError::Other(format!(
                "term index {} is not a term of the ROM ({} terms: {:?})",
                t.index,
                self.g_r.len(),
                self.names
            )));
        }
        Ok(())
    }

    /// Whether `t` is a compliance term ([`TermMap::Compliance`]).
    fn is_compliance(&self, t: &TermCoef) -> bool {
        self.maps[t.index].is_compliance()
    }

    /// The indices of the compliance terms (the shapes of the base springs).
    pub(crate) fn compliance_terms(&self) -> impl Iterator<Item = usize> + '_ {
        (0..self.maps.len()).filter(|&k| self.maps[k].is_compliance())
    }

    /// `Z_r(w, E*) + sum_k c_k G_k,r` (row-major, complex symmetric) and, when `other`, the
    /// same without the compliance terms (`z_other`, for their derivative). Linear terms are
    /// added first.
    pub(crate) fn assemble(
        &self,
        omega: f64,
        e: C64,
        terms: &[TermCoef],
        other: bool,
    ) -> (Vec<C64>, Option<Vec<C64>>) {
        let n = self.rom.n_r;
        let add = |z: &mut [C64], t: &TermCoef| {
            let c = self.maps[t.index].f_at(t.value, omega) * (t.offset + t.per_modulus * e);
            let g = &self.g_r[t.index];
            // (G symmetric: its column i, contiguous, is its row i.)
            for i in 0..n {
                let col = column(g, i);
                for j in 0..n {
                    z[i * n + j] += c * col[j];
                }
            }
        };
        let mut z = self.rom.z_r(omega, e);
        for t in terms.iter().filter(|t| !self.is_compliance(t)) {
            add(&mut z, t);
        }
        let z_other = other.then(|| z.clone());
        for t in terms.iter().filter(|t| self.is_compliance(t)) {
            match (&self.g_held[t.index], self.maps[t.index]) {
                // Another shape: G / v in place of the held H / v_ref.
                (Some(h), TermMap::Compliance { v_ref, v_floor }) => {
                    let o = t.offset + t.per_modulus * e;
                    let (a, b) = (o / t.value.max(v_floor), o / v_ref);
                    let g = &self.g_r[t.index];
                    for i in 0..n {
                        let (gc, hc) = (column(g, i), column(h, i));
                        for j in 0..n {
                            z[i * n + j] += a * gc[j] - b * hc[j];
                        }
                    }
                }
                _ => add(&mut z, t),
            }
        }
        (z, z_other)
    }

    /// The receptances of one line (n_out x n_in row-major), no derivatives.
    pub(crate) fn line_h(
        &self,
        omega: f64,
        e: C64,
        terms: &[TermCoef],
    ) -> Result<Vec<C64>, FrfError> {
        self.check(terms)?;
        Ok(self.line(omega, e, terms, false)?.0)
    }

    /// One line: (h, dh/dE', sh, dh/dv_k per term), each n_out x n_in row-major.
    fn line(
        &self,
        omega: f64,
        e: C64,
        terms: &[TermCoef],
        derivs: bool,
    ) -> Result<TermLine, FrfError> {
        let r = &self.rom;
        let n = r.n_r;
        let no = r.n_out;
        let ni = r.inputs.len();
        // Near the rigid limit (v below COMPLIANCE_FD_BELOW v_ref) a compliance term's
        // derivative is a forward difference (below), which needs no `z_other`.
        let near_rigid = |t: &TermCoef| match self.maps[t.index] {
            TermMap::Compliance { v_ref, .. } => t.value < COMPLIANCE_FD_BELOW * v_ref,
            TermMap::Linear | TermMap::Inertia => false,
        };
        let (z, z_other) = self.assemble(
            omega,
            e,
            terms,
            derivs
                && terms
                    .iter()
                    .any(|t| self.is_compliance(t) && !near_rigid(t)),
        );
        let (x, slot, h) = r.solve_line(z, omega, e, derivs)?;
        let zero = C64::new(0.0, 0.0);
        if !derivs {
            return Ok((h, Vec::new(), Vec::new(), Vec::new()));
        }
        // The products with the real symmetric reduced matrices are done for all columns at
        // once, as real matrix products on [Re X | Im X] (sequential: the lines are what runs in
        // parallel, so results do not depend on the thread count).
        let inputs_x: Vec<&[C64]> = r.inputs.iter().map(|&j| x[slot[j]].as_slice()).collect();
        let x_in = SplitCols::new(&inputs_x, n);
        // S_eff x_j = S_r x_j + sum v_k q_k G_k,r x_j
        let sx = x_in.times(&r.s_r);
        // A compliance term (c = f(v) o, f(v) = 1 / v - 1 / v_ref): its derivative
        // o x_i^T G x_j / v^2 = y_i^T G^+ y_j / o with the springs' forces
        // y = o G x / v = b - Z_other x + o H x / v_ref (H the held springs: G itself, or
        // another shape's, TermSpec::held), free of the cancellation that G x (of
        // order v) suffers near the rigid limit. (With several compliance terms each one's y would
        // need the others in Z_other: one is supported.)
        let n_compliance = terms.iter().filter(|t| self.is_compliance(t)).count();
        if n_compliance > 1 {
            return Err(FrfError::Other(
                "at most one compliance term per sweep".into(),
            ));
        }
        // Near the rigid limit the derivative is the forward difference over
        // COMPLIANCE_FD_STEP v_ref from v = 0 (below 0 the floor makes H that of 0): there
        // y^T G^+ y weighs the spring matrix's small reduced eigenvalues by their inverse, and
        // the error of y (b - Z x, amplified by the norm of Z) along them swamped the column on
        // the 5 mm joint with all points as inputs (4x the difference quotient;
        // tests/suite/base_springs.rs).
        let fd: Option<Vec<C64>> = match terms.iter().find(|t| near_rigid(t)) {
            Some(tc) => {
                let TermMap::Compliance { v_ref, .. } = self.maps[tc.index] else {
                    unreachable!("near_rigid holds only for compliance terms")
                };
                let step = COMPLIANCE_FD_STEP * v_ref;
                let shifted: Vec<TermCoef> = terms
                    .iter()
                    .map(|t| TermCoef {
                        value: if std::ptr::eq(t, tc) {
                            t.value.max(0.0) + step
                        } else {
                            t.value
                        },
                        ..*t
                    })
                    .collect();
                let (hp, _, _, _) = self.line(omega, e, &shifted, false)?;
                Some(hp.iter().zip(&h).map(|(a, b)| (a - b) / step).collect())
            }
            None => None,
        };
        let mut y: Vec<Vec<C64>> = Vec::new();
        if let (Some(zo), Some(tc)) = (&z_other, terms.iter().find(|t| self.is_compliance(t))) {
            let TermMap::Compliance { v_ref, .. } = self.maps[tc.index] else {
                unreachable!("filtered above")
            };
            // (the springs the model holds: G itself, or another shape's H)
            let g = self.g_held[tc.index]
                .as_ref()
                .unwrap_or(&self.g_r[tc.index]);
            let oc = tc.offset + tc.per_modulus * e;
            // (with derivatives every output is solved, in order: slot[c] = c)
            let all_x: Vec<&[C64]> = (0..no).map(|c| x[slot[c]].as_slice()).collect();
            let gx = SplitCols::new(&all_x, n).times(g);
            // Z_other is complex symmetric: its row-major storage is its column-major one.
            let z_o = faer::MatRef::from_column_major_slice(zo, n, n);
            let x_all = Mat::<C64>::from_fn(n, no, |k, c| all_x[c][k]);
            let mut zx = Mat::<C64>::zeros(n, no);
            faer::linalg::matmul::matmul(
                zx.as_mut(),
                faer::Accum::Replace,
                z_o,
                x_all.as_ref(),
                C64::new(1.0, 0.0),
                faer::Par::Seq,
            );
            for c in 0..no {
                let yc: Vec<C64> = (0..n)
                    .map(|p| C64::new(r.b_r[(p, c)], 0.0) - zx[(p, c)] + gx.col(p, c) * oc / v_ref)
                    .collect();
                y.push(yc);
            }
        }
        // G_k,r x_j for the terms whose derivatives use it (a modulus-dependent term's share
        // of dH/dE', or a term's own column outside the compliance paths).
        let gx: Vec<Option<SplitProduct>> = terms
            .iter()
            .map(|t| {
                let own =
                    !(self.is_compliance(t) && (fd.is_some() || self.g_pinv[t.index].is_some()));
                (t.per_modulus != 0.0 || own).then(|| x_in.times(&self.g_r[t.index]))
            })
            .collect();
        // G^+ y_j of a compliance term (no difference quotient).
        let gpy: Vec<Option<SplitProduct>> = terms
            .iter()
            .map(
                |t| match (self.is_compliance(t), &fd, &self.g_pinv[t.index]) {
                    (true, None, Some(gp)) => {
                        let y_in: Vec<&[C64]> =
                            r.inputs.iter().map(|&j| y[slot[j]].as_slice()).collect();
                        Some(SplitCols::new(&y_in, n).times(gp))
                    }
                    _ => None,
                },
            )
            .collect();
        let dot = |a: &[C64], b: &SplitProduct, jj: usize| -> C64 {
            (0..n).map(|k| a[k] * b.col(k, jj)).sum()
        };
        let mut dh = vec![zero; no * ni];
        let mut sh = vec![zero; no * ni];
        let mut dt = vec![vec![zero; no * ni]; terms.len()];
        for (jj, &j) in r.inputs.iter().enumerate() {
            let xj = &x[slot[j]];
            // S_eff x_j
            let s_eff_x: Vec<C64> = (0..n)
                .map(|k| {
                    let mut v = sx.col(k, jj);
                    for (t, g) in terms.iter().zip(&gx) {
                        if let (true, Some(g)) = (t.per_modulus != 0.0, g) {
                            v += self.maps[t.index].f_at(t.value, omega)
                                * t.per_modulus
                                * g.col(k, jj);
                        }
                    }
                    v
                })
                .collect();
            for i in 0..no {
                let xi = &x[slot[i]];
                dh[i * ni + jj] = -(0..n).map(|k| xi[k] * s_eff_x[k]).sum::<C64>();
                sh[i * ni + jj] = (0..n).map(|k| xj[k] * r.sb_r[(k, i)]).sum();
                for (k, t) in terms.iter().enumerate() {
                    if let (true, Some(d)) = (self.is_compliance(t), &fd) {
                        dt[k][i * ni + jj] = d[i * ni + jj];
                        continue;
                    }
                    if let Some(gy_j) = &gpy[k] {
                        // y_i^T G^+ y_j (times the offset: c = f(v) offset)
                        let yi = &y[slot[i]];
                        dt[k][i * ni + jj] = dot(yi, gy_j, jj) / (t.offset + t.per_modulus * e);
                        continue;
                    }
                    let dc =
                        self.maps[t.index].df_at(t.value, omega) * (t.offset + t.per_modulus * e);
                    let g = gx[k].as_ref().expect("computed for this term's own column");
                    dt[k][i * ni + jj] = -dc * dot(xi, g, jj);
                }
            }
        }
        Ok((h, dh, sh, dt))
    }

    pub(crate) fn sweep_terms_impl(
        &self,
        omega: &[f64],
        modulus: &[C64],
        terms: &[TermCoef],
        derivs: bool,
    ) -> Result<(Sweep, Vec<Vec<C64>>), FrfError> {
        crate::frf::check_line_lengths(omega, modulus)?;
        self.check(terms)?;
        let key = (omega.to_vec(), modulus.to_vec(), terms.to_vec(), derivs);
        self.memo
            .get_or_try(key, || self.sweep_lines(omega, modulus, terms, derivs))
    }

    /// [`TermRom::sweep_terms_impl`] without the memo: every line solved, in parallel.
    fn sweep_lines(
        &self,
        omega: &[f64],
        modulus: &[C64],
        terms: &[TermCoef],
        derivs: bool,
    ) -> Result<(Sweep, Vec<Vec<C64>>), FrfError> {
        let lines: Vec<_> = omega
            .par_iter()
            .zip(modulus.par_iter())
            .map(|(&w, &e)| self.line(w, e, terms, derivs))
            .collect::<Result<_, _>>()?;
        let (no, ni) = (self.rom.n_out, self.rom.inputs.len());
        let mut out = Sweep::zeros(omega.len(), no, ni, derivs);
        let blk = no * ni;
        let mut dt = if derivs {
            vec![vec![C64::new(0.0, 0.0); omega.len() * blk]; terms.len()]
        } else {
            Vec::new()
        };
        for (l, (h, dh, sh, d)) in lines.into_iter().enumerate() {
            out.h[l * blk..(l + 1) * blk].copy_from_slice(&h);
            if derivs {
                out.dh_de[l * blk..(l + 1) * blk].copy_from_slice(&dh);
                out.sh[l * blk..(l + 1) * blk].copy_from_slice(&sh);
                for (k, col) in d.into_iter().enumerate() {
                    dt[k][l * blk..(l + 1) * blk].copy_from_slice(&col);
                }
            }
        }
        Ok((out, dt))
    }
}

impl FrfEngine for TermRom {
    fn n_out(&self) -> usize {
        self.rom.n_out
    }
    fn inputs(&self) -> &[usize] {
        &self.rom.inputs
    }
    fn sweep_into(
        &self,
        omega_rad_s: &[f64],
        modulus_pa: &[C64],
        with_derivatives: bool,
        out: &mut Sweep,
    ) -> Result<(), FrfError> {
        *out = self
            .sweep_terms_impl(omega_rad_s, modulus_pa, &[], with_derivatives)?
            .0;
        Ok(())
    }
    fn term_names(&self) -> Vec<String> {
        self.names.clone()
    }
    fn sweep_terms(
        &self,
        omega_rad_s: &[f64],
        modulus_pa: &[C64],
        terms: &[TermCoef],
        with_derivatives: bool,
    ) -> Result<(Sweep, Vec<Vec<C64>>), FrfError> {
        self.sweep_terms_impl(omega_rad_s, modulus_pa, terms, with_derivatives)
    }
}

/// An effect-free engine (the pencil sweep, the full model, ...) with a [`TermRom`] for sweeps
/// with terms: plain sweeps and modes are the plain engine's (unchanged numbers), sweeps with
/// terms the term ROM's. Both must have the same points and inputs. It borrows both
/// ([`WithTerms::new`]) or owns both ([`WithTerms::owning`], for a holder whose posteriors
/// borrow one engine, such as [`crate::diagnose::prepared::Prepared`]).
pub struct WithTerms<'a> {
    plain: Held<'a, dyn FrfEngine + 'a>,
    terms: Held<'a, TermRom>,
}

/// A part of [`WithTerms`], borrowed or owned.
enum Held<'a, T: ?Sized + 'a> {
    Borrowed(&'a T),
    Owned(Box<T>),
}

impl<T: ?Sized> std::ops::Deref for Held<'_, T> {
    type Target = T;
    fn deref(&self) -> &T {
        match self {
            Held::Borrowed(t) => t,
            Held::Owned(t) => t,
        }
    }
}

impl<'a> WithTerms<'a> {
    pub fn new(plain: &'a dyn FrfEngine, terms: &'a TermRom) -> Result<Self, RomError> {
        Self::checked(Held::Borrowed(plain), Held::Borrowed(terms))
    }

    /// [`WithTerms::new`] owning the engine and the term ROM.
    pub fn owning(plain: Box<dyn FrfEngine + 'a>, terms: TermRom) -> Result<Self, RomError> {
        Self::checked(Held::Owned(plain), Held::Owned(Box::new(terms)))
    }

    fn checked(
        plain: Held<'a, dyn FrfEngine + 'a>,
        terms: Held<'a, TermRom>,
    ) -> Result<Self, RomError> {
        if plain.n_out() != terms.n_out() || plain.inputs() != terms.inputs() {
            return Err(RomError::Params(format!(
                "the term ROM has {} points and inputs {:?}; the engine {} and {:?}",
                terms.n_out(),
                terms.inputs(),
                plain.n_out(),
                plain.inputs()
            )));
        }
        Ok(WithTerms { plain, terms })
    }
}

impl FrfEngine for WithTerms<'_> {
    fn n_out(&self) -> usize {
        self.plain.n_out()
    }
    fn inputs(&self) -> &[usize] {
        self.plain.inputs()
    }
    fn sweep_into(
        &self,
        omega_rad_s: &[f64],
        modulus_pa: &[C64],
        with_derivatives: bool,
        out: &mut Sweep,
    ) -> Result<(), FrfError> {
        self.plain
            .sweep_into(omega_rad_s, modulus_pa, with_derivatives, out)
    }
    fn complex_modes(
        &self,
        modulus_pa: C64,
        n_modes: usize,
    ) -> Option<Result<Vec<crate::frf::EngineMode>, FrfError>> {
        self.plain.complex_modes(modulus_pa, n_modes)
    }
    fn term_names(&self) -> Vec<String> {
        self.terms.term_names()
    }
    /// The plain engine's narrowed sweep (without the terms): a likelihood whose effects
    /// have no term of their own evaluates the plain structure's few columns and rows.
    fn with_fewer_points(
        &self,
        inputs: &[usize],
        outputs: &[usize],
    ) -> Option<Box<dyn FrfEngine + '_>> {
        self.plain.with_fewer_points(inputs, outputs)
    }
    fn sweep_terms(
        &self,
        omega_rad_s: &[f64],
        modulus_pa: &[C64],
        terms: &[TermCoef],
        with_derivatives: bool,
    ) -> Result<(Sweep, Vec<Vec<C64>>), FrfError> {
        self.terms
            .sweep_terms_impl(omega_rad_s, modulus_pa, terms, with_derivatives)
    }
}
