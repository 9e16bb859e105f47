//! Second-stage compression of a certified term ROM by proper orthogonal decomposition of
//! its own solutions (the offline stage of a reduced-basis method: Quarteroni, Manzoni and
//! Negri, *Reduced Basis Methods for PDEs*, 2016, ch. 6).
//!
//! The enriched basis of [`super::terms`] holds the Krylov vectors of the effect-free model
//! and of the model with every term on at a few values, each deflated against the others
//! only to `deflation_tol`: on the paper's joint with two bond strips and four inputs it is
//! 551 vectors, and every sweep is a dense LU of that size per line (14 s for the 2000 lines
//! of the measurement model's fine grid). The solutions themselves lie close to a much
//! smaller space. With `x(s) = Z_r(s)^-1 B_r` at samples `s = (w, E*, v_1 .. v_m)` of the
//! band, the certified modulus box and the terms' value ranges,
//!
//! ```text
//!   W = [Re x_o(s) / |x_o(s)|, Im x_o(s) / |x_o(s)|]_(s, o)     (n_r x 2 N n_out, real)
//!   W = U diag(sigma) Q^T,   keep U_k: sigma_i > sv_tol sigma_1
//!   M_r -> U_k^T M_r U_k,  K_r, S_r, C_r, D_r, G_k,r likewise,  B_r -> U_k^T B_r
//! ```
//!
//! a Galerkin projection of the enriched ROM (so of the full model) onto the span of its own
//! normalised solutions: each sample's solution is kept to about `sv_tol` of its norm, at
//! anti-resonances as well as at peaks. The samples are a Halton sequence (deterministic,
//! whatever the thread count). The compressed ROM is then compared with the enriched one on
//! other samples (the error relative to the largest |H| of each FRF over them) and
//! re-certified against the full model like the enriched one ([`super::term_build::build_term_rom`]);
//! when either check fails, the enriched ROM is kept.

use super::terms::{TermRom, TermSpec};
use super::{ModulusRange, RomError};
use crate::common::C64;
use crate::frf::TermCoef;
use faer::Mat;
use rayon::prelude::*;

/// Settings of the compression.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CompressParams {
    /// Training samples (w, E*, term values). Default 3000.
    pub samples: usize,
    /// Samples of the check against the enriched ROM. Default 400.
    pub check_samples: usize,
    /// Singular values kept: above this fraction of the largest. Default 1e-8.
    pub sv_tol: f64,
}

impl Default for CompressParams {
    fn default() -> Self {
        CompressParams {
            samples: 3000,
            check_samples: 400,
            sv_tol: 1e-8,
        }
    }
}

/// The `k`-th point (from 1) of the Halton sequence in prime base `b`.
fn halton(mut k: usize, b: usize) -> f64 {
    let (mut f, mut r) = (1.0, 0.0);
    while k > 0 {
        f /= b as f64;
        r += f * (k % b) as f64;
        k /= b;
    }
    r
}

const PRIMES: [usize; 12] = [2, 3, 5, 7, 11, 13, 17, 19, 23, 29, 31, 37];

/// One sample: line (rad/s), modulus and the terms' coefficients.
#[derive(Clone, Debug)]
pub(crate) struct Sample {
    pub omega: f64,
    pub modulus: C64,
    pub terms: Vec<TermCoef>,
}

/// A value of a term inside the range its specification spans: for `u` below 1/4 one of its
/// enrichment and certificate values (and 0) exactly (a compliance's rigid limit, 0, is a
/// floor of 1e-19 that no segment would reach), else a point of one of the segments between
/// them (each segment equally likely, so a compliance from 0 to 1e-9 visits every decade the
/// specification names).
fn term_value(spec: &TermSpec, u: f64) -> f64 {
    let mut v: Vec<f64> = spec
        .enrich_values
        .iter()
        .chain(&spec.cert_values)
        .copied()
        .chain(std::iter::once(0.0))
        .collect();
    v.sort_by(f64::total_cmp);
    v.dedup();
    if v.len() < 2 {
        return v[0];
    }
    if u < 0.25 {
        return v[((4.0 * u * v.len() as f64) as usize).min(v.len() - 1)];
    }
    let u = (u - 0.25) / 0.75;
    let segs = v.len() - 1;
    let x = u * segs as f64;
    let i = (x.floor() as usize).min(segs - 1);
    v[i] + (x - i as f64) * (v[i + 1] - v[i])
}

