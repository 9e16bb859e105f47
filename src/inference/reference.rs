//! Generalized stepping-stone (Fan, Wu, Chen, Kuo and Lewis 2011, Syst. Biol. 60(2), "Choosing
//! among partition models in Bayesian phylogenetics"): the log evidence along a path from a
//! REFERENCE density `q` close to the posterior, instead of from the prior.
//!
//! With `f(x) = L(x) p(x)` the unnormalised posterior (prior with the transform's Jacobian, in
//! the samplers' unconstrained coordinates) and `q` a normalised density on `R^d`, the path
//! `pi_beta ∝ q^(1 - beta) f^beta = q (f / q)^beta` runs from `q` (`beta = 0`) to the posterior
//! (`beta = 1`) and `Z = int f = int q (f / q)`. This is the prior-path stepping-stone of
//! [`super::stepping_stone`] for a posterior whose "prior" is `q` and whose "likelihood" is
//! `g = f / q`: [`ReferencePosterior`] is that posterior, so the ladder, the resample-move
//! populations, the replicas and their error bar are the ones already there (and validated).
//!
//! Why: from the prior, `log Z` changes by thousands of nats on the default data (the prior is
//! a decade wide in each parameter, the posterior a fraction of a per cent), so most rungs and
//! most likelihood calls go to `beta < 1e-4`, where the tempered densities are far from
//! Gaussian. From a reference that already resembles the posterior the whole path is a few
//! nats long: on a Gaussian posterior and `q` its own Gaussian widened by `w`, `log g` has
//! variance about `d (1 - 1/w^2)^2 / 2` under `q`, so two or three rungs at an effective sample
//! size of 0.8 suffice, and the estimator is unbiased for any `q` with heavier tails than the
//! posterior (it is exact for `q` equal to the posterior: `g` is then constant).
//!
//! The reference [`Reference`] is a multivariate Student-t (or a Gaussian, `nu = inf`) with
//! location `m` and scale `w^2 S`: `m`, `S` the mean and covariance of posterior draws (NUTS's or
//! TMCMC's, in the unconstrained coordinates) or the Laplace mode and covariance, `w` a widening
//! (default 1.5). Heavy tails keep `g` bounded where the posterior's tails are heavier than a
//! Gaussian's (a weakly identified parameter); the width is a trade (a narrow `q` misses mass,
//! a wide one lengthens the path).
//!
//! The draws that fit `q` are not used again: the estimate takes its randomness only from its
//! own replicas (seeded streams, see [`super::stepping_stone`]), so its error bar is honest
//! whatever `q` is; `q` only sets how small it is.

use rand::rngs::StdRng;
use rand::RngExt;
use rand_distr::{ChiSquared, Distribution, StandardNormal};

use super::sampling::SamplerError;
use super::stepping_stone::{
    stepping_stone, stepping_stone_replica, SteppingStoneParams, SteppingStoneReplica,
    SteppingStoneRun,
};
use super::{DensityError, Posterior, Progress};
use crate::linalg::dense::cholesky;

/// A multivariate Student-t (Gaussian for infinite `nu`) on `R^d`: location `mean`, scale
/// matrix `L L^T`.
#[derive(Debug, Clone, PartialEq)]
pub struct Reference {
    /// Location `m`.
    pub mean: Vec<f64>,
    /// Lower Cholesky factor (row-major `d x d`) of the scale matrix (`w^2 S`).
    pub chol: Vec<f64>,
    /// Degrees of freedom (`f64::INFINITY`: Gaussian).
    pub nu: f64,
    log_det_l: f64,
}

/// Why a reference could not be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ReferenceError {
    /// Fewer draws than needed for a covariance.
    #[error("{got} draws fit no reference density in {dim} dimensions: give at least {need}")]
    TooFewDraws {
        /// Draws given.
        got: usize,
        /// Dimension.
        dim: usize,
        /// Draws needed (`d + 2`).
        need: usize,
    },
    /// The covariance is not positive definite (collapsed draws, a singular Laplace Hessian).
    #[error("the reference covariance is not positive definite (collapsed draws or a singular Laplace Hessian)")]
    NotPositiveDefinite,
    /// A setting out of range.
    #[error("invalid reference setting {name} = {value}: {hint}")]
    Setting {
        /// The setting.
        name: &'static str,
        /// Its value.
        value: f64,
        /// What it must be.
        hint: &'static str,
    },
}

fn ln_gamma(x: f64) -> f64 {
    libm::lgamma(x)
}

