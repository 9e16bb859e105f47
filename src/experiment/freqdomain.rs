//! Frequency-domain (fast) mode: block spectra drawn from their exact Gaussian distribution.
//!
//! At each line `f_k` the DFT values `v_b = (F_b, A_0b, .., A_(m-1)b)` of block `b` of the
//! time-domain chain are jointly circular complex Gaussian (linear functionals of a Gaussian
//! process) with covariance
//! `Sigma = E[v v^H] = sum_f S_F(f) r(f) r(f)^H |W((f_k - f) T)|^2 df + diag(sigma^2) sum_n w_n^2`
//! (`r = (1, g_i exp(-j w tau_i) H_i)`, the window's spectral kernel `|W|^2`, sensor noise
//! `sigma`; see [`super::estimator::BandModel::expected`], evaluated by the trapezoid rule on a
//! fine grid). Consecutive overlapping blocks are correlated: for a smooth input spectrum
//! `E[v_b v_(b+m)^H] = rho_m Sigma` up to a phase common to all channels (which cancels in H1
//! and coherence), with `rho_m` the window's overlap correlation. The mode draws `n_averages`
//! vectors with exactly that covariance, `v = (L_R (x) L_Sigma) e` with `e` standard complex
//! Gaussian, `L_Sigma` the Cholesky factor of `Sigma` and `L_R` the banded Cholesky factor of
//! the block correlation matrix `R_(bc) = rho_|b-c|`, and forms H1 and coherence exactly as
//! the Welch estimator does.
//!
//! So the expected value is the brief's `H1_exp(f_k) = int H S_F |W|^2 df / int S_F |W|^2 df`
//! (with the same leakage bias as the time-domain mode), and the random errors follow the
//! estimator's own distribution for `n_averages` overlapping blocks (a complex Wishart-type
//! law whose first-order spread is Bendat & Piersol's `sqrt(1 - gamma^2) / (|gamma| sqrt(2 n_d))`),
//! including the coherence estimate's bias and spread: nothing is set to its expected value.
//! Leakage itself lowers the coherence at sharp peaks (e.g. gamma^2 about 0.93 at a 22 Hz
//! mode with eta 0.2 seen through a 1 s Hann window), in both modes alike.
//! Neglected: the difference of `rho_m` between a coloured and a white input spectrum
//! (second order in the spectral slope over 1/T), and the time-domain mode's wrap-around of
//! the last block (one extra correlated pair among `n_averages`).
//! Each line draws from its own seeded substream, so results do not depend on thread count.

use super::estimator::{BandModel, WelchSums};
use super::signal::{complex_normal, stream, substream};
use super::spec::{ChainParams, Layout};
use crate::common::C64;
use rayon::prelude::*;

/// Lower Cholesky factor of a Hermitian positive semi-definite matrix (`a = L L^H`); pivots
/// below `1e-14` of the largest diagonal entry give a zero column (rank-deficient covariance,
/// e.g. noise-free channels).
pub(crate) fn cholesky_psd(a: &[Vec<C64>]) -> Vec<Vec<C64>> {
    let n = a.len();
    let tol = 1e-14
        * a.iter()
            .enumerate()
            .map(|(i, r)| r[i].re)
            .fold(0.0, f64::max);
    let mut l = vec![vec![C64::new(0.0, 0.0); n]; n];
    for j in 0..n {
        let d = a[j][j].re - (0..j).map(|k| l[j][k].norm_sqr()).sum::<f64>();
        if d <= tol {
            continue;
        }
        let s = d.sqrt();
        l[j][j] = C64::new(s, 0.0);
        for i in j + 1..n {
            let v = a[i][j] - (0..j).map(|k| l[i][k] * l[j][k].conj()).sum::<C64>();
            l[i][j] = v / s;
        }
    }
    l
}

/// Banded Cholesky factor of the symmetric Toeplitz matrix `R_(bc) = rho_|b-c|` (zero beyond
/// `rho.len() - 1`) of size `n`: row `b` holds `L[b][b - q..=b]` (left-padded with zeros).
pub(crate) fn banded_toeplitz_cholesky(rho: &[f64], n: usize) -> Vec<Vec<f64>> {
    let q = rho.len() - 1;
    let mut l = vec![vec![0.0; q + 1]; n];
    // l[b][q - (b - c)] = L[b][c] for c in b-q..=b.
    for b in 0..n {
        for c in b.saturating_sub(q)..=b {
            let mut v = rho[b - c];
            for k in b.saturating_sub(q).max(c.saturating_sub(q))..c {
                v -= l[b][q - (b - k)] * l[c][q - (c - k)];
            }
            if c == b {
                l[b][q] = v.max(0.0).sqrt();
            } else {
                let d = l[c][q];
                l[b][q - (b - c)] = if d > 0.0 { v / d } else { 0.0 };
            }
        }
    }
    l
}

