//! A posterior made of component posteriors that share coordinates: the likelihood of
//! independent data sets is the product of the parts' likelihoods,
//!
//! ```text
//!   log p(x | D_1..D_m) = log pi(x) + sum_k log L_k(x[idx_k]) - log Z
//! ```
//!
//! with `idx_k` the joint coordinates part `k` sees (in its own order) and one prior `pi` over
//! the joint coordinates (a product of per-coordinate priors, so a shared coordinate's prior
//! counts once). Used for the shared-versus-separate question across excitation levels: law
//! parameters shared by both levels' likelihoods, noise coordinates per level; against
//! separate parameters the evidence ratio is `Z_shared / (Z_1 Z_2)`.
//!
//! The parts' own priors are not used (only their likelihoods), but their transforms must be
//! the joint priors' (checked at construction), so that a joint coordinate means the same
//! physical value in every part. There is no second likelihood path: the parts are the same
//! [`Posterior`]s the single-level inference samples.

use super::prior::{log_density_all, log_jacobian_all, quantile_all, to_physical_all, Prior};
use super::{DensityError, Posterior};
use rand::rngs::StdRng;

/// Errors in the layout of a joint posterior.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("joint posterior: {0}")]
pub struct JointError(pub String);

/// The sum of component posteriors' log likelihoods over shared coordinates (see the module
/// doc).
pub struct JointPosterior<'a> {
    parts: Vec<&'a dyn Posterior>,
    /// `maps[k][i]`: the joint coordinate of part `k`'s coordinate `i`.
    maps: Vec<Vec<usize>>,
    priors: Vec<Prior>,
    names: Vec<String>,
}

impl<'a> JointPosterior<'a> {
    /// `parts` with their coordinate maps into the joint vector, one prior and name per joint
    /// coordinate. Every joint coordinate must be seen by at least one part, and a part's
    /// transform to physical values must be the joint prior's for each coordinate it sees.
    pub fn new(
        parts: Vec<&'a dyn Posterior>,
        maps: Vec<Vec<usize>>,
        priors: Vec<Prior>,
        names: Vec<String>,
    ) -> Result<Self, JointError> {
        let d = priors.len();
        if names.len() != d {
            return Err(JointError(format!("{} names for {d} priors", names.len())));
        }
        if parts.len() != maps.len() || parts.is_empty() {
            return Err(JointError(format!(
                "{} parts with {} coordinate maps",
                parts.len(),
                maps.len()
            )));
        }
        let mut seen = vec![false; d];
        for (k, (p, m)) in parts.iter().zip(&maps).enumerate() {
            if m.len() != p.dim() {
                return Err(JointError(format!(
                    "part {k} has {} coordinates but its map has {}",
                    p.dim(),
                    m.len()
                )));
            }
            if let Some(j) = m.iter().find(|j| **j >= d) {
                return Err(JointError(format!(
                    "part {k} maps to coordinate {j} of {d}"
                )));
            }
            // Same transform: compare physical values at two probe points.
            for probe in [-0.7, 0.4] {
                let xj: Vec<f64> = (0..d).map(|j| probe + 0.01 * j as f64).collect();
                let xp: Vec<f64> = m.iter().map(|&j| xj[j]).collect();
                let phys = p.constrained(&xp);
                for (i, &j) in m.iter().enumerate() {
                    let a = phys[i];
                    let b = priors[j].to_physical(xj[j]);
                    if !((a - b).abs() <= 1e-9 * b.abs().max(a.abs()).max(1e-300)) {
                        return Err(JointError(format!(
                            "part {k}'s coordinate {i} maps x = {} to {a}, the joint prior of {} to {b}: give the parts the joint priors",
                            xj[j], names[j]
                        )));
                    }
                }
            }
            for &j in m {
                seen[j] = true;
            }
        }
        if let Some(j) = seen.iter().position(|s| !s) {
            return Err(JointError(format!(
                "coordinate {} ({}) is in no part",
                j, names[j]
            )));
        }
        Ok(JointPosterior {
            parts,
            maps,
            priors,
            names,
        })
    }

    /// Part `k`'s coordinates of the joint point `x`.
    pub fn part_x(&self, k: usize, x: &[f64]) -> Vec<f64> {
        self.maps[k].iter().map(|&j| x[j]).collect()
    }

    pub fn n_parts(&self) -> usize {
        self.parts.len()
    }

    pub fn priors(&self) -> &[Prior] {
        &self.priors
    }
}

