//! The forward model: structure + constitutive law + measurement model -> the predicted H1 of
//! every measured channel at every line, with its Jacobian in the law's parameters.
//!
//! ```text
//!   H'_i(w; p)   = -w^2 H_i,in(w; E*(w; p))                       (engine: full FE or certified ROM)
//!   dH'_i/dp_k   = -w^2 dH_i,in/dE' * dE*/dp_k(w)                   (paper eq. 44-47; dH/dE* = dH/dE')
//!   E[H1]_i(f_l) = sum_j a_lj H'_i(f_j)  (or conj(H'_i(f_j)) for mirror terms)   (measurement.rs)
//! ```
//!
//! The deterministic RFM (through the leakage bias `E[H1] - H'` at the lines, see
//! `runner::leakage`), the likelihood ([`crate::inference`]) and the closed loop call this one
//! object, so a prediction is made in one place. Without a measurement model the prediction is
//! the exact accelerance at the lines.

pub mod measurement;

use crate::common::C64;
use crate::frf::{FrfEngine, FrfError};
use crate::material::ConstitutiveModel;
pub use measurement::{EstimatorSpec, KernelTerm, MeasurementModel, MeasurementParams};

/// Errors of a prediction.
#[derive(Debug, Clone, thiserror::Error)]
pub enum ForwardError {
    /// The engine failed (singular dynamic stiffness, ...).
    #[error("{0}")]
    Frf(String),
    /// The law's parameters are outside its admissible range.
    #[error("parameters {0:?} are outside the law's admissible range")]
    Inadmissible(Vec<f64>),
    #[error("forward model: {0}")]
    Setup(String),
}

impl From<FrfError> for ForwardError {
    fn from(e: FrfError) -> Self {
        ForwardError::Frf(e.to_string())
    }
}

/// Accelerance `[line][k]`, its derivative in E' (empty unless asked) and the drive-point
/// accelerance per line.
pub type Columns = (Vec<C64>, Vec<C64>, Vec<C64>);

/// A prediction at the lines: values `[line * n_out + k]` and, when asked, the Jacobian
/// `jac[param][line * n_out + k]`.
#[derive(Clone, Debug, Default)]
pub struct Prediction {
    pub values: Vec<C64>,
    pub jac: Vec<Vec<C64>>,
}

/// Structure (an FRF engine), law, the measured column's layout and the measurement model.
pub struct ForwardModel<'a> {
    pub obs: Observation<'a>,
    pub law: &'a dyn ConstitutiveModel,
}

/// What is observed, and how: the structure (an FRF engine), the measured column's layout and
/// the measurement model, for any modulus curve.
pub struct Observation<'a> {
    pub engine: &'a dyn FrfEngine,
    /// Lines (rad/s) of the data.
    pub omega_rad_s: Vec<f64>,
    /// Excitation point (index into the engine's points; must be an engine input).
    pub input: usize,
    /// Response points (indices into the engine's points).
    pub outputs: Vec<usize>,
    /// The H1 estimator's expectation, when the study declares it.
    pub measurement: Option<MeasurementModel>,
}

impl<'a> ForwardModel<'a> {
    /// A forward model of `law` on the lines `omega_rad_s`, driven at point `input` (an engine
    /// input) and observed at `outputs`.
    pub fn new(
        engine: &'a dyn FrfEngine,
        law: &'a dyn ConstitutiveModel,
        omega_rad_s: &[f64],
        input: usize,
        outputs: &[usize],
        measurement: Option<MeasurementModel>,
    ) -> Result<Self, ForwardError> {
        Ok(ForwardModel {
            obs: Observation::new(engine, omega_rad_s, input, outputs, measurement)?,
            law,
        })
    }

    pub fn n_out(&self) -> usize {
        self.obs.outputs.len()
    }
    pub fn n_lines(&self) -> usize {
        self.obs.omega_rad_s.len()
    }
    pub fn n_params(&self) -> usize {
        self.law.n_params()
    }