impl Reference {
    /// The reference with location `mean`, covariance `cov` (row-major `d x d`) widened by
    /// `widen` in standard deviation, and `nu` degrees of freedom (`f64::INFINITY` for a
    /// Gaussian). For finite `nu > 2` the scale is chosen so that the t's covariance is the
    /// widened `cov`: scale `widen^2 cov (nu - 2) / nu`.
    pub fn new(mean: &[f64], cov: &[f64], widen: f64, nu: f64) -> Result<Self, ReferenceError> {
        let d = mean.len();
        if !(widen > 0.0 && widen.is_finite()) {
            return Err(ReferenceError::Setting {
                name: "widen",
                value: widen,
                hint: "a positive factor on the standard deviations, e.g. 1.5",
            });
        }
        if !(nu > 2.0) {
            return Err(ReferenceError::Setting {
                name: "nu",
                value: nu,
                hint: "degrees of freedom above 2 (inf for a Gaussian), e.g. 5",
            });
        }
        let f = if nu.is_finite() {
            widen * widen * (nu - 2.0) / nu
        } else {
            widen * widen
        };
        let scaled: Vec<f64> = cov.iter().map(|c| c * f).collect();
        let chol = cholesky(&scaled, d).ok_or(ReferenceError::NotPositiveDefinite)?;
        let log_det_l = (0..d).map(|i| chol[i * d + i].ln()).sum();
        Ok(Self {
            mean: mean.to_vec(),
            chol,
            nu,
            log_det_l,
        })
    }

    /// The reference fitted to draws `x[row][coordinate]` (unconstrained): their mean and
    /// covariance (divisor `n - 1`).
    pub fn from_draws(x: &[Vec<f64>], widen: f64, nu: f64) -> Result<Self, ReferenceError> {
        let n = x.len();
        let d = x.first().map_or(0, |r| r.len());
        if n < d + 2 {
            return Err(ReferenceError::TooFewDraws {
                got: n,
                dim: d,
                need: d + 2,
            });
        }
        let mut mean = vec![0.0; d];
        for r in x {
            for k in 0..d {
                mean[k] += r[k] / n as f64;
            }
        }
        let mut cov = vec![0.0; d * d];
        for r in x {
            for a in 0..d {
                for b in 0..d {
                    cov[a * d + b] += (r[a] - mean[a]) * (r[b] - mean[b]) / (n - 1) as f64;
                }
            }
        }
        Self::new(&mean, &cov, widen, nu)
    }

    /// Dimension.
    pub fn dim(&self) -> usize {
        self.mean.len()
    }

    /// `z = L^-1 (x - m)`.
    fn whiten(&self, x: &[f64]) -> Vec<f64> {
        let d = self.dim();
        let mut z = vec![0.0; d];
        for i in 0..d {
            let mut s = x[i] - self.mean[i];
            for k in 0..i {
                s -= self.chol[i * d + k] * z[k];
            }
            z[i] = s / self.chol[i * d + i];
        }
        z
    }

    /// Normalised log density at `x`, with its gradient when `grad` is given.
    pub fn log_density(&self, x: &[f64], grad: Option<&mut [f64]>) -> f64 {
        let d = self.dim();
        let z = self.whiten(x);
        let q: f64 = z.iter().map(|v| v * v).sum();
        let dd = d as f64;
        let (lp, coef) = if self.nu.is_finite() {
            let nu = self.nu;
            (
                ln_gamma(0.5 * (nu + dd))
                    - ln_gamma(0.5 * nu)
                    - 0.5 * dd * (nu * std::f64::consts::PI).ln()
                    - self.log_det_l
                    - 0.5 * (nu + dd) * (q / nu).ln_1p(),
                (nu + dd) / (nu + q),
            )
        } else {
            (
                -0.5 * dd * (2.0 * std::f64::consts::PI).ln() - self.log_det_l - 0.5 * q,
                1.0,
            )
        };
        if let Some(g) = grad {
            // d/dx (-c/2 q) with q = z'z, z = L^-1 (x - m): -coef L^-T z.
            let mut v = z.clone();
            for i in (0..d).rev() {
                let mut s = v[i];
                for k in i + 1..d {
                    s -= self.chol[k * d + i] * v[k];
                }
                v[i] = s / self.chol[i * d + i];
            }
            for (gi, vi) in g.iter_mut().zip(&v) {
                *gi = -coef * vi;
            }
        }
        lp
    }

    /// One draw.
    pub fn sample(&self, rng: &mut StdRng) -> Vec<f64> {
        let d = self.dim();
        let z: Vec<f64> = (0..d).map(|_| rng.sample(StandardNormal)).collect();
        let s = if self.nu.is_finite() {
            let c: f64 = ChiSquared::new(self.nu)
                .expect("nu > 2 was checked")
                .sample(rng);
            (self.nu / c).sqrt()
        } else {
            1.0
        };
        (0..d)
            .map(|i| self.mean[i] + s * (0..=i).map(|k| self.chol[i * d + k] * z[k]).sum::<f64>())
            .collect()
    }
}

