//! The FE structure as the rig sees it: a [`Plant`] from any [`FrfEngine`] and an adhesive
//! modulus curve E*(w), so `rfmlab simulate` can drive the virtual experiment with the full
//! model or the certified ROM, and the identification can model its own measurement chain.

use super::{ExperimentError, Plant};
use crate::common::C64;
use crate::frf::FrfEngine;

/// Accelerance of every engine output for a unit force at one engine input, with the adhesive
/// modulus E*(w) (Pa, w in rad/s) given as a curve: a constitutive law at fixed parameters,
/// `|w| law.modulus(&p, w)`, or a constant.
pub struct EnginePlant<'a> {
    pub engine: &'a dyn FrfEngine,
    pub modulus: &'a (dyn Fn(f64) -> C64 + Sync),
    /// Column of the engine's inputs that is the drive point.
    pub input_col: usize,
    /// Output index of the drive point.
    pub drive_output: usize,
}

impl Plant for EnginePlant<'_> {
    fn n_channels(&self) -> usize {
        self.engine.n_out()
    }
    fn drive_channel(&self) -> usize {
        self.drive_output
    }
    /// At 0 Hz (the lower edge of a baseband force band) the accelerance `-w^2 H` of the
    /// grounded structure is 0; the engine is not asked for it.
    fn accelerance(&self, freq_hz: &[f64]) -> Result<Vec<Vec<C64>>, ExperimentError> {
        let omega: Vec<f64> = freq_hz
            .iter()
            .map(|f| 2.0 * std::f64::consts::PI * f)
            .collect();
        if freq_hz.first() == Some(&0.0) {
            let zero = C64::new(0.0, 0.0);
            if freq_hz.len() == 1 {
                return Ok(vec![vec![zero]; self.n_channels()]);
            }
            let rest = self.accelerance(&freq_hz[1..])?;
            return Ok(rest
                .into_iter()
                .map(|c| std::iter::once(zero).chain(c).collect())
                .collect());
        }
        let modulus: Vec<C64> = omega.iter().map(|&w| (self.modulus)(w)).collect();
        let s = self
            .engine
            .sweep(&omega, &modulus, false)
            .map_err(|e| ExperimentError::Plant(e.to_string()))?;
        let mut out = vec![vec![C64::new(0.0, 0.0); freq_hz.len()]; s.n_out];
        for (l, &w) in omega.iter().enumerate() {
            for (i, row) in out.iter_mut().enumerate() {
                row[l] = -w * w * s.h[s.idx(l, i, self.input_col)];
            }
        }
        Ok(out)
    }
}

/// A plant whose force channel reads the force on the shaker's side of the stinger (the force
/// driving the moving mass) instead of the force into the structure: every accelerance is
/// multiplied by the shaker's force transfer `T = k_s / (k_s - w^2 m_a + k_s m_a A_dd)`
/// ([`super::spec::Shaker::transfer`], `A_dd` the structure's drive-point accelerance), the
/// same algebra as the forward model's `Effect::Shaker` (`crate::forward::effects`), which
/// its tests check against the full model with the moving mass as a DOF.
pub struct ShakerSidePlant<'a> {
    pub inner: &'a dyn Plant,
    pub shaker: super::spec::Shaker,
}

impl Plant for ShakerSidePlant<'_> {
    fn n_channels(&self) -> usize {
        self.inner.n_channels()
    }
    fn drive_channel(&self) -> usize {
        self.inner.drive_channel()
    }
    fn accelerance(&self, freq_hz: &[f64]) -> Result<Vec<Vec<C64>>, ExperimentError> {
        let mut a = self.inner.accelerance(freq_hz)?;
        let d = self.inner.drive_channel();
        let t: Vec<C64> = freq_hz
            .iter()
            .zip(&a[d])
            .map(|(&f, &a_dd)| self.shaker.transfer(f, a_dd))
            .collect();
        if t.iter().any(|z| !z.is_finite()) {
            return Err(ExperimentError::Plant(
                "the shaker-structure transfer is singular or not finite: check the shaker's armature mass and stinger stiffness".into(),
            ));
        }
        for row in a.iter_mut() {
            row.iter_mut().zip(&t).for_each(|(x, t)| *x *= t);
        }
        Ok(a)
    }
}