    /// Check `p` against the law's admissible range.
    pub fn check(&self, p: &[f64]) -> Result<(), ForwardError> {
        let ok = p.len() == self.law.n_params()
            && p.iter()
                .zip(self.law.bounds())
                .all(|(v, (lo, hi))| v.is_finite() && *v > lo && *v < hi);
        if ok {
            Ok(())
        } else {
            Err(ForwardError::Inadmissible(p.to_vec()))
        }
    }

    /// Exact accelerance at `omega` for parameters `p`, with its Jacobian in `p`, and the
    /// drive-point accelerance.
    fn exact_on(
        &self,
        omega: &[f64],
        p: &[f64],
        jac: bool,
    ) -> Result<(Prediction, Vec<C64>), ForwardError> {
        let np = self.law.n_params();
        let modulus: Vec<C64> = omega.iter().map(|&w| self.law.modulus(p, w)).collect();
        let (h, dh, drive) = self.obs.accelerance_and_drive(omega, &modulus, jac)?;
        let n = self.obs.outputs.len();
        let mut out = Prediction {
            values: h,
            jac: Vec::new(),
        };
        if jac {
            let mut dedp = vec![C64::new(0.0, 0.0); np];
            let mut jm = vec![vec![C64::new(0.0, 0.0); omega.len() * n]; np];
            for (l, &w) in omega.iter().enumerate() {
                self.law.jacobian(p, w, &mut dedp);
                for k in 0..n {
                    let d = dh[l * n + k];
                    for (q, col) in jm.iter_mut().enumerate() {
                        col[l * n + k] = d * dedp[q];
                    }
                }
            }
            out.jac = jm;
        }
        Ok((out, drive))
    }

    /// The exact accelerance at the data's lines (no measurement model).
    pub fn exact(&self, p: &[f64], jac: bool) -> Result<Prediction, ForwardError> {
        self.check(p)?;
        Ok(self.exact_on(&self.obs.omega_rad_s, p, jac)?.0)
    }

    /// What the analyser is expected to report: `E[H1]` at the lines (the exact accelerance
    /// without a measurement model), with its Jacobian in `p` when `jac`.
    pub fn predict(&self, p: &[f64], jac: bool) -> Result<Prediction, ForwardError> {
        self.check(p)?;
        let Some(m) = &self.obs.measurement else {
            return Ok(self.exact_on(&self.obs.omega_rad_s, p, jac)?.0);
        };
        let (fine, drive) = self.exact_on(&m.fine_omega(), p, jac)?;
        let n = self.obs.outputs.len();
        // A shaker colours the force spectrum through the drive point; its weights are
        // evaluated at p and held fixed in the Jacobian (their derivative is second order in
        // the leakage bias).
        let shaker_rows = m
            .spec
            .shaker
            .map(|_| m.weights_for_force(Some(&m.force_psd(&drive))));
        let rows = shaker_rows.as_ref().unwrap_or(&m.rows);
        if fine.jac.is_empty() {
            return Ok(Prediction {
                values: MeasurementModel::apply(rows, &fine.values, n),
                jac: Vec::new(),
            });
        }
        // Values and Jacobian columns side by side, so that one pass over the kernel terms
        // applies them all (contiguous inner loop).
        let nc = n * (1 + fine.jac.len());
        let n_fine = fine.values.len() / n;
        let mut stacked = vec![C64::new(0.0, 0.0); n_fine * nc];
        for j in 0..n_fine {
            let row = &mut stacked[j * nc..(j + 1) * nc];
            row[..n].copy_from_slice(&fine.values[j * n..(j + 1) * n]);
            for (q, col) in fine.jac.iter().enumerate() {
                row[n * (q + 1)..n * (q + 2)].copy_from_slice(&col[j * n..(j + 1) * n]);
            }
        }
        let out = MeasurementModel::apply(rows, &stacked, nc);
        let n_lines = rows.len();
        let pick = |q: usize| -> Vec<C64> {
            (0..n_lines)
                .flat_map(|l| out[l * nc + n * q..l * nc + n * (q + 1)].iter().copied())
                .collect()
        };
        Ok(Prediction {
            values: pick(0),
            jac: (1..=fine.jac.len()).map(pick).collect(),
        })
    }
}