/// The posterior seen from a reference: "prior" `q`, "likelihood" `g = L p / q`. Its evidence
/// is the evidence of `post` (see the module documentation).
pub struct ReferencePosterior<'a> {
    /// The posterior whose evidence is wanted.
    pub post: &'a dyn Posterior,
    /// The reference.
    pub q: &'a Reference,
}

impl Posterior for ReferencePosterior<'_> {
    fn dim(&self) -> usize {
        self.post.dim()
    }
    fn names(&self) -> Vec<String> {
        self.post.names()
    }
    fn log_prior(&self, x: &[f64], grad: Option<&mut [f64]>) -> f64 {
        self.q.log_density(x, grad)
    }
    fn log_likelihood(&self, x: &[f64], grad: Option<&mut [f64]>) -> Result<f64, DensityError> {
        match grad {
            None => {
                let lp = self.post.log_prior(x, None);
                if lp == f64::NEG_INFINITY {
                    return Ok(lp);
                }
                Ok(lp + self.post.log_likelihood(x, None)? - self.q.log_density(x, None))
            }
            Some(g) => {
                let d = self.dim();
                let mut gq = vec![0.0; d];
                let v = self.post.log_posterior(x, Some(g))? - self.q.log_density(x, Some(&mut gq));
                g.iter_mut().zip(&gq).for_each(|(a, b)| *a -= b);
                Ok(v)
            }
        }
    }
    fn sample_prior(&self, rng: &mut StdRng) -> Vec<f64> {
        self.q.sample(rng)
    }
    fn constrained(&self, x: &[f64]) -> Vec<f64> {
        self.post.constrained(x)
    }
}

