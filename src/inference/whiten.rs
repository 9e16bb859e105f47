//! An affine reparameterisation of a posterior by its Laplace approximation: `x = m + L z` with
//! `L L^T` the Laplace covariance. The density of `z` is `p(m + L z) |det L|`; gradients map by
//! `L^T`. The joint's posteriors are narrow and strongly correlated in `x` (moduli that trade
//! against each other), and NUTS's diagonal mass matrix cannot undo a correlation: in `z` they
//! are close to isotropic, so trajectories stay short. The draws and every statistic are the
//! same distribution; only the sampler's coordinates change.

use super::{DensityError, Posterior};
use rand::rngs::StdRng;

/// `post` seen through `x = m + L z` (`l` lower triangular, row-major d x d).
pub struct Whitened<'a> {
    pub inner: &'a dyn Posterior,
    pub m: Vec<f64>,
    pub l: Vec<f64>,
    log_det: f64,
    l_inv: Vec<f64>,
}

impl<'a> Whitened<'a> {
    /// `None` when `l` has a non-positive diagonal.
    pub fn new(inner: &'a dyn Posterior, m: Vec<f64>, l: Vec<f64>) -> Option<Self> {
        let d = m.len();
        if l.len() != d * d || (0..d).any(|i| !(l[i * d + i] > 0.0)) {
            return None;
        }
        let log_det = (0..d).map(|i| l[i * d + i].ln()).sum();
        // Inverse of the lower-triangular L by forward substitution on the identity.
        let mut l_inv = vec![0.0; d * d];
        for j in 0..d {
            for i in j..d {
                let mut s = if i == j { 1.0 } else { 0.0 };
                for k in j..i {
                    s -= l[i * d + k] * l_inv[k * d + j];
                }
                l_inv[i * d + j] = s / l[i * d + i];
            }
        }
        Some(Whitened {
            inner,
            m,
            l,
            log_det,
            l_inv,
        })
    }

    fn dim_(&self) -> usize {
        self.m.len()
    }

    /// `x = m + L z`.
    pub fn to_x(&self, z: &[f64]) -> Vec<f64> {
        let d = self.dim_();
        (0..d)
            .map(|i| self.m[i] + (0..=i).map(|k| self.l[i * d + k] * z[k]).sum::<f64>())
            .collect()
    }

    /// `z = L^-1 (x - m)`.
    pub fn to_z(&self, x: &[f64]) -> Vec<f64> {
        let d = self.dim_();
        (0..d)
            .map(|i| {
                (0..=i)
                    .map(|k| self.l_inv[i * d + k] * (x[k] - self.m[k]))
                    .sum::<f64>()
            })
            .collect()
    }

    /// `L^T g` in place.
    fn pull_back(&self, g: &mut [f64]) {
        let d = self.dim_();
        let gx = g.to_vec();
        for (j, gj) in g.iter_mut().enumerate() {
            *gj = (j..d).map(|i| self.l[i * d + j] * gx[i]).sum();
        }
    }
}

impl Posterior for Whitened<'_> {
    fn dim(&self) -> usize {
        self.dim_()
    }
    fn names(&self) -> Vec<String> {
        self.inner.names()
    }
    fn log_prior(&self, z: &[f64], grad: Option<&mut [f64]>) -> f64 {
        let x = self.to_x(z);
        match grad {
            None => self.inner.log_prior(&x, None) + self.log_det,
            Some(g) => {
                let v = self.inner.log_prior(&x, Some(g));
                self.pull_back(g);
                v + self.log_det
            }
        }
    }
    fn log_likelihood(&self, z: &[f64], grad: Option<&mut [f64]>) -> Result<f64, DensityError> {
        let x = self.to_x(z);
        match grad {
            None => self.inner.log_likelihood(&x, None),
            Some(g) => {
                let v = self.inner.log_likelihood(&x, Some(g))?;
                self.pull_back(g);
                Ok(v)
            }
        }
    }
    fn sample_prior(&self, rng: &mut StdRng) -> Vec<f64> {
        self.to_z(&self.inner.sample_prior(rng))
    }
    fn constrained(&self, z: &[f64]) -> Vec<f64> {
        self.inner.constrained(&self.to_x(z))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A correlated Gaussian in x (unnormalised prior 0, likelihood the density).
    struct Gauss;
    impl Posterior for Gauss {
        fn dim(&self) -> usize {
            2
        }
        fn names(&self) -> Vec<String> {
            vec!["a".into(), "b".into()]
        }
        fn log_prior(&self, _x: &[f64], grad: Option<&mut [f64]>) -> f64 {
            if let Some(g) = grad {
                g.fill(0.0);
            }
            0.0
        }
        fn log_likelihood(&self, x: &[f64], grad: Option<&mut [f64]>) -> Result<f64, DensityError> {
            // Precision [[2, 1.9], [1.9, 2]].
            let (a, b) = (x[0] - 1.0, x[1] + 2.0);
            if let Some(g) = grad {
                g[0] = -(2.0 * a + 1.9 * b);
                g[1] = -(1.9 * a + 2.0 * b);
            }
            Ok(-0.5 * (2.0 * a * a + 3.8 * a * b + 2.0 * b * b))
        }
        fn sample_prior(&self, _rng: &mut StdRng) -> Vec<f64> {
            vec![0.0, 0.0]
        }
        fn constrained(&self, x: &[f64]) -> Vec<f64> {
            x.to_vec()
        }
    }

    #[test]
    fn round_trip_and_gradient() {
        let l = vec![0.7, 0.0, -0.5, 0.3];
        let w = Whitened::new(&Gauss, vec![1.0, -2.0], l).unwrap();
        let z = [0.3, -1.2];
        let x = w.to_x(&z);
        let back = w.to_z(&x);
        assert!((back[0] - z[0]).abs() < 1e-14 && (back[1] - z[1]).abs() < 1e-14);
        let mut g = vec![0.0; 2];
        w.log_likelihood(&z, Some(&mut g)).unwrap();
        for i in 0..2 {
            let e = 1e-6;
            let mut a = z.to_vec();
            let mut b = z.to_vec();
            a[i] += e;
            b[i] -= e;
            let fd = (w.log_likelihood(&a, None).unwrap() - w.log_likelihood(&b, None).unwrap())
                / (2.0 * e);
            assert!((fd - g[i]).abs() < 1e-7, "{fd} vs {}", g[i]);
        }
        assert_eq!(w.constrained(&z), x);
    }
}
