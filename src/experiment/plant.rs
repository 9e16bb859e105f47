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