/// The log evidence of `post` by stepping-stone from the reference `q` (replicas, ladder and
/// error bar as in [`stepping_stone`]).
pub fn reference_stepping_stone(
    post: &dyn Posterior,
    q: &Reference,
    params: &SteppingStoneParams,
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<SteppingStoneRun, SamplerError> {
    check_dim(post, q)?;
    stepping_stone(&ReferencePosterior { post, q }, params, progress)
}

/// Replica `replica` of [`reference_stepping_stone`] alone (for checkpointing callers).
pub fn reference_stepping_stone_replica(
    post: &dyn Posterior,
    q: &Reference,
    params: &SteppingStoneParams,
    replica: usize,
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<SteppingStoneReplica, SamplerError> {
    check_dim(post, q)?;
    stepping_stone_replica(&ReferencePosterior { post, q }, params, replica, progress)
}

fn check_dim(post: &dyn Posterior, q: &Reference) -> Result<(), SamplerError> {
    if q.dim() != post.dim() {
        return Err(SamplerError::StartDim {
            index: 0,
            got: q.dim(),
            dim: post.dim(),
        });
    }
    Ok(())
}

/// The result of [`importance_evidence`].
#[derive(Debug, Clone, PartialEq)]
pub struct ImportanceRun {
    /// `log mean_i w_i`, `w_i = L(x_i) p(x_i) / q(x_i)` over independent draws `x_i ~ q`.
    pub log_evidence: f64,
    /// Its delta-method standard error `sd(w) / (mean(w) sqrt(n))`: honest for independent
    /// draws when `w` has a finite variance (a reference with heavier tails than the
    /// posterior).
    pub log_evidence_se: f64,
    /// Effective sample size of the weights as a fraction of the draws.
    pub ess: f64,
    /// Likelihood evaluations (one per draw).
    pub n_loglik: u64,
}

const IS_SALT: u64 = 0x5245_4649_4d50_4f52; // "REFIMPOR"

/// The log evidence of `post` by importance sampling from the reference `q` with `n`
/// independent draws: the last step of a tempering run whose particles fitted `q` (TMCMC's
/// "final importance reweighting": its own product of stage means is the other estimate). Draw
/// `i` takes its stream from `unit_rng(seed ^ salt, i)`, so the result does not depend on the
/// thread count.
pub fn importance_evidence(
    post: &dyn Posterior,
    q: &Reference,
    n: usize,
    seed: u64,
) -> Result<ImportanceRun, SamplerError> {
    use rayon::prelude::*;
    check_dim(post, q)?;
    if n < 2 {
        return Err(SamplerError::Setting {
            name: "draws",
            value: n.to_string(),
            hint: "at least 2 (thousands for evidence)",
        });
    }
    let rp = ReferencePosterior { post, q };
    let lw: Vec<Result<f64, SamplerError>> = (0..n)
        .into_par_iter()
        .map(|i| {
            let mut rng = super::unit_rng(seed ^ IS_SALT, i as u64);
            let x = q.sample(&mut rng);
            super::sampling::eval_log_lik(&rp, &x)
        })
        .collect();
    let lw = lw.into_iter().collect::<Result<Vec<f64>, _>>()?;
    let m = lw.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if m == f64::NEG_INFINITY {
        return Err(SamplerError::AllWeightsZero {
            particles: n,
            stage: 1,
            beta: 1.0,
        });
    }
    let w: Vec<f64> = lw.iter().map(|l| (l - m).exp()).collect();
    let nf = n as f64;
    let mean = w.iter().sum::<f64>() / nf;
    let var = w.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (nf - 1.0);
    let s2: f64 = w.iter().map(|v| v * v).sum();
    Ok(ImportanceRun {
        log_evidence: m + mean.ln(),
        log_evidence_se: (var / nf).sqrt() / mean,
        ess: (nf * mean).powi(2) / s2 / nf,
        n_loglik: n as u64,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::inference::unit_rng;

    fn spd3() -> (Vec<f64>, Vec<f64>) {
        (
            vec![0.3, -1.0, 2.0],
            vec![2.0, 0.6, -0.3, 0.6, 1.0, 0.2, -0.3, 0.2, 0.5],
        )
    }

    /// Gaussian and t densities integrate to one (Monte Carlo from a wide Gaussian) and their
    /// gradients match central differences.
    #[test]
    fn reference_density_is_normalised_and_its_gradient_matches_differences() {
        let (m, c) = spd3();
        for nu in [f64::INFINITY, 5.0] {
            let q = Reference::new(&m, &c, 1.2, nu).unwrap();
            let wide = Reference::new(&m, &c, 4.0, f64::INFINITY).unwrap();
            let mut rng = unit_rng(7, 0);
            let n = 200_000;
            let mut s = 0.0;
            for _ in 0..n {
                let x = wide.sample(&mut rng);
                s += (q.log_density(&x, None) - wide.log_density(&x, None)).exp();
            }
            let integral = s / n as f64;
            assert!((integral - 1.0).abs() < 0.02, "nu {nu}: {integral}");
            let x = [0.5, -0.7, 1.4];
            let mut g = [0.0; 3];
            q.log_density(&x, Some(&mut g));
            for k in 0..3 {
                let h = 1e-6;
                let mut a = x;
                let mut b = x;
                a[k] += h;
                b[k] -= h;
                let fd = (q.log_density(&a, None) - q.log_density(&b, None)) / (2.0 * h);
                assert!((fd - g[k]).abs() < 1e-6, "nu {nu} k {k}: {fd} vs {}", g[k]);
            }
        }
    }

    /// Draws of the t have the covariance asked for (widened), and the mean.
    #[test]
    fn reference_draws_have_the_widened_covariance() {
        let (m, c) = spd3();
        let q = Reference::new(&m, &c, 1.5, 7.0).unwrap();
        let mut rng = unit_rng(3, 1);
        let xs: Vec<Vec<f64>> = (0..200_000).map(|_| q.sample(&mut rng)).collect();
        let fit = Reference::from_draws(&xs, 1.0, f64::INFINITY).unwrap();
        for k in 0..3 {
            assert!((fit.mean[k] - m[k]).abs() < 0.02, "{:?}", fit.mean);
        }
        // Compare the covariance through its Cholesky factor's diagonal.
        let want = Reference::new(&m, &c, 1.5, f64::INFINITY).unwrap();
        for i in 0..3 {
            let (a, b) = (fit.chol[i * 3 + i], want.chol[i * 3 + i]);
            assert!((a / b - 1.0).abs() < 0.03, "{i}: {a} vs {b}");
        }
    }

    #[test]
    fn bad_reference_settings_are_rejected() {
        let (m, c) = spd3();
        assert!(Reference::new(&m, &c, 0.0, 5.0).is_err());
        assert!(Reference::new(&m, &c, 1.5, 2.0).is_err());
        let bad = vec![1.0, 2.0, 0.0, 2.0, 1.0, 0.0, 0.0, 0.0, 1.0];
        assert_eq!(
            Reference::new(&m, &bad, 1.0, f64::INFINITY),
            Err(ReferenceError::NotPositiveDefinite)
        );
        assert!(matches!(
            Reference::from_draws(&vec![vec![1.0; 3]; 4], 1.0, 5.0),
            Err(ReferenceError::TooFewDraws { .. })
        ));
    }
}
