//! The identification's model of its own measurement: the H1 estimator's leakage.
//!
//! A measured H1 with a window of length T is not the structure's FRF at the line but its
//! window-kernel average, `E[H1](f_k) = int H S_F |W((f - f_k) T)|^2 df / int S_F |W|^2 df`
//! over the band where the force had power ([`crate::forward::measurement`], the same
//! operator the likelihood uses). At a mode as damped as the joint's first (eta 0.2 at
//! 22 Hz, half-power bandwidth 4.4 Hz) a 1 s Hann window lowers the peak by about 6 % and
//! widens it, so a circle fit reads a loss factor about 16 % too high. When the study states
//! its estimator (`[measurements.estimator]`), each identification is wrapped in a fixed point:
//! fit on the data minus the leakage bias of the current fit, `X - (E[H1](p) - H(p))`, until the
//! parameters stop changing. At the fixed point the model's expected H1 matches the data,
//! which is what a consistent estimator needs; the RFM inside is unchanged.

use crate::common::C64;
use crate::forward::{MeasurementModel, Observation};
use crate::frf::FrfEngine;
use crate::rfm::MeasuredColumn;
use crate::stage::RunError;

/// Fixed-point passes stop when the largest relative change of the parameters is below this.
pub const PASS_TOLERANCE: f64 = 1e-6;
/// At most this many corrected passes after the uncorrected first fit.
pub const MAX_PASSES: usize = 12;

/// The study's measurement model applied to one level's data.
pub struct Leakage<'a> {
    pub engine: &'a dyn FrfEngine,
    /// The H1 estimator's expectation on the level's lines ([`crate::forward::measurement`]).
    pub measurement: MeasurementModel,
}

impl Leakage<'_> {
    /// The leakage bias `E[H1] - H` of the model with modulus curve `modulus` (Pa, of w in
    /// rad/s) on the lines and outputs of `col`, flattened `[line][k]` like its accelerance:
    /// the forward model's ([`Observation::bias_for_modulus`]). `col` may be a band of the
    /// level's lines; the operator is restricted to those lines.
    pub fn bias(
        &self,
        col: &MeasuredColumn,
        modulus: &(dyn Fn(f64) -> C64 + Sync),
    ) -> Result<Vec<C64>, RunError> {
        let fail = |m: String| RunError::Analysis {
            analysis: "leakage model of [measurements.estimator]".into(),
            message: m,
        };
        let lines_hz: Vec<f64> = col
            .omega_rad_s
            .iter()
            .map(|w| w / std::f64::consts::TAU)
            .collect();
        if lines_hz.is_empty() {
            return Ok(Vec::new());
        }
        let m = MeasurementModel::new(self.measurement.spec, &lines_hz, &self.measurement.params)
            .map_err(|e| fail(e.to_string()))?;
        let obs = Observation::new(
            self.engine,
            &col.omega_rad_s,
            col.input,
            &col.outputs,
            Some(m),
        )
        .map_err(|e| fail(e.to_string()))?;
        obs.bias_for_modulus(modulus)
            .map_err(|e| fail(e.to_string()))
    }

    /// `col` with `bias` subtracted from its accelerance.
    pub fn corrected(col: &MeasuredColumn, bias: &[C64]) -> MeasuredColumn {
        let mut c = col.clone();
        c.accelerance
            .iter_mut()
            .zip(bias)
            .for_each(|(x, b)| *x -= b);
        c
    }
}

/// Run `fit` on the data, then, with a leakage model, again on the data corrected by the
/// bias of the previous fit until its parameters (`params_of`) change by less than
/// [`PASS_TOLERANCE`] (relative, largest component). `modulus(p, w)` is E*(w) (Pa) at
/// parameters `p`. Returns the last fit and the number of corrected passes.
pub fn fixed_point<T>(
    leak: Option<&Leakage<'_>>,
    col: &MeasuredColumn,
    mut fit: impl FnMut(&MeasuredColumn, Option<&T>) -> Result<T, RunError>,
    params_of: impl Fn(&T) -> Vec<f64>,
    modulus: &(dyn Fn(&[f64], f64) -> C64 + Sync),
) -> Result<(T, usize), RunError> {
    let mut r = fit(col, None)?;
    let Some(leak) = leak else {
        return Ok((r, 0));
    };
    if params_of(&r).is_empty() {
        // The fit failed (e.g. an IEM that found no mode): nothing to correct with.
        return Ok((r, 0));
    }
    let mut passes = 0;
    for _ in 0..MAX_PASSES {
        let p = params_of(&r);
        let bias = leak.bias(col, &|w| modulus(&p, w))?;
        let next = fit(&Leakage::corrected(col, &bias), Some(&r))?;
        passes += 1;
        let change = params_of(&r)
            .iter()
            .zip(params_of(&next))
            .map(|(a, b)| ((b - a) / a.abs().max(f64::MIN_POSITIVE)).abs())
            .fold(0.0, f64::max);
        r = next;
        if params_of(&r).is_empty() || change < PASS_TOLERANCE {
            break;
        }
    }
    Ok((r, passes))
}