/// The expected block spectral matrix (signal part, [`BandModel::expected`]) and the
/// window-kernel average of the plain FRF at every line of `layout`, in parallel.
pub(crate) fn line_expectations(
    band: &BandModel,
    chain: &ChainParams,
    layout: &Layout,
) -> Vec<(Vec<Vec<C64>>, Vec<C64>)> {
    let df = 1.0 / chain.block_s;
    layout
        .line_bins
        .par_iter()
        .map(|&k| {
            band.expected(
                k as f64 * df,
                chain.window,
                layout.n_block,
                chain.block_s,
                chain.kernel.half_width_hz,
            )
        })
        .collect()
}

/// Simulate the chain's block spectra at every line; returns the Welch sums per channel.
/// `noise_power` = (force, per response channel) block noise power `sigma^2 sum w^2`.
/// `expected`: every line's [`line_expectations`] (they do not depend on the noise or the
/// seed, so replicates of a level share them).
pub(crate) fn simulate(
    band: &BandModel,
    expected: &[(Vec<Vec<C64>>, Vec<C64>)],
    chain: &ChainParams,
    layout: &Layout,
    noise_power: (f64, &[f64]),
) -> Vec<WelchSums> {
    let m = band.resp.len();
    let rho = chain.window.overlap_correlation(layout.n_block, layout.hop);
    let lr = banded_toeplitz_cholesky(&rho, chain.n_averages);
    let q = rho.len() - 1;
    let per_line: Vec<(Vec<f64>, Vec<C64>, Vec<f64>)> = layout
        .line_bins
        .par_iter()
        .enumerate()
        .map(|(li, _)| {
            let mut cov = expected[li].0.clone();
            cov[0][0] += noise_power.0;
            for i in 0..m {
                cov[i + 1][i + 1] += noise_power.1[i];
            }
            let ls = cholesky_psd(&cov);
            let mut rng = substream(chain.seed, stream::FD_LINE, li as u64);
            // u_b = L_Sigma e_b, kept for the last q blocks; v_b = sum_c L_R[b][c] u_c.
            let mut hist: Vec<Vec<C64>> = vec![vec![C64::new(0.0, 0.0); m + 1]; q + 1];
            let mut e = vec![C64::new(0.0, 0.0); m + 1];
            let mut v = vec![C64::new(0.0, 0.0); m + 1];
            let (mut g_ff, mut g_fa, mut g_aa) = (0.0, vec![C64::new(0.0, 0.0); m], vec![0.0; m]);
            for lr_b in lr.iter().take(chain.n_averages) {
                e.iter_mut().for_each(|x| *x = complex_normal(&mut rng));
                hist.rotate_left(1);
                let u = &mut hist[q];
                for (a, ua) in u.iter_mut().enumerate() {
                    *ua = (0..=a).map(|c| ls[a][c] * e[c]).sum();
                }
                for (a, va) in v.iter_mut().enumerate() {
                    *va = (0..=q).map(|s| lr_b[s] * hist[s][a]).sum();
                }
                g_ff += v[0].norm_sqr();
                for i in 0..m {
                    g_fa[i] += v[0].conj() * v[i + 1];
                    g_aa[i] += v[i + 1].norm_sqr();
                }
            }
            (vec![g_ff; m], g_fa, g_aa)
        })
        .collect();
    (0..m)
        .map(|i| {
            let mut s = WelchSums::new(layout.line_bins.len());
            for (li, (ff, fa, aa)) in per_line.iter().enumerate() {
                s.g_ff[li] = ff[i];
                s.g_fa[li] = fa[i];
                s.g_aa[li] = aa[i];
            }
            s
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn banded_cholesky_reproduces_toeplitz() {
        let rho = [1.0, 0.3, -0.1];
        let n = 7;
        let l = banded_toeplitz_cholesky(&rho, n);
        let q = 2;
        let get = |b: usize, c: usize| {
            if c <= b && b - c <= q {
                l[b][q - (b - c)]
            } else {
                0.0
            }
        };
        for b in 0..n {
            for c in 0..n {
                let s: f64 = (0..n).map(|k| get(b, k) * get(c, k)).sum();
                let want = if b.abs_diff(c) <= q {
                    rho[b.abs_diff(c)]
                } else {
                    0.0
                };
                assert!((s - want).abs() < 1e-12, "({b},{c}) {s} vs {want}");
            }
        }
    }

    #[test]
    fn complex_cholesky_reproduces_matrix() {
        let a = vec![
            vec![C64::new(4.0, 0.0), C64::new(1.0, -1.0), C64::new(0.5, 0.2)],
            vec![C64::new(1.0, 1.0), C64::new(3.0, 0.0), C64::new(0.0, 0.7)],
            vec![C64::new(0.5, -0.2), C64::new(0.0, -0.7), C64::new(2.0, 0.0)],
        ];
        let l = cholesky_psd(&a);
        for i in 0..3 {
            for j in 0..3 {
                let s: C64 = (0..3).map(|k| l[i][k] * l[j][k].conj()).sum();
                assert!((s - a[i][j]).norm() < 1e-12);
            }
        }
    }
}