impl Posterior for JointPosterior<'_> {
    fn dim(&self) -> usize {
        self.priors.len()
    }
    fn names(&self) -> Vec<String> {
        self.names.clone()
    }
    fn log_prior(&self, x: &[f64], grad: Option<&mut [f64]>) -> f64 {
        log_density_all(&self.priors, x, grad)
    }
    fn log_likelihood(&self, x: &[f64], grad: Option<&mut [f64]>) -> Result<f64, DensityError> {
        let mut total = 0.0;
        match grad {
            None => {
                for k in 0..self.parts.len() {
                    total += self.parts[k].log_likelihood(&self.part_x(k, x), None)?;
                }
            }
            Some(g) => {
                g.iter_mut().for_each(|v| *v = 0.0);
                for (k, part) in self.parts.iter().enumerate() {
                    let mut gk = vec![0.0; part.dim()];
                    total += part.log_likelihood(&self.part_x(k, x), Some(&mut gk))?;
                    for (i, &j) in self.maps[k].iter().enumerate() {
                        g[j] += gk[i];
                    }
                }
            }
        }
        Ok(total)
    }
    fn sample_prior(&self, rng: &mut StdRng) -> Vec<f64> {
        self.priors.iter().map(|p| p.sample_x(rng)).collect()
    }
    fn constrained(&self, x: &[f64]) -> Vec<f64> {
        to_physical_all(&self.priors, x)
    }
    fn log_jacobian(&self, x: &[f64], grad: Option<&mut [f64]>) -> f64 {
        log_jacobian_all(&self.priors, x, grad)
    }
    fn prior_quantile(&self, u: &[f64]) -> Vec<f64> {
        quantile_all(&self.priors, u)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::inference::map::{find_map, MapParams};

    /// Gaussian likelihood of `y_i ~ N(theta_i, s_i^2)` in physical values, coordinates
    /// through `priors` (as FrfPosterior does).
    struct Gauss {
        y: Vec<f64>,
        s: Vec<f64>,
        priors: Vec<Prior>,
    }
    impl Posterior for Gauss {
        fn dim(&self) -> usize {
            self.y.len()
        }
        fn names(&self) -> Vec<String> {
            (0..self.y.len()).map(|i| format!("t{i}")).collect()
        }
        fn log_prior(&self, x: &[f64], grad: Option<&mut [f64]>) -> f64 {
            let mut s = 0.0;
            let mut g = grad;
            for (i, (x, p)) in x.iter().zip(&self.priors).enumerate() {
                let (l, d) = p.log_density_x(*x);
                s += l;
                if let Some(g) = g.as_deref_mut() {
                    g[i] = d;
                }
            }
            s
        }
        fn log_likelihood(&self, x: &[f64], grad: Option<&mut [f64]>) -> Result<f64, DensityError> {
            let mut v = 0.0;
            let mut g = grad;
            for i in 0..x.len() {
                let t = self.priors[i].to_physical(x[i]);
                let r = (t - self.y[i]) / self.s[i];
                v += -0.5 * r * r - (self.s[i] * std::f64::consts::TAU.sqrt()).ln();
                if let Some(g) = g.as_deref_mut() {
                    g[i] = -r / self.s[i] * self.priors[i].dp_dx(x[i]);
                }
            }
            Ok(v)
        }
        fn sample_prior(&self, rng: &mut StdRng) -> Vec<f64> {
            self.priors.iter().map(|p| p.sample_x(rng)).collect()
        }
        fn constrained(&self, x: &[f64]) -> Vec<f64> {
            x.iter()
                .zip(&self.priors)
                .map(|(x, p)| p.to_physical(*x))
                .collect()
        }
        fn prior_quantile(&self, u: &[f64]) -> Vec<f64> {
            u.iter()
                .zip(&self.priors)
                .map(|(u, p)| p.quantile_x(*u))
                .collect()
        }
    }

    fn normal(mean: f64, sd: f64) -> Prior {
        Prior::TruncatedNormal {
            mean,
            sd,
            lo: mean - 40.0 * sd,
            hi: mean + 40.0 * sd,
        }
    }

    #[test]
    fn joint_likelihood_is_the_sum_of_the_parts_and_its_gradient_scatters() {
        let pa = normal(1.0, 2.0);
        let pb = Prior::LogUniform { lo: 0.1, hi: 10.0 };
        let pc = normal(-1.0, 1.0);
        // Part 1 sees (a, b), part 2 sees (c, a): a is shared.
        let p1 = Gauss {
            y: vec![0.3, 2.0],
            s: vec![0.5, 0.7],
            priors: vec![pa.clone(), pb.clone()],
        };
        let p2 = Gauss {
            y: vec![-0.5, 0.9],
            s: vec![0.4, 0.3],
            priors: vec![pc.clone(), pa.clone()],
        };
        let j = JointPosterior::new(
            vec![&p1, &p2],
            vec![vec![0, 1], vec![2, 0]],
            vec![pa, pb, pc],
            vec!["a".into(), "b".into(), "c".into()],
        )
        .unwrap();
        let x = [0.2, 0.3, -0.4];
        let l1 = p1.log_likelihood(&[0.2, 0.3], None).unwrap();
        let l2 = p2.log_likelihood(&[-0.4, 0.2], None).unwrap();
        let mut g = vec![0.0; 3];
        let lj = j.log_likelihood(&x, Some(&mut g)).unwrap();
        assert!((lj - (l1 + l2)).abs() < 1e-12);
        assert!((j.log_likelihood(&x, None).unwrap() - lj).abs() < 1e-12);
        for i in 0..3 {
            let mut xp = x;
            let mut xm = x;
            xp[i] += 1e-6;
            xm[i] -= 1e-6;
            let fd = (j.log_likelihood(&xp, None).unwrap() - j.log_likelihood(&xm, None).unwrap())
                / 2e-6;
            assert!(
                (fd - g[i]).abs() < 1e-6 * (1.0 + fd.abs()),
                "{i}: {fd} vs {}",
                g[i]
            );
        }
    }

    #[test]
    fn shared_gaussian_evidence_matches_the_closed_form() {
        // theta ~ N(0, tau^2), y1 ~ N(theta, s1^2), y2 ~ N(theta, s2^2).
        // Shared: (y1, y2) ~ N(0, [[tau^2 + s1^2, tau^2], [tau^2, tau^2 + s2^2]]).
        // Separate: y1 ~ N(0, tau^2 + s1^2), y2 ~ N(0, tau^2 + s2^2) independently.
        let (tau, s1, s2, y1, y2) = (2.0, 0.3, 0.5, 1.1, 0.4);
        let pr = Prior::TruncatedNormal {
            mean: 0.0,
            sd: tau,
            lo: -60.0,
            hi: 60.0,
        };
        let a = Gauss {
            y: vec![y1],
            s: vec![s1],
            priors: vec![pr.clone()],
        };
        let b = Gauss {
            y: vec![y2],
            s: vec![s2],
            priors: vec![pr.clone()],
        };
        let j = JointPosterior::new(
            vec![&a, &b],
            vec![vec![0], vec![0]],
            vec![pr],
            vec!["theta".into()],
        )
        .unwrap();
        let params = MapParams {
            n_starts: 4,
            ..MapParams::default()
        };
        let zj = find_map(&j, None, &params, &|| ())
            .unwrap()
            .laplace
            .log_evidence;
        let za = find_map(&a, None, &params, &|| ())
            .unwrap()
            .laplace
            .log_evidence;
        let zb = find_map(&b, None, &params, &|| ())
            .unwrap()
            .laplace
            .log_evidence;
        let (t2, v1, v2) = (tau * tau, s1 * s1, s2 * s2);
        let det = (t2 + v1) * (t2 + v2) - t2 * t2;
        let q = ((t2 + v2) * y1 * y1 - 2.0 * t2 * y1 * y2 + (t2 + v1) * y2 * y2) / det;
        let exact_joint = -std::f64::consts::TAU.ln() - 0.5 * det.ln() - 0.5 * q;
        let single = |v: f64, y: f64| {
            -0.5 * (std::f64::consts::TAU * (t2 + v)).ln() - 0.5 * y * y / (t2 + v)
        };
        // The truncated-normal prior's logit transform makes the density in x non-Gaussian:
        // Laplace is then close, not exact.
        assert!((zj - exact_joint).abs() < 0.02, "{zj} vs {exact_joint}");
        assert!((za - single(v1, y1)).abs() < 0.02);
        assert!((zb - single(v2, y2)).abs() < 0.02);
    }

    #[test]
    fn mismatched_transforms_are_rejected() {
        let a = Gauss {
            y: vec![1.0],
            s: vec![1.0],
            priors: vec![Prior::LogUniform { lo: 0.1, hi: 10.0 }],
        };
        let e = JointPosterior::new(
            vec![&a],
            vec![vec![0]],
            vec![Prior::LogUniform { lo: 0.2, hi: 10.0 }],
            vec!["t".into()],
        );
        assert!(e.is_err());
        let e = JointPosterior::new(
            vec![&a],
            vec![vec![0]],
            vec![
                Prior::LogUniform { lo: 0.1, hi: 10.0 },
                Prior::LogUniform { lo: 0.1, hi: 10.0 },
            ],
            vec!["t".into(), "u".into()],
        );
        assert!(e.is_err(), "a coordinate in no part");
    }
}