/// `n` samples from index `start` of the sequence over the band, the box (log-uniform in E'
/// and E'', E'' from zero uniform) and the terms' ranges (every term on at once, but one
/// compliance term: the shapes of the same springs are alternatives).
pub(crate) fn samples(
    band_hz: (f64, f64),
    range: ModulusRange,
    specs: &[TermSpec],
    start: usize,
    n: usize,
) -> Result<Vec<Sample>, RomError> {
    let dims = 3 + specs.len();
    if dims > PRIMES.len() {
        return Err(RomError::Params(format!(
            "compression supports at most {} terms",
            PRIMES.len() - 3
        )));
    }
    let lerp_log = |(a, b): (f64, f64), u: f64| {
        if a > 0.0 {
            a * (b / a).powf(u)
        } else {
            a + u * (b - a)
        }
    };
    let compliance: Vec<usize> = (0..specs.len())
        .filter(|&i| specs[i].map.is_compliance())
        .collect();
    Ok((start..start + n)
        .map(|k| {
            let u = |d: usize| halton(k + 1, PRIMES[d]);
            let f = band_hz.0 + u(0) * (band_hz.1 - band_hz.0);
            Sample {
                omega: std::f64::consts::TAU * f,
                modulus: C64::new(
                    lerp_log(range.e_storage_pa, u(1)),
                    lerp_log(range.e_loss_pa, u(2)),
                ),
                terms: specs
                    .iter()
                    .enumerate()
                    // (one shape of the springs at a time: sample k has the (k mod m)-th of
                    // the m compliance terms)
                    .filter(|(i, _)| match compliance.iter().position(|c| c == i) {
                        Some(j) => k % compliance.len() == j,
                        None => true,
                    })
                    .map(|(i, s)| TermCoef {
                        index: i,
                        value: term_value(s, u(3 + i)),
                        offset: s.offset,
                        per_modulus: s.per_modulus,
                    })
                    .collect(),
            }
        })
        .collect())
}

/// The reduced solutions `Z_r^-1 b_o` of every output `o` at one sample.
fn solutions(rom: &TermRom, s: &Sample) -> Result<Vec<Vec<C64>>, RomError> {
    let z = rom.assemble(s.omega, s.modulus, &s.terms, false).0;
    // (all outputs, solved in output order)
    let (x, _, _) = rom
        .rom
        .solve_line(z, s.omega, s.modulus, true)
        .map_err(|e| RomError::Factorization(e.to_string()))?;
    Ok(x)
}

/// The orthonormal basis `U_k` (n_r x k) of the normalised solutions at `train`.
pub(crate) fn pod_basis(
    rom: &TermRom,
    train: &[Sample],
    sv_tol: f64,
) -> Result<Mat<f64>, RomError> {
    Ok(leading(&snapshot_factor(rom, train, sv_tol)?, sv_tol)?.0)
}

/// Eigenvalues of a compliance term's reduced matrix below this fraction of its largest span
/// the block of [`pod_basis_split`] that the springs do not load.
pub(crate) const SPLIT_NULL_BELOW: f64 = 1e-10;

