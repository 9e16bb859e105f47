//! Pencil sweep: a per-line decomposition of the reduced pencil, prepared once for a fixed
//! frequency grid, after which a sweep for any E*(w) costs O(N_f n_terms n_out n_in).
//!
//! On line w, with A(w) = -w^2 M_r + K_r + j w C_r + j D_r and the centre e0 of the declared
//! modulus box, F = A + e0 S_r. S_r is positive semi-definite with a large null space (the
//! basis's directions without adhesive strain): S_r = W W^T over its range (n_r x r). With
//! Y = F^-1 W, T = W^T Y = Q diag(lambda) Q^-1 (r x r) and d = E* - e0, Woodbury gives
//!
//!   (A + E* S_r)^-1 = F^-1 - Y Q diag(d / (1 + d lambda_k)) Q^-1 Y^T,
//!
//! and d / (1 + d lambda) = (1 - 1 / (1 + d lambda)) / lambda, so with b_k = L_k P_k,
//! L = B^T Y Q, P = Q^-1 W^T F^-1 B_in, a_k = b_k / lambda_k, nu_k = lambda_k (the nonzero
//! eigenvalues of F^-1 S_r) and H0 = B^T F^-1 B_in,
//!
//!   H_ij      =  H0_ij - sum_k a_k,ij + sum_k a_k,ij / (1 + d nu_k),
//!   dH_ij/dE' = -sum_k a_k,ij nu_k / (1 + d nu_k)^2,
//!   sh_ij     =  the same with (V^T S B)^T in place of B^T.
//!
//! Decomposing the r x r T rather than the n_r x n_r F^-1 S_r keeps S_r's null space out of
//! the eigensolver, where it is an ill-conditioned cluster at zero (a basis holding the x and
//! z directions of the points has dozens of such directions).
//!
//! Terms whose pole E = e0 - 1/nu_k lies far from the box (rho_k = |nu_k| r < rho_max, r the
//! box's half diagonal) are summed once into Taylor moments, m_0 = H0 - sum_near a_k and
//! m_p = sum_far b_k nu_k^(p-1) for p >= 1 (no division by a far term's small nu_k), so that
//! their contribution is sum_p m_p (-d)^p, with the order P chosen per line so that the
//! truncation bound sum_far |a_k| rho^(P+1) / (1 - rho) stays below `series_tol` times the
//! line's |H(e0)|. The split between explicit terms and moments minimises the per-line cost.
//! Where Q is ill-conditioned (1-norm condition estimate above `cond_max`) the line falls
//! back to a dense LU of the reduced system; such lines are counted.

use super::dense::DenseLu;
use super::reduced::ReducedModel;
use super::RomError;
use crate::common::C64;
use crate::frf::{FrfEngine, FrfError, Sweep};
use faer::linalg::evd::{evd_cplx, evd_scratch, ComputeEigenvectors};
use faer::{Mat, Par};
use rayon::prelude::*;

/// Settings of the pencil decomposition.
#[derive(Clone, Debug)]
pub struct PencilParams {
    /// Lines whose eigenvector matrix Q has a 1-norm condition estimate above this fall back
    /// to dense LU. Default 1e8.
    pub cond_max: f64,
    /// Truncation tolerance of the far-pole Taylor series, relative to max |H(e0)| of the
    /// line. Default 1e-13.
    pub series_tol: f64,
    /// Largest |nu_k| r for a term to be summed as a series. Default 0.7.
    pub rho_max: f64,
    /// Largest series order. Default 60.
    pub max_order: usize,
}

impl Default for PencilParams {
    fn default() -> Self {
        PencilParams {
            cond_max: 1e8,
            series_tol: 1e-13,
            rho_max: 0.7,
            max_order: 60,
        }
    }
}

const Z0: C64 = C64::new(0.0, 0.0);

/// The prepared decomposition of one line.
#[derive(Clone, Debug, Default)]
struct Line {
    fallback: bool,
    cond: f64,
    nu: Vec<C64>,
    /// n_near x blk residues for h and sh while the line is prepared (emptied once packed).
    a: Vec<C64>,
    s: Vec<C64>,
    /// (P+1) x blk moments for h and sh (p * blk + q while the line is prepared; entry-major,
    /// q * (P+1) + p, once packed: an entry's series is contiguous).
    mh: Vec<C64>,
    ms: Vec<C64>,
    /// The explicit terms packed for the lane kernel: n_pad = n_near rounded up to LANES,
    /// padding terms have nu = 0 and zero residues (they add exactly 0).
    n_pad: usize,
    nu_re: Vec<f64>,
    nu_im: Vec<f64>,
    /// blk x n_pad each (residue q of term k at q * n_pad + k).
    a_re: Vec<f64>,
    a_im: Vec<f64>,
    s_re: Vec<f64>,
    s_im: Vec<f64>,
}

/// Lane width of the explicit-term kernel (one AVX-512 register of f64).
const LANES: usize = 8;