impl<'a> Observation<'a> {
    /// Observation on the lines `omega_rad_s`, driven at point `input` (an engine input) and
    /// observed at `outputs`.
    pub fn new(
        engine: &'a dyn FrfEngine,
        omega_rad_s: &[f64],
        input: usize,
        outputs: &[usize],
        measurement: Option<MeasurementModel>,
    ) -> Result<Self, ForwardError> {
        if !engine.inputs().contains(&input) {
            return Err(ForwardError::Setup(format!(
                "point index {input} is not an input of the engine"
            )));
        }
        if let Some(&o) = outputs.iter().find(|&&o| o >= engine.n_out()) {
            return Err(ForwardError::Setup(format!(
                "output point index {o} is not a point of the engine ({} points)",
                engine.n_out()
            )));
        }
        if let Some(m) = &measurement {
            if m.rows.len() != omega_rad_s.len() {
                return Err(ForwardError::Setup(format!(
                    "measurement model has {} lines, the data {}",
                    m.rows.len(),
                    omega_rad_s.len()
                )));
            }
        }
        Ok(Observation {
            engine,
            omega_rad_s: omega_rad_s.to_vec(),
            input,
            outputs: outputs.to_vec(),
            measurement,
        })
    }

    /// Exact accelerance `-w^2 H_i,in` on `omega` at the modulus `modulus(w)`, `[line][k]`,
    /// with `-w^2 dH/dE'` when `derivs`.
    pub fn accelerance_with(
        &self,
        omega: &[f64],
        modulus: &[C64],
        derivs: bool,
    ) -> Result<(Vec<C64>, Vec<C64>), ForwardError> {
        self.accelerance_and_drive(omega, modulus, derivs)
            .map(|(h, dh, _)| (h, dh))
    }

    /// [`ForwardModel::accelerance_with`] plus the drive-point accelerance per line.
    pub fn accelerance_and_drive(
        &self,
        omega: &[f64],
        modulus: &[C64],
        derivs: bool,
    ) -> Result<Columns, ForwardError> {
        let sw = self.engine.sweep(omega, modulus, derivs)?;
        let jpos = self
            .engine
            .inputs()
            .iter()
            .position(|&j| j == self.input)
            .ok_or(FrfError::BadInput(self.input))?;
        let n = self.outputs.len();
        let mut h = Vec::with_capacity(omega.len() * n);
        let mut dh = Vec::with_capacity(if derivs { omega.len() * n } else { 0 });
        let mut drive = Vec::with_capacity(omega.len());
        for (l, &w) in omega.iter().enumerate() {
            drive.push(-w * w * sw.h[sw.idx(l, self.input, jpos)]);
            for &i in &self.outputs {
                let idx = sw.idx(l, i, jpos);
                h.push(-w * w * sw.h[idx]);
                if derivs {
                    dh.push(-w * w * sw.dh_de[idx]);
                }
            }
        }
        Ok((h, dh, drive))
    }

    /// The measurement model's systematic error at the lines, `E[H1] - H'` (`[line][k]`),
    /// for any modulus curve `modulus(w)` (Pa): what the RFM's fixed point subtracts from the
    /// data. Empty without a measurement model.
    pub fn bias_for_modulus(
        &self,
        modulus: &(dyn Fn(f64) -> C64 + Sync),
    ) -> Result<Vec<C64>, ForwardError> {
        let Some(m) = &self.measurement else {
            return Ok(Vec::new());
        };
        let fo = m.fine_omega();
        let fe: Vec<C64> = fo.iter().map(|&w| modulus(w)).collect();
        let (fine, _, drive) = self.accelerance_and_drive(&fo, &fe, false)?;
        let le: Vec<C64> = self.omega_rad_s.iter().map(|&w| modulus(w)).collect();
        let (exact, _) = self.accelerance_with(&self.omega_rad_s, &le, false)?;
        let shaker_rows = m
            .spec
            .shaker
            .map(|_| m.weights_for_force(Some(&m.force_psd(&drive))));
        let rows = shaker_rows.as_ref().unwrap_or(&m.rows);
        let expected = MeasurementModel::apply(rows, &fine, self.outputs.len());
        Ok(expected.iter().zip(&exact).map(|(a, b)| a - b).collect())
    }
}