/// The POD basis of [`pod_basis`] kept apart on the two blocks of the compliance terms' reduced
/// matrix `g` (symmetric positive semi-definite; with several shapes of the springs, the sum
/// of their matrices): its near-null space `N` (eigenvalues at most
/// [`SPLIT_NULL_BELOW`] of the largest: motions the springs do not load) and its range `R`,
/// each compressed on its own (singular values above `sv_tol` of the largest of all snapshots),
/// `U = [Q_N U_N, Q_R U_R]`, returned with the number of columns of its first block.
///
/// At the rigid limit (springs 1e19 times stiffer than the structure) the reduced system is a
/// penalty method: one basis for both blocks has vectors that meet the constraint to `sv_tol`
/// instead of to rounding, and the penalty times that error squared stiffens the model (on the
/// 10 mm joint, 2.3e-3 of the peak at the rigid limit). Split, the compressed range block
/// keeps `U_R^T G U_R` positive definite, so the rigid limit sets its coordinates to zero and
/// leaves the Galerkin solution on `Q_N U_N`, which the springs do not load. The projected
/// term must then be exactly zero on that block ([`TermRom::rotated_split`]): its entries there
/// are rounding (on the paper's joint, 46 eigenvalues below 6e-16 of the largest, the next at
/// 7e-9), and the penalty would amplify them.
pub(crate) fn pod_basis_split(
    rom: &TermRom,
    train: &[Sample],
    sv_tol: f64,
    g: &Mat<f64>,
) -> Result<(Mat<f64>, usize), RomError> {
    let n = rom.rom.n_r;
    let acc = snapshot_factor(rom, train, sv_tol)?;
    let smax = acc.col_iter().map(|c| c.norm_l2()).fold(0.0_f64, f64::max);
    let (q, k_q) = split_rotation(g)?;
    let mut cols: Vec<Vec<f64>> = Vec::new();
    let mut k_null = 0;
    for null in [true, false] {
        let (lo, hi) = if null { (0, k_q) } else { (k_q, n) };
        if lo == hi {
            continue;
        }
        let qb = Mat::from_fn(n, hi - lo, |i, j| q[(i, lo + j)]);
        let wb = qb.transpose() * &acc;
        let svd = wb
            .thin_svd()
            .map_err(|e| RomError::Factorization(format!("SVD of the snapshots: {e:?}")))?;
        let sig: Vec<f64> = svd.S().column_vector().iter().copied().collect();
        let k = sig.iter().take_while(|&&s| s > sv_tol * smax).count();
        let ub = &qb * svd.U().subcols(0, k);
        cols.extend((0..k).map(|j| (0..n).map(|i| ub[(i, j)]).collect()));
        if null {
            k_null = k;
        }
    }
    if cols.is_empty() {
        return Err(RomError::Params(
            "no snapshot above the POD tolerance".into(),
        ));
    }
    Ok((Mat::from_fn(n, cols.len(), |i, j| cols[j][i]), k_null))
}

/// The eigenvectors of the compliance terms' reduced matrix `g` (symmetric positive
/// semi-definite), those of its near-null space first (eigenvalues at most
/// [`SPLIT_NULL_BELOW`] of the largest), with their number: the rotation after which
/// [`TermRom::rotated_split`] sets the terms' rounding on that block to zero.
pub(crate) fn split_rotation(g: &Mat<f64>) -> Result<(Mat<f64>, usize), RomError> {
    let n = g.nrows();
    let evd = super::basis::symmetric_part(g)
        .self_adjoint_eigen(faer::Side::Lower)
        .map_err(|e| RomError::Factorization(format!("eigenvalues of the springs' term: {e:?}")))?;
    let lam: Vec<f64> = (0..n).map(|i| evd.S()[i]).collect();
    let lmax = lam.iter().fold(0.0_f64, |a, &l| a.max(l.abs()));
    let null = |i: usize| lam[i].abs() <= SPLIT_NULL_BELOW * lmax;
    let order: Vec<usize> = (0..n)
        .filter(|&i| null(i))
        .chain((0..n).filter(|&i| !null(i)))
        .collect();
    let k_null = (0..n).filter(|&i| null(i)).count();
    let u = evd.U();
    Ok((Mat::from_fn(n, n, |i, j| u[(i, order[j])]), k_null))
}