impl Line {
    fn pack(&mut self, blk: usize) {
        let n = self.nu.len();
        let n_pad = n.div_ceil(LANES) * LANES;
        self.n_pad = n_pad;
        self.nu_re = vec![0.0; n_pad];
        self.nu_im = vec![0.0; n_pad];
        for k in 0..n {
            self.nu_re[k] = self.nu[k].re;
            self.nu_im[k] = self.nu[k].im;
        }
        let pk = |src: &[C64]| {
            let mut re = vec![0.0; blk * n_pad];
            let mut im = vec![0.0; blk * n_pad];
            for k in 0..n {
                for q in 0..blk {
                    re[q * n_pad + k] = src[k * blk + q].re;
                    im[q * n_pad + k] = src[k * blk + q].im;
                }
            }
            (re, im)
        };
        (self.a_re, self.a_im) = pk(&self.a);
        (self.s_re, self.s_im) = pk(&self.s);
        // Entry-major moments: a sweep of a few entries reads their series only.
        let count = self.mh.len() / blk.max(1);
        let by_entry = |src: &[C64]| {
            let mut out = vec![Z0; src.len()];
            for p in 0..count {
                for q in 0..blk {
                    out[q * count + p] = src[p * blk + q];
                }
            }
            out
        };
        self.mh = by_entry(&self.mh);
        self.ms = by_entry(&self.ms);
        // The sweep reads the packed copies only: a line of a 12-input basis holds about
        // 50 terms of 144 residues each, and the unpacked copies doubled a fine grid's
        // memory (2.4 GB for 4000 lines).
        self.a = Vec::new();
        self.s = Vec::new();
    }
}

