//! FRF correlation criteria (paper eq. 38-40) and the normalised FRF sensitivity of the
//! paper's Fig. 9. All inner products use the conjugate transpose: x^H a = sum conj(x_k) a_k.
//!
//! Conventions for degenerate input (these functions return plain numbers, never panic):
//! vectors of different lengths give NaN; if either vector is identically zero the
//! criterion is undefined and 0.0 is returned.

use crate::common::C64;

/// x^H a = sum_k conj(x_k) a_k.
fn inner(x: &[C64], a: &[C64]) -> C64 {
    x.iter().zip(a).map(|(x, a)| x.conj() * a).sum()
}

/// x^H x = sum_k |x_k|^2.
fn norm2(x: &[C64]) -> f64 {
    x.iter().map(|x| x.norm_sqr()).sum()
}

/// |x^H a|^2 / ((x^H x)(a^H a)): the squared cosine shared by eq. 38 and 39.
fn assurance(x: &[C64], a: &[C64]) -> f64 {
    if x.len() != a.len() {
        return f64::NAN;
    }
    let (nx, na) = (norm2(x), norm2(a));
    if nx == 0.0 || na == 0.0 {
        return 0.0;
    }
    // Clamp the rounding excess (Cauchy-Schwarz bounds the exact value by 1).
    (inner(x, a).norm_sqr() / (nx * na)).min(1.0)
}

/// Frequency response assurance criterion, paper eq. 38:
/// FRAC(H_X, H_A) = |H_X^H H_A|^2 / ((H_X^H H_X)(H_A^H H_A)),
/// with `x` the measured and `a` the analytical FRF along the frequency axis (same lines).
/// In [0, 1]; 1 iff a = c x for some complex c != 0; symmetric in its arguments.
pub fn frac(x: &[C64], a: &[C64]) -> f64 {
    assurance(x, a)
}

/// Shape correlation coefficient at one frequency line, paper eq. 39: the same formula as
/// [`frac`] applied to the vectors of all FRFs (measured `x`, analytical `a`, matching
/// response/excitation pairs) at that line. Insensitive to a common complex scale.
pub fn scc(x: &[C64], a: &[C64]) -> f64 {
    assurance(x, a)
}

/// Amplitude correlation coefficient at one frequency line, paper eq. 40:
/// ACC = 2 |H_X^H H_A| / (H_X^H H_X + H_A^H H_A). In [0, 1]; 1 iff a = x;
/// ACC(x, c x) = 2|c| / (1 + |c|^2) for any complex c.
pub fn acc(x: &[C64], a: &[C64]) -> f64 {
    if x.len() != a.len() {
        return f64::NAN;
    }
    let (nx, na) = (norm2(x), norm2(a));
    if nx == 0.0 || na == 0.0 {
        return 0.0;
    }
    (2.0 * inner(x, a).norm() / (nx + na)).min(1.0)
}

/// FRAC of every FRF column of matrices stored as rows `[line][frf]` (measured `x`,
/// analytical `a`, same shape): element j is FRAC(x[..][j], a[..][j]) over all lines.
/// Returns NaN for a column whose shapes do not match.
pub fn frac_per_frf<R: AsRef<[C64]>>(x: &[R], a: &[R]) -> Vec<f64> {
    let n_frf = x.first().map_or(0, |r| r.as_ref().len());
    (0..n_frf)
        .map(|j| {
            if x.len() != a.len() {
                return f64::NAN;
            }
            let mut col_x = Vec::with_capacity(x.len());
            let mut col_a = Vec::with_capacity(a.len());
            for (rx, ra) in x.iter().zip(a) {
                match (rx.as_ref().get(j), ra.as_ref().get(j)) {
                    (Some(&vx), Some(&va)) => {
                        col_x.push(vx);
                        col_a.push(va);
                    }
                    _ => return f64::NAN,
                }
            }
            frac(&col_x, &col_a)
        })
        .collect()
}

/// SCC(w) curve (eq. 39) over matrices stored as rows `[line][frf]`: one value per line.
/// Lines present in only one of the matrices are dropped (the result has the shorter length).
pub fn scc_curve<R: AsRef<[C64]>>(x: &[R], a: &[R]) -> Vec<f64> {
    x.iter()
        .zip(a)
        .map(|(x, a)| scc(x.as_ref(), a.as_ref()))
        .collect()
}

/// ACC(w) curve (eq. 40) over matrices stored as rows `[line][frf]`: one value per line.
/// Lines present in only one of the matrices are dropped (the result has the shorter length).
pub fn acc_curve<R: AsRef<[C64]>>(x: &[R], a: &[R]) -> Vec<f64> {
    x.iter()
        .zip(a)
        .map(|(x, a)| acc(x.as_ref(), a.as_ref()))
        .collect()
}

/// The normalised sensitivity of one FRF, as plotted in the paper's Fig. 9:
///
/// s(w_k) = |dH(w_k)/dp| / max_l |H(w_l)|,
///
/// i.e. the amplitude of the sensitivity curve `dh` (e.g. dH'_22/dE', per line) divided
/// by the peak amplitude of the FRF `h` itself over the lines given. The result has
/// units of 1/[p] (1/Pa for dE', dE''); multiplied by a parameter value it is the
/// change of H, relative to the FRF's peak, for a 100 % change of that parameter: see
/// [`normalised_sensitivity_scaled`]. All zeros if `h` is identically zero. `dh` and
/// `h` need not have the same length (only max |h| is used).
pub fn normalised_sensitivity(dh: &[C64], h: &[C64]) -> Vec<f64> {
    let peak = h.iter().map(|v| v.norm()).fold(0.0, f64::max);
    if peak == 0.0 || !peak.is_finite() {
        return vec![0.0; dh.len()];
    }
    dh.iter().map(|d| d.norm() / peak).collect()
}

/// Dimensionless form of [`normalised_sensitivity`]: |dH/dp| |p| / max |H|, with `p_value`
/// the parameter's value (e.g. the identified E' in Pa for dH/dE', E'' for dH/dE'').
/// This is the normalisation used for the report's Fig. 9.
pub fn normalised_sensitivity_scaled(dh: &[C64], h: &[C64], p_value: f64) -> Vec<f64> {
    normalised_sensitivity(dh, h)
        .into_iter()
        .map(|s| s * p_value.abs())
        .collect()
}