/// `U diag(sigma)` of the normalised solutions at `train` (singular values above 1e-3
/// `sv_tol` of the largest): a factor `F` with `F F^T = W W^T` to that accuracy.
fn snapshot_factor(rom: &TermRom, train: &[Sample], sv_tol: f64) -> Result<Mat<f64>, RomError> {
    let n = rom.rom.n_r;
    // Chunks of samples, each compressed with the running basis (U diag(sigma) and the chunk
    // side by side, then a thin SVD): memory stays O(n_r x chunk).
    const CHUNK: usize = 500;
    let mut acc: Mat<f64> = Mat::zeros(n, 0);
    for chunk in train.chunks(CHUNK) {
        let sols: Vec<Vec<Vec<C64>>> = chunk
            .par_iter()
            .map(|s| solutions(rom, s))
            .collect::<Result<_, _>>()?;
        let cols: Vec<Vec<f64>> = sols
            .iter()
            .flatten()
            .flat_map(|x| {
                let norm = x.iter().map(|z| z.norm_sqr()).sum::<f64>().sqrt();
                let s = if norm > 0.0 { 1.0 / norm } else { 0.0 };
                [
                    x.iter().map(|z| z.re * s).collect::<Vec<f64>>(),
                    x.iter().map(|z| z.im * s).collect(),
                ]
            })
            .collect();
        let k0 = acc.ncols();
        let w = Mat::from_fn(n, k0 + cols.len(), |i, j| {
            if j < k0 {
                acc[(i, j)]
            } else {
                cols[j - k0][i]
            }
        });
        // Keep well below the final tolerance while accumulating.
        let (u, sig) = leading(&w, 1e-3 * sv_tol)?;
        acc = Mat::from_fn(n, u.ncols(), |i, j| u[(i, j)] * sig[j]);
    }
    Ok(acc)
}

/// The left singular vectors of `w` (and their singular values) above `rel` times the
/// largest (at least one).
fn leading(w: &Mat<f64>, rel: f64) -> Result<(Mat<f64>, Vec<f64>), RomError> {
    let svd = w
        .thin_svd()
        .map_err(|e| RomError::Factorization(format!("SVD of the snapshots: {e:?}")))?;
    let sig: Vec<f64> = svd.S().column_vector().iter().copied().collect();
    let smax = sig.first().copied().unwrap_or(0.0);
    let k = sig.iter().take_while(|&&s| s > rel * smax).count().max(1);
    let u = svd.U();
    Ok((
        Mat::from_fn(w.nrows(), k, |i, j| u[(i, j)]),
        sig[..k].to_vec(),
    ))
}

/// Largest |H_a - H_b| at `check` relative to the largest |H_b| of each FRF over them.
pub(crate) fn check_error(a: &TermRom, b: &TermRom, check: &[Sample]) -> Result<f64, RomError> {
    let hs = |rom: &TermRom| -> Result<Vec<Vec<C64>>, RomError> {
        check
            .par_iter()
            .map(|s| {
                rom.line_h(s.omega, s.modulus, &s.terms)
                    .map_err(|e| RomError::Factorization(e.to_string()))
            })
            .collect()
    };
    Ok(super::certify::worst_rel_to_peak(
        &hs(a)?.concat(),
        &hs(b)?,
        b.rom.inputs.len(),
    ))
}

/// `U^T A U` of a dense symmetric matrix.
fn congruence(a: &Mat<f64>, u: &Mat<f64>) -> Mat<f64> {
    super::basis::symmetric_part(&(u.transpose() * (a * u)))
}

impl TermRom {
    /// [`TermRom::rotated`] onto a basis of [`pod_basis_split`] whose first `k_null` columns
    /// span the compliance terms' common null space: every compliance term (and the springs it
    /// replaces) is set to zero on their rows and columns (there it is rounding).
    pub(crate) fn rotated_split(&self, u: &Mat<f64>, k_null: usize) -> TermRom {
        let mut r = self.rotated(u);
        let zero = |g: &mut Mat<f64>| {
            for i in 0..g.nrows() {
                for j in 0..k_null {
                    g[(i, j)] = 0.0;
                    g[(j, i)] = 0.0;
                }
            }
        };
        for k in self.compliance_terms() {
            zero(&mut r.g_r[k]);
            if let Some(h) = r.g_held[k].as_mut() {
                zero(h);
            }
        }
        r.g_pinv = super::terms::pinvs(&r.g_r, &r.maps);
        r
    }