/// Sum of the explicit terms for one line, lane-parallel over terms (fixed summation order:
/// lanes accumulate terms k = lane mod LANES, then lanes are added 0..LANES), so the result
/// does not depend on the instruction set used. acc: 6 rows of LANES per entry of `qs` (the
/// block indices computed) (h, dh, sh; re, im); dh with `with_d`, sh with `with_s` (each
/// accumulates apart, so leaving one out changes no other).
#[inline(always)]
fn near_kernel(
    line: &Line,
    qs: &[usize],
    d: C64,
    with_d: bool,
    with_s: bool,
    acc: &mut [[f64; LANES]],
) {
    // Fixed-size arrays (no slices, no aliasing between accumulators) so that every `t` loop
    // compiles to whole-register vector instructions; the arithmetic and its order are the
    // same per lane as a scalar loop would do.
    #[inline(always)]
    fn lanes(v: &[f64], o: usize) -> &[f64; LANES] {
        v[o..o + LANES].try_into().expect("LANES-wide chunk")
    }
    let n_pad = line.n_pad;
    for c in (0..n_pad).step_by(LANES) {
        let (nr, ni) = (lanes(&line.nu_re, c), lanes(&line.nu_im, c));
        let mut wr = [0.0; LANES];
        let mut wi = [0.0; LANES];
        let mut vr = [0.0; LANES];
        let mut vi = [0.0; LANES];
        for t in 0..LANES {
            let re = 1.0 + (d.re * nr[t] - d.im * ni[t]);
            let im = d.re * ni[t] + d.im * nr[t];
            let inv = 1.0 / (re * re + im * im);
            wr[t] = re * inv;
            wi[t] = -im * inv;
            let w2r = wr[t] * wr[t] - wi[t] * wi[t];
            let w2i = 2.0 * wr[t] * wi[t];
            vr[t] = nr[t] * w2r - ni[t] * w2i;
            vi[t] = nr[t] * w2i + ni[t] * w2r;
        }
        for (qq, &q) in qs.iter().enumerate() {
            let o = q * n_pad + c;
            let (ar, ai) = (lanes(&line.a_re, o), lanes(&line.a_im, o));
            let q = qq;
            let (mut hr, mut hi) = (acc[6 * q], acc[6 * q + 1]);
            for t in 0..LANES {
                hr[t] += ar[t] * wr[t] - ai[t] * wi[t];
                hi[t] += ar[t] * wi[t] + ai[t] * wr[t];
            }
            acc[6 * q] = hr;
            acc[6 * q + 1] = hi;
            if with_d {
                let (mut dr, mut di) = (acc[6 * q + 2], acc[6 * q + 3]);
                for t in 0..LANES {
                    dr[t] -= ar[t] * vr[t] - ai[t] * vi[t];
                    di[t] -= ar[t] * vi[t] + ai[t] * vr[t];
                }
                acc[6 * q + 2] = dr;
                acc[6 * q + 3] = di;
            }
            if with_s {
                let (sr, si) = (lanes(&line.s_re, o), lanes(&line.s_im, o));
                let (mut xr, mut xi) = (acc[6 * q + 4], acc[6 * q + 5]);
                for t in 0..LANES {
                    xr[t] += sr[t] * wr[t] - si[t] * wi[t];
                    xi[t] += sr[t] * wi[t] + si[t] * wr[t];
                }
                acc[6 * q + 4] = xr;
                acc[6 * q + 5] = xi;
            }
        }
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512vl,avx512dq")]
unsafe fn near_kernel_avx512(
    line: &Line,
    qs: &[usize],
    d: C64,
    with_d: bool,
    with_s: bool,
    acc: &mut [[f64; LANES]],
) {
    near_kernel(line, qs, d, with_d, with_s, acc)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn near_kernel_avx2(
    line: &Line,
    qs: &[usize],
    d: C64,
    with_d: bool,
    with_s: bool,
    acc: &mut [[f64; LANES]],
) {
    near_kernel(line, qs, d, with_d, with_s, acc)
}

/// The widest instruction set of the kernels' compiled variants that this CPU has (one
/// detection for every dispatcher below; the standard library caches it).
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy)]
enum Isa {
    Avx512,
    Avx2,
    Baseline,
}

#[cfg(target_arch = "x86_64")]
fn isa() -> Isa {
    if std::arch::is_x86_feature_detected!("avx512f")
        && std::arch::is_x86_feature_detected!("avx512vl")
        && std::arch::is_x86_feature_detected!("avx512dq")
    {
        Isa::Avx512
    } else if std::arch::is_x86_feature_detected!("avx2") {
        Isa::Avx2
    } else {
        Isa::Baseline
    }
}

/// Dispatch to the widest available instruction set (no FMA contraction is allowed in
/// Rust, so every path rounds identically).
fn near_terms(
    line: &Line,
    qs: &[usize],
    d: C64,
    with_d: bool,
    with_s: bool,
    acc: &mut [[f64; LANES]],
) {
    #[cfg(target_arch = "x86_64")]
    match isa() {
        // SAFETY: `isa` detected the required CPU features at run time.
        Isa::Avx512 => return unsafe { near_kernel_avx512(line, qs, d, with_d, with_s, acc) },
        // SAFETY: as above.
        Isa::Avx2 => return unsafe { near_kernel_avx2(line, qs, d, with_d, with_s, acc) },
        Isa::Baseline => {}
    }
    near_kernel(line, qs, d, with_d, with_s, acc)
}

/// `mh += b pw` and `ms += bs pw` entry by entry (the far terms' moments), with exactly the
/// complex arithmetic of `C64` (`b * pw` then `+`), on the widest available instruction set.
#[inline(always)]
fn add_scaled_kernel(mh: &mut [C64], ms: &mut [C64], b: &[C64], bs: &[C64], pw: C64) {
    for (m, x) in mh.iter_mut().zip(b) {
        *m += x * pw;
    }
    for (m, x) in ms.iter_mut().zip(bs) {
        *m += x * pw;
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512vl,avx512dq")]
unsafe fn add_scaled_avx512(mh: &mut [C64], ms: &mut [C64], b: &[C64], bs: &[C64], pw: C64) {
    add_scaled_kernel(mh, ms, b, bs, pw)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn add_scaled_avx2(mh: &mut [C64], ms: &mut [C64], b: &[C64], bs: &[C64], pw: C64) {
    add_scaled_kernel(mh, ms, b, bs, pw)
}

/// [`add_scaled_kernel`] (every path rounds identically, as [`near_terms`]).
fn add_scaled(mh: &mut [C64], ms: &mut [C64], b: &[C64], bs: &[C64], pw: C64) {
    #[cfg(target_arch = "x86_64")]
    match isa() {
        // SAFETY: `isa` detected the required CPU features at run time.
        Isa::Avx512 => return unsafe { add_scaled_avx512(mh, ms, b, bs, pw) },
        // SAFETY: as above.
        Isa::Avx2 => return unsafe { add_scaled_avx2(mh, ms, b, bs, pw) },
        Isa::Baseline => {}
    }
    add_scaled_kernel(mh, ms, b, bs, pw)
}

/// Right-hand sides from which a line's solves run as one blocked solve rather than one column
/// at a time: a basis with every point's three directions has about 120 directions with
/// adhesive strain, and its single-column solves (streaming the factor once per column) were
/// a third of preparing a line; the blocked solve rounds differently, so smaller bases keep
/// the column-by-column results.
const BLOCKED_SOLVE_FROM: usize = 64;

/// `lu^-1 m`: blocked from [`BLOCKED_SOLVE_FROM`] columns, else one column at a time.
fn solve_all(lu: &DenseLu, m: &Mat<C64>) -> Mat<C64> {
    let n = m.nrows();
    if m.ncols() >= BLOCKED_SOLVE_FROM {
        let mut out = m.clone();
        lu.solve_columns(&mut out);
        return out;
    }
    let mut out = Mat::<C64>::zeros(n, m.ncols());
    for j in 0..m.ncols() {
        let mut c: Vec<C64> = (0..n).map(|i| m[(i, j)]).collect();
        lu.solve(&mut c);
        for (i, v) in c.into_iter().enumerate() {
            out[(i, j)] = v;
        }
    }
    out
}

/// Entries of the block evaluated together by the far-pole series ([`series_kernel`]).
const SERIES_GROUP: usize = 4;

/// The far-pole series `sum_p m_p t^p` by Horner's rule for the block entries `qs` (with
/// `t = -d`), with `with_d` its derivative `sum_p p m_p t^(p-1)` and with `with_s` the `S H`
/// series: into `ser`, 6 values per entry of `qs` (v, dv, vs; re, im). The entries are evaluated
/// [`SERIES_GROUP`] at a time, each lane with exactly the complex arithmetic, in the order, of
/// `v = v * t + m` on one entry (Horner's chain is sequential in the order, so the lanes keep
/// the independent chains of several entries in flight instead of one).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn series_kernel(
    line: &Line,
    qs: &[usize],
    count: usize,
    t: C64,
    (with_d, with_s): (bool, bool),
    ser: &mut [f64],
) {
    const G: usize = SERIES_GROUP;
    for (g, group) in qs.chunks(G).enumerate() {
        let mut vr = [0.0; G];
        let mut vi = [0.0; G];
        let mut dr = [0.0; G];
        let mut di = [0.0; G];
        let mut sr = [0.0; G];
        let mut si = [0.0; G];
        for pp in (0..count).rev() {
            let mut mr = [0.0; G];
            let mut mi = [0.0; G];
            let mut nr = [0.0; G];
            let mut ni = [0.0; G];
            for (u, &q) in group.iter().enumerate() {
                let m = line.mh[q * count + pp];
                mr[u] = m.re;
                mi[u] = m.im;
                if with_s {
                    let m = line.ms[q * count + pp];
                    nr[u] = m.re;
                    ni[u] = m.im;
                }
            }
            if with_d {
                for u in 0..G {
                    // dv = dv * t + v (the old v)
                    let (a, b) = (dr[u] * t.re - di[u] * t.im, dr[u] * t.im + di[u] * t.re);
                    dr[u] = a + vr[u];
                    di[u] = b + vi[u];
                }
            }
            if with_s {
                for u in 0..G {
                    // vs = vs * t + ms
                    let (a, b) = (sr[u] * t.re - si[u] * t.im, sr[u] * t.im + si[u] * t.re);
                    sr[u] = a + nr[u];
                    si[u] = b + ni[u];
                }
            }
            for u in 0..G {
                // v = v * t + mh
                let (a, b) = (vr[u] * t.re - vi[u] * t.im, vr[u] * t.im + vi[u] * t.re);
                vr[u] = a + mr[u];
                vi[u] = b + mi[u];
            }
        }
        for u in 0..group.len() {
            let o = &mut ser[6 * (g * G + u)..6 * (g * G + u + 1)];
            o.copy_from_slice(&[vr[u], vi[u], dr[u], di[u], sr[u], si[u]]);
        }
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512vl,avx512dq")]
#[allow(clippy::too_many_arguments)]
unsafe fn series_kernel_avx512(
    line: &Line,
    qs: &[usize],
    count: usize,
    t: C64,
    with: (bool, bool),
    ser: &mut [f64],
) {
    series_kernel(line, qs, count, t, with, ser)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[allow(clippy::too_many_arguments)]
unsafe fn series_kernel_avx2(
    line: &Line,
    qs: &[usize],
    count: usize,
    t: C64,
    with: (bool, bool),
    ser: &mut [f64],
) {
    series_kernel(line, qs, count, t, with, ser)
}

/// [`series_kernel`] on the widest available instruction set (every path rounds identically,
/// as [`near_terms`]).
#[allow(clippy::too_many_arguments)]
fn series_terms(
    line: &Line,
    qs: &[usize],
    count: usize,
    t: C64,
    with: (bool, bool),
    ser: &mut [f64],
) {
    #[cfg(target_arch = "x86_64")]
    match isa() {
        // SAFETY: `isa` detected the required CPU features at run time.
        Isa::Avx512 => return unsafe { series_kernel_avx512(line, qs, count, t, with, ser) },
        // SAFETY: as above.
        Isa::Avx2 => return unsafe { series_kernel_avx2(line, qs, count, t, with, ser) },
        Isa::Baseline => {}
    }
    series_kernel(line, qs, count, t, with, ser)
}

/// A reduced model prepared for a fixed list of frequency lines.
#[derive(Clone, Debug)]
pub struct PencilSweep {
    rom: ReducedModel,
    omega: Vec<f64>,
    e0: C64,
    lines: Vec<Line>,
}

/// Dense complex n x n (row-major) times matrix helpers.
/// Eigenvalues of S_r at or below this fraction of its largest are its null space (the basis's
/// directions without adhesive strain): dropping them changes S_r by at most this fraction.
const S_RANK_RTOL: f64 = 1e-13;

impl ReducedModel {
    /// W (n_r x r, complex storage of a real matrix) with S_r = W W^T to [`S_RANK_RTOL`]: the
    /// eigenvectors of S_r above it scaled by the square roots of their eigenvalues.
    /// None when the eigensolver fails (every line then falls back to dense LU).
    fn s_range(&self) -> Option<Mat<C64>> {
        let n = self.n_r;
        let eig = self.s_r.self_adjoint_eigen(faer::Side::Lower).ok()?;
        let smax = (0..n).map(|i| eig.S()[i]).fold(0.0f64, f64::max);
        if !(smax.is_finite() && smax > 0.0) {
            return None;
        }
        let kept: Vec<usize> = (0..n)
            .filter(|&i| eig.S()[i] > S_RANK_RTOL * smax)
            .collect();
        Some(Mat::<C64>::from_fn(n, kept.len(), |i, c| {
            let k = kept[c];
            C64::new(eig.U()[(i, k)] * eig.S()[k].sqrt(), 0.0)
        }))
    }

    /// Decompose the reduced pencil on every line of `omega_rad_s` (in parallel; each line
    /// with sequential kernels, so the result is independent of the thread count).
    pub fn prepare(&self, omega_rad_s: &[f64]) -> Result<PencilSweep, RomError> {
        self.prepare_with(omega_rad_s, &PencilParams::default())
    }

    /// [`ReducedModel::prepare`] with explicit settings.
    pub fn prepare_with(
        &self,
        omega_rad_s: &[f64],
        params: &PencilParams,
    ) -> Result<PencilSweep, RomError> {
        if let Some(w) = omega_rad_s.iter().find(|w| !w.is_finite() || **w < 0.0) {
            return Err(RomError::Params(format!(
                "frequency lines must be finite and >= 0 rad/s; got {w}"
            )));
        }
        let e0 = self.range.centre();
        let radius = self.range.radius();
        let w = self.s_range();
        let lines: Vec<Line> = omega_rad_s
            .par_iter()
            .map(|&om| match &w {
                Some(w) => self.prepare_line(om, e0, radius, w, params),
                None => Line {
                    fallback: true,
                    cond: f64::INFINITY,
                    ..Default::default()
                },
            })
            .collect();
        Ok(PencilSweep {
            rom: self.clone(),
            omega: omega_rad_s.to_vec(),
            e0,
            lines,
        })
    }

    fn prepare_line(
        &self,
        omega: f64,
        e0: C64,
        radius: f64,
        w: &Mat<C64>,
        p: &PencilParams,
    ) -> Line {
        let fallback = Line {
            fallback: true,
            cond: f64::INFINITY,
            ..Default::default()
        };
        let n = self.n_r;
        let no = self.n_out;
        let ni = self.inputs.len();
        let blk = no * ni;
        let Some(flu) = DenseLu::factor_symmetric(n, self.z_r(omega, e0)) else {
            return fallback;
        };
        // With S_r = W W^T (its range only, `s_range`) and T = W^T F^-1 W = Q diag(lambda) Q^-1,
        // Woodbury gives (F + d W W^T)^-1 = F^-1 - Y Q diag(d / (1 + d lambda)) Q^-1 Y^T with
        // Y = F^-1 W, and d / (1 + d lambda) = (1 - 1 / (1 + d lambda)) / lambda: the nonzero
        // eigenvalues nu = lambda of F^-1 S_r with their residues, plus one constant term
        // (nu = 0) for S_r's null space, which an eigensolver of the n x n F^-1 S_r resolves
        // only as an ill-conditioned cluster at zero.
        let r = w.ncols();
        let solve_cols = |m: &Mat<C64>| -> Mat<C64> { solve_all(&flu, m) };
        let y = solve_cols(w);
        let t = {
            let t = w.transpose() * &y;
            // complex symmetric up to rounding
            Mat::<C64>::from_fn(r, r, |i, j| 0.5 * (t[(i, j)] + t[(j, i)]))
        };
        let mut lam = faer::diag::Diag::<C64>::zeros(r);
        let mut q = Mat::<C64>::zeros(r, r);
        if r > 0 {
            let req = evd_scratch::<C64>(
                r,
                ComputeEigenvectors::No,
                ComputeEigenvectors::Yes,
                Par::Seq,
                Default::default(),
            );
            let mut mem = faer::dyn_stack::MemBuffer::new(req);
            if evd_cplx(
                t.as_ref(),
                lam.as_mut(),
                None,
                Some(q.as_mut()),
                Par::Seq,
                faer::dyn_stack::MemStack::new(&mut mem),
                Default::default(),
            )
            .is_err()
            {
                return fallback;
            }
        }
        // unit columns, then Q^-1 and a 1-norm condition estimate
        let mut qr = vec![Z0; r * r];
        for k in 0..r {
            let nrm = (0..r).map(|i| q[(i, k)].norm_sqr()).sum::<f64>().sqrt();
            if !(nrm > 0.0 && nrm.is_finite()) {
                return fallback;
            }
            for i in 0..r {
                q[(i, k)] /= nrm;
                qr[i * r + k] = q[(i, k)];
            }
        }
        let mut qinv = Mat::<C64>::zeros(r, r);
        let mut cond = 1.0;
        if r > 0 {
            let Some(qlu) = DenseLu::factor(r, qr) else {
                return fallback;
            };
            qinv = solve_all(&qlu, &Mat::<C64>::identity(r, r));
            // (the moduli by their squares: the estimate is compared with `cond_max` only)
            let norm1 = |m: &Mat<C64>| {
                (0..r)
                    .map(|j| (0..r).map(|i| m[(i, j)].norm_sqr().sqrt()).sum::<f64>())
                    .fold(0.0, f64::max)
            };
            cond = norm1(&q) * norm1(&qinv);
        }
        if !(cond <= p.cond_max) {
            return Line { cond, ..fallback };
        }
        let lam: Vec<C64> = (0..r).map(|k| lam.column_vector()[k]).collect();
        if lam
            .iter()
            .any(|l| !(l.norm() > 0.0 && l.re.is_finite() && l.im.is_finite()))
        {
            return fallback;
        }
        let cplx = |m: &Mat<f64>, cols: &[usize]| {
            Mat::<C64>::from_fn(m.nrows(), cols.len(), |i, j| C64::new(m[(i, cols[j])], 0.0))
        };
        let all: Vec<usize> = (0..no).collect();
        let (b_out, sb_out) = (cplx(&self.b_r, &all), cplx(&self.sb_r, &all));
        let z_in = solve_cols(&cplx(&self.b_r, &self.inputs)); // F^-1 B_in, n x ni
        let yq = &y * &q; // the eigenvectors of F^-1 S_r, n x r
        let l_h = b_out.transpose() * &yq; // no x r
        let l_s = sb_out.transpose() * &yq;
        let pr = &qinv * (w.transpose() * &z_in); // r x ni
        let c_h = b_out.transpose() * &z_in; // H at e0, no x ni
        let c_s = sb_out.transpose() * &z_in;
        // Term k: b_k = L_k P_k (no x ni); its residue in H is a_k = b_k / nu_k, nu_k = lambda_k.
        // H(d) = [H(e0) - sum_k a_k] + sum_k a_k / (1 + d nu_k); a far term enters the series
        // as sum_{p>=1} b_k nu_k^(p-1) (-d)^p, without the division (a pole far from the box
        // has a small nu_k and a large a_k that would cancel against the constant).
        let n = r;
        let nu = lam;
        let mut b = vec![Z0; n * blk];
        let mut bs = vec![Z0; n * blk];
        for k in 0..n {
            for i in 0..no {
                let (lh, ls) = (l_h[(i, k)], l_s[(i, k)]);
                for jj in 0..ni {
                    b[k * blk + i * ni + jj] = lh * pr[(k, jj)];
                    bs[k * blk + i * ni + jj] = ls * pr[(k, jj)];
                }
            }
        }
        // scale of this line: H and sh at e0
        let max_abs = |m: &Mat<C64>| {
            (0..m.ncols())
                .flat_map(|j| (0..m.nrows()).map(move |i| (i, j)))
                .map(|(i, j)| m[(i, j)].norm())
                .fold(0.0, f64::max)
        };
        let (scale_h, scale_s) = (max_abs(&c_h), max_abs(&c_s));
        // order terms by |nu| descending (stable: ties by index)
        let nu_abs: Vec<f64> = nu.iter().map(|z| z.norm()).collect();
        let mut order: Vec<usize> = (0..n).collect();
        order.sort_by(|&i, &j| nu_abs[j].total_cmp(&nu_abs[i]).then(i.cmp(&j)));
        // |a_k| = |b_k| / |nu_k|, largest over the block: the entry found by its square, then
        // its modulus (one hypot per term instead of one per entry: with twelve inputs a
        // line's 35 000 moduli were 7 % of preparing it); by the moduli themselves where the
        // squares underflow.
        let amax = |v: &[C64], k: usize| {
            let block = &v[k * blk..(k + 1) * blk];
            let (at, sq) = block.iter().enumerate().fold((0, 0.0), |(i, m), (j, z)| {
                let s = z.norm_sqr();
                if s > m {
                    (j, s)
                } else {
                    (i, m)
                }
            });
            let largest = if sq >= f64::MIN_POSITIVE && sq.is_finite() {
                block[at].norm()
            } else {
                block.iter().map(|z| z.norm()).fold(0.0, f64::max)
            };
            largest / nu_abs[k]
        };
        // suffix sums of residue sizes in sorted order
        let mut suf_a = vec![0.0; n + 1];
        let mut suf_s = vec![0.0; n + 1];
        for t in (0..n).rev() {
            suf_a[t] = suf_a[t + 1] + amax(&b, order[t]);
            suf_s[t] = suf_s[t + 1] + amax(&bs, order[t]);
        }
        let mut best = (n, 0usize, usize::MAX); // (n_near, order P+1 count, cost)
        best.2 = 3 * n;
        for n_near in 0..n {
            let rho = nu_abs[order[n_near]] * radius;
            if rho >= p.rho_max {
                continue;
            }
            // smallest count c = P + 1 with bound * rho^c / (1 - rho) <= tol * scale
            let need = |sum: f64, scale: f64| -> Option<usize> {
                if sum == 0.0 {
                    return Some(0);
                }
                let target = p.series_tol * scale * (1.0 - rho) / sum;
                if rho == 0.0 {
                    return Some(1);
                }
                if !(target > 0.0) {
                    return None;
                }
                if target >= 1.0 {
                    return Some(1);
                }
                Some((target.ln() / rho.ln()).ceil().max(1.0) as usize)
            };
            let (Some(ch), Some(cs)) = (need(suf_a[n_near], scale_h), need(suf_s[n_near], scale_s))
            else {
                continue;
            };
            let c = ch.max(cs);
            if c > p.max_order + 1 {
                continue;
            }
            let cost = 3 * n_near + 2 * c;
            if cost < best.2 {
                best = (n_near, c, cost);
            }
        }
        let (n_near, count, _) = best;
        // the constant needs m_0 even when every term is explicit
        let count = count.max(1);
        let mut line = Line {
            fallback: false,
            cond,
            ..Default::default()
        };
        line.mh = vec![Z0; count * blk];
        line.ms = vec![Z0; count * blk];
        for i in 0..no {
            for jj in 0..ni {
                line.mh[i * ni + jj] = c_h[(i, jj)];
                line.ms[i * ni + jj] = c_s[(i, jj)];
            }
        }
        for &k in &order[..n_near] {
            let inv = nu[k].inv();
            line.nu.push(nu[k]);
            for q in 0..blk {
                let (ak, sk) = (b[k * blk + q] * inv, bs[k * blk + q] * inv);
                line.a.push(ak);
                line.s.push(sk);
                line.mh[q] -= ak;
                line.ms[q] -= sk;
            }
        }
        for &k in &order[n_near..] {
            let mut pw = C64::new(1.0, 0.0);
            for pp in 1..count {
                add_scaled(
                    &mut line.mh[pp * blk..(pp + 1) * blk],
                    &mut line.ms[pp * blk..(pp + 1) * blk],
                    &b[k * blk..(k + 1) * blk],
                    &bs[k * blk..(k + 1) * blk],
                    pw,
                );
                pw *= nu[k];
            }
        }
        line.pack(blk);
        line
    }
}

impl PencilSweep {
    /// Number of lines that fall back to dense LU (poorly conditioned eigenvectors).
    pub fn n_fallback_lines(&self) -> usize {
        self.lines.iter().filter(|l| l.fallback).count()
    }
    /// Largest condition estimate of Q (the eigenvectors of T) over the non-fallback lines.
    pub fn max_condition(&self) -> f64 {
        self.lines
            .iter()
            .filter(|l| !l.fallback)
            .map(|l| l.cond)
            .fold(0.0, f64::max)
    }
    /// Mean number of explicit (near-pole) terms and of series moments per line.
    pub fn mean_terms(&self) -> (f64, f64) {
        let blk = self.rom.n_out * self.rom.inputs.len();
        let nl = self.lines.len().max(1) as f64;
        let near = self.lines.iter().map(|l| l.nu.len()).sum::<usize>() as f64 / nl;
        let mom = self
            .lines
            .iter()
            .map(|l| l.mh.len() / blk.max(1))
            .sum::<usize>() as f64
            / nl;
        (near, mom)
    }
    /// The prepared frequency grid (rad/s).
    pub fn omega_rad_s(&self) -> &[f64] {
        &self.omega
    }
    /// Floating-point operations of one sweep (with derivatives), counted from the kernel:
    /// per explicit term 1 complex division-like reciprocal (~11 flops) + 2 complex products
    /// (12) + 3 blk complex multiply-adds (8 each); per moment 3 blk complex multiply-adds.
    pub fn flops_per_sweep(&self, with_derivatives: bool) -> f64 {
        let blk = (self.rom.n_out * self.rom.inputs.len()) as f64;
        let per_cmac = 8.0;
        self.lines
            .iter()
            .map(|l| {
                let near = l.nu.len() as f64;
                let mom = (l.mh.len() as f64) / blk.max(1.0);
                if with_derivatives {
                    near * (11.0 + 12.0 + 3.0 * blk * per_cmac) + mom * 3.0 * blk * per_cmac
                } else {
                    near * (11.0 + blk * per_cmac) + mom * blk * per_cmac
                }
            })
            .sum()
    }

    /// Line `l` at modulus `e` for the block entries `qs` (indices into the n_out x n_in
    /// row-major block), into `h` (and `dh`, `sh` when given) at the positions `slots` (one per
    /// entry of `qs`).
    #[inline]
    #[allow(clippy::too_many_arguments)]
    fn eval_line(
        &self,
        l: usize,
        e: C64,
        qs: &[usize],
        slots: &[usize],
        h: &mut [C64],
        mut dh: Option<&mut [C64]>,
        mut sh: Option<&mut [C64]>,
        acc: &mut Vec<[f64; LANES]>,
        ser: &mut Vec<f64>,
    ) -> Result<(), FrfError> {
        let line = &self.lines[l];
        let blk = self.rom.n_out * self.rom.inputs.len();
        if line.fallback {
            let [hh, dd, ss] = self.rom.lu_line(self.omega[l], e, dh.is_some())?;
            for (&k, &q) in slots.iter().zip(qs) {
                h[k] = hh[q];
                if let Some(d) = dh.as_mut() {
                    d[k] = dd[q];
                }
                if let Some(s) = sh.as_mut() {
                    s[k] = ss[q];
                }
            }
            return Ok(());
        }
        let d = e - self.e0;
        let t = -d;
        let count = line.mh.len() / blk.max(1);
        let (with_d, with_s) = (dh.is_some(), sh.is_some());
        acc.clear();
        acc.resize(6 * qs.len(), [0.0; LANES]);
        near_terms(line, qs, d, with_d, with_s, acc);
        ser.clear();
        ser.resize(6 * qs.len(), 0.0);
        series_terms(line, qs, count, t, (with_d, with_s), ser);
        let lanesum = |r: &[f64; LANES]| r.iter().fold(0.0, |a, b| a + b);
        for (k, &at) in slots.iter().enumerate() {
            let sk = &ser[6 * k..6 * k + 6];
            let (v, dv, vs) = (
                C64::new(sk[0], sk[1]),
                C64::new(sk[2], sk[3]),
                C64::new(sk[4], sk[5]),
            );
            h[at] = C64::new(lanesum(&acc[6 * k]), lanesum(&acc[6 * k + 1])) + v;
            if let Some(dd) = dh.as_mut() {
                dd[at] = C64::new(lanesum(&acc[6 * k + 2]), lanesum(&acc[6 * k + 3])) - dv;
            }
            if let Some(ss) = sh.as_mut() {
                ss[at] = C64::new(lanesum(&acc[6 * k + 4]), lanesum(&acc[6 * k + 5])) + vs;
            }
        }
        Ok(())
    }

    /// Sweep the prepared grid for the moduli E*(w_l) (one per line).
    pub fn sweep_moduli_into(
        &self,
        modulus_pa: &[C64],
        with_derivatives: bool,
        out: &mut Sweep,
    ) -> Result<(), FrfError> {
        let all: Vec<usize> = (0..self.rom.inputs.len()).collect();
        self.sweep_columns_into(modulus_pa, &all, with_derivatives, out)
    }

    /// [`PencilSweep::sweep_moduli_into`] for the input columns `cols` only (positions in the
    /// ROM's inputs): `out` has `cols.len()` inputs. A sweep's cost is proportional to the
    /// columns computed, and the likelihood of a model without masses needs the excitation's
    /// alone. Each value equals the full sweep's bit for bit.
    pub fn sweep_columns_into(
        &self,
        modulus_pa: &[C64],
        cols: &[usize],
        with_derivatives: bool,
        out: &mut Sweep,
    ) -> Result<(), FrfError> {
        self.sweep_block_into(
            modulus_pa,
            None,
            cols,
            with_derivatives,
            with_derivatives,
            out,
        )
    }

    /// [`PencilSweep::sweep_columns_into`] for the output rows `rows` only (every output when
    /// `None`), and with derivatives, `S H` only when `with_sh`: `out` keeps every output, the
    /// rows not computed hold NaN and `out.sh` is empty without `with_sh`. The cost is
    /// proportional to the entries computed: a likelihood reads H and dH/dE' at the measured
    /// outputs and the points that carry masses, a few of a basis's twelve outputs when every
    /// measured point's three directions are outputs. Each value equals the full sweep's bit for
    /// bit.
    pub fn sweep_block_into(
        &self,
        modulus_pa: &[C64],
        rows: Option<&[usize]>,
        cols: &[usize],
        with_derivatives: bool,
        with_sh: bool,
        out: &mut Sweep,
    ) -> Result<(), FrfError> {
        let with_sh = with_sh && with_derivatives;
        let nl = self.omega.len();
        if modulus_pa.len() != nl {
            return Err(FrfError::Length {
                what: "modulus_pa",
                expected: nl,
                got: modulus_pa.len(),
            });
        }
        let no = self.rom.n_out;
        let ni_all = self.rom.inputs.len();
        if let Some(&c) = cols.iter().find(|&&c| c >= ni_all) {
            return Err(FrfError::BadInput(c));
        }
        if let Some(&r) = rows.and_then(|r| r.iter().find(|&&r| r >= no)) {
            return Err(FrfError::BadInput(r));
        }
        let ni = cols.len();
        let blk = no * ni;
        // The rows computed, in increasing order; per entry its index in the ROM's block and
        // its slot in a line of `out`.
        let computed: Vec<usize> = match rows {
            Some(r) => (0..no).filter(|i| r.contains(i)).collect(),
            None => (0..no).collect(),
        };
        let qs: Vec<usize> = computed
            .iter()
            .flat_map(|&i| cols.iter().map(move |&c| i * ni_all + c))
            .collect();
        let slots: Vec<usize> = computed
            .iter()
            .flat_map(|&i| (0..ni).map(move |cc| i * ni + cc))
            .collect();
        if out.n_lines != nl
            || out.n_out != no
            || out.n_in != ni
            || out.h.len() != nl * blk
            || (with_derivatives && out.dh_de.len() != nl * blk)
            || (with_sh && out.sh.len() != nl * blk)
        {
            *out = Sweep::zeros(nl, no, ni, with_derivatives);
        }
        if !with_derivatives {
            out.dh_de.clear();
        }
        if !with_sh {
            out.sh.clear();
        }
        if computed.len() < no {
            // The rows not computed read NaN, so that a caller that reads one fails loudly.
            let nan = C64::new(f64::NAN, f64::NAN);
            for v in [&mut out.h, &mut out.dh_de, &mut out.sh] {
                for line in v.chunks_mut(blk.max(1)) {
                    for i in (0..no).filter(|i| !computed.contains(i)) {
                        line[i * ni..(i + 1) * ni].fill(nan);
                    }
                }
            }
        }
        const CHUNK: usize = 64;
        let run = |c: usize,
                   h: &mut [C64],
                   mut dh: Option<&mut [C64]>,
                   mut sh: Option<&mut [C64]>|
         -> Result<(), FrfError> {
            let l0 = c * CHUNK;
            let mut acc: Vec<[f64; LANES]> = Vec::with_capacity(6 * blk);
            let mut ser: Vec<f64> = Vec::with_capacity(6 * blk);
            for (i, hl) in h.chunks_mut(blk).enumerate() {
                let span = i * blk..(i + 1) * blk;
                self.eval_line(
                    l0 + i,
                    modulus_pa[l0 + i],
                    &qs,
                    &slots,
                    hl,
                    dh.as_deref_mut().map(|d| &mut d[span.clone()]),
                    sh.as_deref_mut().map(|s| &mut s[span]),
                    &mut acc,
                    &mut ser,
                )?;
            }
            Ok(())
        };
        if blk == 0 {
            return Ok(());
        }
        let hs = out.h.par_chunks_mut(CHUNK * blk);
        match (with_derivatives, with_sh) {
            (true, true) => hs
                .zip(out.dh_de.par_chunks_mut(CHUNK * blk))
                .zip(out.sh.par_chunks_mut(CHUNK * blk))
                .enumerate()
                .try_for_each(|(c, ((h, d), s))| run(c, h, Some(d), Some(s))),
            (true, false) => hs
                .zip(out.dh_de.par_chunks_mut(CHUNK * blk))
                .enumerate()
                .try_for_each(|(c, (h, d))| run(c, h, Some(d), None)),
            _ => hs.enumerate().try_for_each(|(c, h)| run(c, h, None, None)),
        }
    }
}

impl FrfEngine for PencilSweep {
    fn n_out(&self) -> usize {
        self.rom.n_out
    }
    fn inputs(&self) -> &[usize] {
        &self.rom.inputs
    }
    /// Only the prepared grid is accepted (bitwise equal `omega_rad_s`).
    fn sweep_into(
        &self,
        omega_rad_s: &[f64],
        modulus_pa: &[C64],
        with_derivatives: bool,
        out: &mut Sweep,
    ) -> Result<(), FrfError> {
        if omega_rad_s.len() != self.omega.len()
            || omega_rad_s
                .iter()
                .zip(&self.omega)
                .any(|(a, b)| a.to_bits() != b.to_bits())
        {
            return Err(FrfError::Other(format!(
                "this PencilSweep was prepared for a different frequency grid ({} lines); call ReducedModel::prepare with the new grid",
                self.omega.len()
            )));
        }
        self.sweep_moduli_into(modulus_pa, with_derivatives, out)
    }
}