    /// The Galerkin projection of this ROM onto the columns of `u` (n_r x k, orthonormal).
    pub(crate) fn rotated(&self, u: &Mat<f64>) -> TermRom {
        let r = &self.rom;
        let mut rom = r.clone();
        rom.n_r = u.ncols();
        rom.m_r = congruence(&r.m_r, u);
        rom.k_r = congruence(&r.k_r, u);
        rom.s_r = congruence(&r.s_r, u);
        rom.c_r = r.c_r.as_ref().map(|c| congruence(c, u));
        rom.d_r = r.d_r.as_ref().map(|d| congruence(d, u));
        rom.b_r = u.transpose() * &r.b_r;
        rom.sb_r = u.transpose() * &r.sb_r;
        rom.m_axes_r = r.m_axes_r.as_ref().map(|m| {
            Box::new([
                congruence(&m[0], u),
                congruence(&m[1], u),
                congruence(&m[2], u),
            ])
        });
        let g_r: Vec<Mat<f64>> = self.g_r.iter().map(|g| congruence(g, u)).collect();
        TermRom {
            rom,
            g_pinv: super::terms::pinvs(&g_r, &self.maps),
            g_r,
            names: self.names.clone(),
            maps: self.maps.clone(),
            g_held: self
                .g_held
                .iter()
                .map(|h| h.as_ref().map(|h| congruence(h, u)))
                .collect(),
            memo: Default::default(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rom::reduced::ReducedModel;
    use crate::rom::terms::TermMap;

    /// A small symmetric matrix from a seed (positive definite when `shift` is large).
    fn sym(n: usize, seed: u64, shift: f64) -> Mat<f64> {
        let mut x = seed;
        let mut next = || {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((x >> 11) as f64 / (1u64 << 53) as f64) - 0.5
        };
        let a = Mat::from_fn(n, n, |_, _| next());
        let mut s = a.transpose() * &a;
        for i in 0..n {
            s[(i, i)] += shift;
        }
        s
    }

    fn small_rom(n: usize) -> TermRom {
        let b = sym(n, 7, 0.0);
        TermRom {
            rom: ReducedModel {
                n_r: n,
                n_out: 2,
                inputs: vec![0, 1],
                m_r: sym(n, 1, 1.0),
                k_r: sym(n, 2, 50.0),
                s_r: sym(n, 3, 0.1),
                c_r: None,
                d_r: Some(sym(n, 4, 0.0)),
                b_r: Mat::from_fn(n, 2, |i, j| b[(i, j)]),
                sb_r: Mat::from_fn(n, 2, |i, j| b[(i, j + 2)]),
                range: ModulusRange::default(),
                m_axes_r: None,
            },
            g_r: vec![sym(n, 5, 0.0)],
            names: vec!["t".into()],
            maps: vec![TermMap::Linear],
            g_pinv: vec![None],
            g_held: vec![None],
            memo: Default::default(),
        }
    }

    #[test]
    fn a_full_rotation_leaves_the_receptances_unchanged_and_a_truncation_changes_them() {
        let n = 8;
        let rom = small_rom(n);
        let q = sym(n, 9, 0.0).qr().compute_Q();
        let rot = rom.rotated(&q);
        let coef = [TermCoef {
            index: 0,
            value: 0.4,
            offset: C64::new(0.0, 0.0),
            per_modulus: -1.0,
        }];
        for (w, e) in [(3.0, C64::new(2.0, 0.3)), (7.5, C64::new(0.5, 0.1))] {
            let a = rom.line_h(w, e, &coef).unwrap();
            let b = rot.line_h(w, e, &coef).unwrap();
            let scale = a.iter().map(|z| z.norm()).fold(0.0, f64::max);
            for (x, y) in a.iter().zip(&b) {
                assert!((x - y).norm() <= 1e-12 * scale, "{x} vs {y}");
            }
            // (the comparison can fail: half the basis is not the model)
            let half = rom.rotated(&Mat::from_fn(n, n / 2, |i, j| q[(i, j)]));
            let c = half.line_h(w, e, &coef).unwrap();
            let dev = a
                .iter()
                .zip(&c)
                .map(|(x, y)| (x - y).norm())
                .fold(0.0, f64::max);
            assert!(dev > 1e-6 * scale);
        }
    }

    #[test]
    fn the_pod_basis_of_a_rom_is_orthonormal_and_reproduces_the_training_solutions() {
        let n = 10;
        let rom = small_rom(n);
        let spec = TermSpec {
            name: "t".into(),
            matrix: crate::fe::model::SpMat::try_new_from_triplets(1, 1, &[]).unwrap(),
            offset: C64::new(0.0, 0.0),
            per_modulus: -1.0,
            enrich_values: vec![0.95],
            cert_values: vec![0.5],
            map: TermMap::Linear,
            held: None,
        };
        let range = ModulusRange {
            e_storage_pa: (0.5, 2.0),
            e_loss_pa: (0.05, 0.5),
        };
        let band = (0.1, 1.5);
        let train = samples(band, range, std::slice::from_ref(&spec), 0, 200).unwrap();
        let u = pod_basis(&rom, &train, 1e-10).unwrap();
        let k = u.ncols();
        assert!(k >= 2 && k <= n);
        let utu = u.transpose() * &u;
        for i in 0..k {
            for j in 0..k {
                let want = if i == j { 1.0 } else { 0.0 };
                assert!((utu[(i, j)] - want).abs() < 1e-12);
            }
        }
        let small = rom.rotated(&u);
        let check = samples(band, range, std::slice::from_ref(&spec), 200, 50).unwrap();
        assert!(check_error(&small, &rom, &check).unwrap() < 1e-8);
    }

    #[test]
    fn halton_is_the_radical_inverse() {
        assert_eq!(halton(1, 2), 0.5);
        assert_eq!(halton(2, 2), 0.25);
        assert_eq!(halton(3, 2), 0.75);
        assert!((halton(1, 3) - 1.0 / 3.0).abs() < 1e-15);
        assert!((halton(5, 3) - (2.0 / 3.0 + 1.0 / 9.0)).abs() < 1e-15);
    }

    /// A compliance term with a null space (springs that load 3 of 10 coordinates) at its rigid
    /// limit (1e19 times the structure's stiffness): a generic rotation smears the term's
    /// rounding over the null block, which the penalty amplifies; the split basis keeps the
    /// null block apart, zeroes the term there and keeps the receptances.
    #[test]
    fn the_split_basis_keeps_a_compliance_term_exact_at_its_rigid_limit() {
        let n = 10;
        let mut rom = small_rom(n);
        rom.rom.inputs = vec![0];
        // (exact zeros outside the three directions: the reference is exact at the limit)
        rom.g_r = vec![Mat::from_fn(n, n, |i, j| {
            if i == j && [2, 5, 7].contains(&i) {
                1.0 + i as f64
            } else {
                0.0
            }
        })];
        rom.maps = vec![TermMap::Compliance {
            v_ref: 1.0,
            v_floor: 1e-19,
        }];
        rom.g_pinv = super::super::terms::pinvs(&rom.g_r, &rom.maps);
        let rigid = |value: f64| {
            [TermCoef {
                index: 0,
                value,
                offset: C64::new(1.0, 0.0),
                per_modulus: 0.0,
            }]
        };
        let train: Vec<Sample> = (0..40)
            .map(|k| Sample {
                omega: 1.0 + 0.25 * k as f64,
                modulus: C64::new(1.0 + 0.05 * k as f64, 0.2),
                terms: rigid(if k % 2 == 0 { 0.0 } else { 0.1 }).to_vec(),
            })
            .collect();
        let (u, k_null) = pod_basis_split(&rom, &train, 1e-12, &rom.g_r[0]).unwrap();
        assert_eq!((u.ncols(), k_null), (n, n - 3));
        let split = rom.rotated_split(&u, k_null);
        let generic = rom.rotated(&sym(n, 9, 0.0).qr().compute_Q());
        for (w, e, v) in [
            (3.0, C64::new(2.0, 0.3), 0.0),
            (7.5, C64::new(0.5, 0.1), 0.1),
        ] {
            let a = rom.line_h(w, e, &rigid(v)).unwrap();
            let scale = a.iter().map(|z| z.norm()).fold(0.0, f64::max);
            let dev = |r: &TermRom| {
                let b = r.line_h(w, e, &rigid(v)).unwrap();
                a.iter()
                    .zip(&b)
                    .map(|(x, y)| (x - y).norm())
                    .fold(0.0, f64::max)
                    / scale
            };
            assert!(dev(&split) < 1e-9, "split: {:e} at v = {v}", dev(&split));
            if v == 0.0 {
                // (the comparison can fail: rounding of 1e-16 times a penalty of 1e19)
                assert!(dev(&generic) > 1e-6, "generic: {:e}", dev(&generic));
            }
        }
    }
}
