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
//! [`crate::identify::leakage`]), the likelihood ([`crate::inference`]) and the closed loop call this one
//! object, so a prediction is made in one place. Without a measurement model the prediction is
//! the exact accelerance at the lines.

pub mod effects;
pub mod fixed;
pub mod measurement;

use crate::common::C64;
use crate::frf::{FrfEngine, FrfError};
use crate::material::ConstitutiveModel;
pub use effects::{Effect, EffectTerm, Effects};
pub use measurement::{EstimatorSpec, KernelTerm, MeasurementModel, MeasurementParams};
use std::borrow::Cow;

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
    /// The measurement model's bias linearised at a point ([`ForwardModel::linearise_measurement`]):
    /// when set, predictions are `H(p) + b(p0) + db/dln p (ln p - ln p0)`.
    pub linear_bias: Option<LinearBias>,
    /// Effects the structure and law lack ([`effects`]); none by default. Free terms' values
    /// are parameters after the law's.
    pub effects: Effects,
}

/// The measurement model's systematic error `b = E[H1] - H` at `p0` and its derivative in
/// `ln p`, at the lines (`[line * n_out + k]`).
#[derive(Clone, Debug)]
pub struct LinearBias {
    pub p0: Vec<f64>,
    pub b0: Vec<C64>,
    /// `d b / d ln p_q` for the law's parameters (positive), `d b / d p_q` for the free
    /// effects' (which may be zero or negative), `[q][line * n_out + k]`.
    pub jac: Vec<Vec<C64>>,
    /// The first `n_log` parameters (the law's) are linearised in `ln p_q`, the rest in `p_q`.
    pub n_log: usize,
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
            linear_bias: None,
            effects: Effects::default(),
        })
    }

    pub fn n_out(&self) -> usize {
        self.obs.outputs.len()
    }
    pub fn n_lines(&self) -> usize {
        self.obs.omega_rad_s.len()
    }
    /// The law's parameters plus the free effects' values.
    pub fn n_params(&self) -> usize {
        self.law.n_params() + self.effects.n_free()
    }
    /// Names of the parameters: the law's, then the free effects'.
    pub fn param_names(&self) -> Vec<String> {
        let mut n = self.law.param_names();
        n.extend(self.effects.free_names());
        n
    }
    /// Replace the effects (checked against the engine and the channels).
    pub fn set_effects(&mut self, effects: Effects) -> Result<(), ForwardError> {
        effects.check(self.obs.engine, self.obs.outputs.len())?;
        // A bias linearised for other effects no longer applies (without effects before or
        // after, the law's linearisation stands).
        if !effects.is_empty() || !self.effects.is_empty() {
            self.linear_bias = None;
        }
        self.effects = effects;
        Ok(())
    }

    /// Check `p` against the law's admissible range (and the free effects' ranges).
    pub fn check(&self, p: &[f64]) -> Result<(), ForwardError> {
        let bounds = self.law.bounds().into_iter().chain(
            self.effects
                .terms
                .iter()
                .filter(|t| t.free)
                .map(|t| t.effect.bounds()),
        );
        let ok = p.len() == self.n_params()
            && p.iter()
                .zip(bounds)
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
        if !self.effects.is_empty() {
            return self.exact_on_with_effects(omega, p, jac);
        }
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

    /// [`Self::exact_on`] with structural effects (channel effects come at the lines).
    fn exact_on_with_effects(
        &self,
        omega: &[f64],
        p: &[f64],
        jac: bool,
    ) -> Result<(Prediction, Vec<C64>), ForwardError> {
        let nl = self.law.n_params();
        let (pl, pe) = p.split_at(nl);
        let values = self.effects.values(pe);
        // The law, plus any extra Maxwell branches (law effects).
        let modulus: Vec<C64> = omega
            .iter()
            .map(|&w| {
                self.law.modulus(pl, w)
                    + self
                        .effects
                        .terms
                        .iter()
                        .zip(&values)
                        .map(|(t, v)| t.effect.law_factor(w) * v)
                        .sum::<C64>()
            })
            .collect();
        let sc = self.effects.structural(
            self.obs.engine,
            self.obs.input,
            &self.obs.outputs,
            omega,
            &modulus,
            jac,
            &values,
        )?;
        let n = self.obs.outputs.len();
        let mut out = Prediction {
            values: sc.h,
            jac: Vec::new(),
        };
        if jac {
            let mut dedp = vec![C64::new(0.0, 0.0); nl];
            let mut jm = vec![vec![C64::new(0.0, 0.0); omega.len() * n]; nl];
            for (l, &w) in omega.iter().enumerate() {
                self.law.jacobian(pl, w, &mut dedp);
                for k in 0..n {
                    let d = sc.dh[l * n + k];
                    for (q, col) in jm.iter_mut().enumerate() {
                        col[l * n + k] = d * dedp[q];
                    }
                }
            }
            for (t, term) in self.effects.terms.iter().enumerate() {
                if !term.free {
                    continue;
                }
                if matches!(term.effect, Effect::MaxwellBranch { .. }) {
                    // A law effect: dH/dE' times dE*/dE_k.
                    jm.push(
                        (0..omega.len() * n)
                            .map(|o| sc.dh[o] * term.effect.law_factor(omega[o / n]))
                            .collect(),
                    );
                } else {
                    jm.push(sc.d_terms[t].clone());
                }
            }
            out.jac = jm;
        }
        Ok((out, sc.drive))
    }

    /// The channel effects' factor `(1 + g) exp(-j w tau)` at the lines, `[line * n_out + k]`,
    /// for the values `values` of all terms.
    fn channel_factor(&self, values: &[f64]) -> Vec<C64> {
        let n = self.obs.outputs.len();
        let one = C64::new(1.0, 0.0);
        let mut factor = vec![one; self.obs.omega_rad_s.len() * n];
        for (term, v) in self.effects.terms.iter().zip(values) {
            match term.effect {
                Effect::Gain { channel, .. } => {
                    for f in factor.iter_mut().skip(channel).step_by(n) {
                        *f *= 1.0 + v;
                    }
                }
                Effect::Delay { channel, .. } => {
                    for (l, w) in self.obs.omega_rad_s.iter().enumerate() {
                        factor[l * n + channel] *= C64::from_polar(1.0, -w * v);
                    }
                }
                _ => {}
            }
        }
        factor
    }

    /// Channel effects (gains, delays) applied at the lines to `out` (values and Jacobian).
    fn apply_channel_effects(&self, p: &[f64], out: &mut Prediction) {
        if self.effects.is_empty() {
            return;
        }
        let nl = self.law.n_params();
        let values = self.effects.values(&p[nl..]);
        let n = self.obs.outputs.len();
        let factor = self.channel_factor(&values);
        out.values
            .iter_mut()
            .zip(&factor)
            .for_each(|(a, f)| *a *= f);
        for col in out.jac.iter_mut() {
            col.iter_mut().zip(&factor).for_each(|(a, f)| *a *= f);
        }
        if out.jac.is_empty() {
            return;
        }
        let mut q = nl;
        for (term, v) in self.effects.terms.iter().zip(&values) {
            if !term.free {
                continue;
            }
            match term.effect {
                Effect::Gain { channel, .. } => {
                    let col = &mut out.jac[q];
                    for (o, c) in col.iter_mut().enumerate() {
                        *c = if o % n == channel {
                            out.values[o] / (1.0 + v)
                        } else {
                            C64::new(0.0, 0.0)
                        };
                    }
                }
                Effect::Delay { channel, .. } => {
                    let col = &mut out.jac[q];
                    for (o, c) in col.iter_mut().enumerate() {
                        *c = if o % n == channel {
                            C64::new(0.0, -self.obs.omega_rad_s[o / n]) * out.values[o]
                        } else {
                            C64::new(0.0, 0.0)
                        };
                    }
                }
                _ => {}
            }
            q += 1;
        }
    }

    /// The exact accelerance at the data's lines (no measurement model; channel effects on).
    pub fn exact(&self, p: &[f64], jac: bool) -> Result<Prediction, ForwardError> {
        self.check(p)?;
        let mut out = self.exact_on(&self.obs.omega_rad_s, p, jac)?.0;
        self.apply_channel_effects(p, &mut out);
        Ok(out)
    }

    /// What the analyser is expected to report: `E[H1]` at the lines (the exact accelerance
    /// without a measurement model), with its Jacobian in `p` when `jac`; the effects'
    /// channel gains and delays act on the analyser's output.
    pub fn predict(&self, p: &[f64], jac: bool) -> Result<Prediction, ForwardError> {
        let mut out = self.predict_structure(p, jac)?;
        self.apply_channel_effects(p, &mut out);
        Ok(out)
    }

    fn predict_structure(&self, p: &[f64], jac: bool) -> Result<Prediction, ForwardError> {
        self.check(p)?;
        if let Some(lb) = &self.linear_bias {
            let mut out = self.exact_on(&self.obs.omega_rad_s, p, jac)?.0;
            lb.add_to(
                p,
                &mut out.values,
                if jac { Some(&mut out.jac) } else { None },
            );
            return Ok(out);
        }
        let Some(m) = &self.obs.measurement else {
            return Ok(self.exact_on(&self.obs.omega_rad_s, p, jac)?.0);
        };
        let (fine, drive) = self.exact_on(&m.fine_omega(), p, jac)?;
        let n = self.obs.outputs.len();
        // A shaker's weights are evaluated at p and held fixed in the Jacobian. That misses
        // about 1 % of a column (tests/suite/inference_likelihood.rs); the linearised bias,
        // which the samplers see by default, differences the weights instead
        // (`linearise_model_measurement`).
        let rows = &*m.rows_for_drive(&drive);
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
        // The excitation's column alone, read at the outputs and the drive point.
        let rows: Vec<usize> = self.outputs.iter().copied().chain([self.input]).collect();
        let fewer = crate::frf::narrowed(self.engine, &[self.input], &rows);
        let engine: &dyn FrfEngine = fewer.as_deref().unwrap_or(self.engine);
        let sw = engine.sweep(omega, modulus, derivs)?;
        let jpos = engine
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
        let expected =
            MeasurementModel::apply(&m.rows_for_drive(&drive), &fine, self.outputs.len());
        Ok(expected.iter().zip(&exact).map(|(a, b)| a - b).collect())
    }
}

/// How the measurement model's grid was chosen: per candidate points-per-line `m`, the largest
/// change of `E[H1]` from `m` to `2 m` relative to `|H|` at the same line and channel.
#[derive(Clone, Debug, PartialEq)]
pub struct GridChoice {
    pub points_per_line: usize,
    pub history: Vec<(usize, f64)>,
    pub tolerance: f64,
    pub converged: bool,
}

/// Candidate points per line of [`Observation::converged_measurement`], coarsest first.
pub const GRID_CANDIDATES: [usize; 4] = [2, 4, 8, 16];
/// Default tolerance of [`Observation::converged_measurement`]: the change of `E[H1]` from `m`
/// to `2 m` points per line, relative to `|H|` at each line and channel (the H1 random error
/// is relative too). 1e-4 is 1/16 of that error at coherence 0.999 with 190 averages
/// (1.6e-3 of |H|).
pub const GRID_TOLERANCE: f64 = 1e-4;

impl Observation<'_> {
    /// The measurement model for `spec` on this observation's lines with the coarsest grid
    /// whose `E[H1]` at the modulus curve `modulus` changes by less than `tolerance` (relative
    /// to `|H|` at each line and channel) when the grid is doubled. The midpoint rule is spectrally
    /// accurate for the smooth interior of the kernel integral, so the grid needed is set by the
    /// sharpest feature: the lightest mode's bandwidth, or a shaker's coupled resonance in the
    /// force spectrum (on the default rig 2 points per line leave 8e-3 on a noiseless Model 4
    /// fit, 8 points 1.5e-5). Falls back to the finest candidate, flagged, if none converges.
    pub fn converged_measurement(
        &self,
        spec: EstimatorSpec,
        modulus: &(dyn Fn(f64) -> C64 + Sync),
        tolerance: f64,
    ) -> Result<(MeasurementModel, GridChoice), ForwardError> {
        let lines_hz: Vec<f64> = self
            .omega_rad_s
            .iter()
            .map(|w| w / std::f64::consts::TAU)
            .collect();
        let le: Vec<C64> = self.omega_rad_s.iter().map(|&w| modulus(w)).collect();
        let (exact, _) = self.accelerance_with(&self.omega_rad_s, &le, false)?;
        let peak = exact
            .iter()
            .map(|z| z.norm())
            .fold(0.0, f64::max)
            .max(1e-300);
        let build = |m: usize| -> Result<(MeasurementModel, Vec<C64>), ForwardError> {
            let mm = MeasurementModel::new(
                spec,
                &lines_hz,
                &MeasurementParams {
                    points_per_line: m,
                    ..MeasurementParams::default()
                },
            )
            .map_err(|e| ForwardError::Setup(e.to_string()))?;
            let obs = Observation::new(
                self.engine,
                &self.omega_rad_s,
                self.input,
                &self.outputs,
                Some(mm),
            )?;
            let bias = obs.bias_for_modulus(modulus)?;
            Ok((obs.measurement.expect("set above"), bias))
        };
        let mut history = Vec::new();
        let mut prev = build(GRID_CANDIDATES[0])?;
        for w in GRID_CANDIDATES.windows(2) {
            let next = build(w[1])?;
            let change = prev
                .1
                .iter()
                .zip(&next.1)
                .zip(&exact)
                .map(|((a, b), h)| (a - b).norm() / h.norm().max(1e-6 * peak))
                .fold(0.0, f64::max);
            history.push((w[0], change));
            if change < tolerance {
                return Ok((
                    prev.0,
                    GridChoice {
                        points_per_line: w[0],
                        history,
                        tolerance,
                        converged: true,
                    },
                ));
            }
            prev = next;
        }
        let last = *GRID_CANDIDATES.last().expect("candidates");
        Ok((
            prev.0,
            GridChoice {
                points_per_line: last,
                history,
                tolerance,
                converged: false,
            },
        ))
    }
}

/// A prediction with what its Jacobian needs, for vector-Jacobian products: the gradient of a
/// scalar of the prediction (a log likelihood) costs one adjoint pass of the kernel instead of
/// one forward pass per parameter ([`ForwardModel::linearise`]).
pub struct Linearised<'m> {
    /// `E[H1]` (or the exact accelerance) at the lines, `[line * n_out + k]`.
    pub values: Vec<C64>,
    n_out: usize,
    n_params: usize,
    /// `dH'/dE'` on the evaluation grid (the lines, or the fine grid), `[j * n_out + k]`.
    dh: Vec<C64>,
    /// `dE*/dp_q` on the evaluation grid, `[j * n_params + q]`.
    dedp: Vec<C64>,
    /// The kernel rows (fixed at p), when there is a measurement model.
    rows: Option<Cow<'m, [Vec<KernelTerm>]>>,
    /// Jacobian columns added at the lines (the linearised bias, or the channel effects'
    /// columns), `[q][line * n_out + k]` (empty: none).
    extra: Vec<Vec<C64>>,
    /// With effects: the Jacobian columns of the structural part on the evaluation grid,
    /// `[q][j * n_out + k]` (empty: none), in place of `dh` and `dedp`.
    grid_jac: Vec<Vec<C64>>,
    /// With effects: the channel factor at the lines (the structural part's cotangent is
    /// `c conj(f)`).
    factor: Option<Vec<C64>>,
}

impl Linearised<'_> {
    /// `g_q = Re sum_o conj(c_o) dE[H1]_o/dp_q` for the cotangent `c` (`[line * n_out + k]`).
    pub fn vjp(&self, c: &[C64]) -> Vec<f64> {
        let n = self.n_out;
        let zero = C64::new(0.0, 0.0);
        // b_j,k: the cotangent pulled back to the evaluation grid, conjugated (so that
        // g_q = Re sum_j,k b_jk dh_jk dE/dp_q(j)).
        let scaled: Vec<C64>;
        let (c_lines, c) = match &self.factor {
            Some(f) => {
                scaled = c.iter().zip(f).map(|(z, f)| z * f.conj()).collect();
                (c, &scaled[..])
            }
            None => (c, c),
        };
        let grid_len = if self.grid_jac.is_empty() {
            self.dh.len()
        } else {
            self.grid_jac.iter().map(Vec::len).max().unwrap_or(0)
        };
        let b: Vec<C64> = match &self.rows {
            None => c.iter().map(|z| z.conj()).collect(),
            Some(rows) => {
                let mut b = vec![zero; grid_len];
                for (l, terms) in rows.iter().enumerate() {
                    let cl = &c[l * n..(l + 1) * n];
                    for t in terms {
                        let bj = &mut b[t.j * n..(t.j + 1) * n];
                        if t.mirror {
                            bj.iter_mut().zip(cl).for_each(|(a, z)| *a += z * t.weight);
                        } else {
                            bj.iter_mut()
                                .zip(cl)
                                .for_each(|(a, z)| *a += z.conj() * t.weight);
                        }
                    }
                }
                b
            }
        };
        let mut g: Vec<f64> = (0..self.n_params)
            .map(|q| {
                self.extra.get(q).map_or(0.0, |e| {
                    e.iter().zip(c_lines).map(|(a, z)| (z.conj() * a).re).sum()
                })
            })
            .collect();
        for (q, col) in self.grid_jac.iter().enumerate() {
            if !col.is_empty() {
                g[q] += b.iter().zip(col).map(|(x, y)| (x * y).re).sum::<f64>();
            }
        }
        for (j, (bj, dj)) in b.chunks(n).zip(self.dh.chunks(n)).enumerate() {
            let s: C64 = bj.iter().zip(dj).map(|(x, y)| x * y).sum();
            for (q, gq) in g.iter_mut().enumerate() {
                *gq += (s * self.dedp[j * self.n_params + q]).re;
            }
        }
        g
    }
}

impl ForwardModel<'_> {
    /// The prediction at `p` (as [`ForwardModel::predict`] without the Jacobian) and what its
    /// vector-Jacobian products need. A shaker's kernel weights are held fixed at `p`, as in
    /// `predict`.
    pub fn linearise(&self, p: &[f64]) -> Result<Linearised<'_>, ForwardError> {
        self.check(p)?;
        if !self.effects.is_empty() {
            return self.linearise_with_effects(p);
        }
        let np = self.law.n_params();
        let measurement = self
            .obs
            .measurement
            .as_ref()
            .filter(|_| self.linear_bias.is_none());
        let omega = match measurement {
            None => self.obs.omega_rad_s.clone(),
            Some(m) => m.fine_omega(),
        };
        let modulus: Vec<C64> = omega.iter().map(|&w| self.law.modulus(p, w)).collect();
        let (h, dh, drive) = self.obs.accelerance_and_drive(&omega, &modulus, true)?;
        let mut dedp = vec![C64::new(0.0, 0.0); omega.len() * np];
        for (j, &w) in omega.iter().enumerate() {
            self.law.jacobian(p, w, &mut dedp[j * np..(j + 1) * np]);
        }
        let n = self.obs.outputs.len();
        let (mut values, rows) = match measurement {
            None => (h, None),
            Some(m) => {
                let rows = m.rows_for_drive(&drive);
                (MeasurementModel::apply(&rows, &h, n), Some(rows))
            }
        };
        let mut extra = Vec::new();
        if let Some(lb) = &self.linear_bias {
            lb.add_to(p, &mut values, Some(&mut extra));
        }
        Ok(Linearised {
            values,
            n_out: n,
            n_params: np,
            dh,
            dedp,
            rows,
            extra,
            grid_jac: Vec::new(),
            factor: None,
        })
    }
}

impl ForwardModel<'_> {
    /// [`ForwardModel::linearise`] with effects: the Jacobian columns of the structure and law
    /// on the evaluation grid (the lines, or the measurement model's fine grid), pulled back by
    /// one adjoint pass of the kernel instead of one forward pass per column; channel effects
    /// act at the lines (the cotangent of the structural part is `c conj(f)` for the channel
    /// factor `f`; the gain and delay columns are kept at the lines).
    fn linearise_with_effects(&self, p: &[f64]) -> Result<Linearised<'_>, ForwardError> {
        let nl = self.law.n_params();
        let n = self.obs.outputs.len();
        let measurement = self
            .obs
            .measurement
            .as_ref()
            .filter(|_| self.linear_bias.is_none());
        let omega = match measurement {
            None => self.obs.omega_rad_s.clone(),
            Some(m) => m.fine_omega(),
        };
        let (mut grid, drive) = self.exact_on(&omega, p, true)?;
        // The linearised bias is structural: it joins the values and the grid's columns (on
        // the lines) before the channel factor.
        if let Some(lb) = &self.linear_bias {
            lb.add_to(p, &mut grid.values, Some(&mut grid.jac));
        }
        let (mut values, rows) = match measurement {
            None => (grid.values, None),
            Some(m) => {
                let rows = m.rows_for_drive(&drive);
                (MeasurementModel::apply(&rows, &grid.values, n), Some(rows))
            }
        };
        let all = self.effects.values(&p[nl..]);
        let factor = self.channel_factor(&all);
        values.iter_mut().zip(&factor).for_each(|(a, f)| *a *= f);
        let mut grid_jac = grid.jac;
        let mut extra = vec![Vec::new(); p.len()];
        let mut q = nl;
        for (term, v) in self.effects.terms.iter().zip(&all) {
            if !term.free {
                continue;
            }
            let col: Option<Vec<C64>> = match term.effect {
                Effect::Gain { channel, .. } => Some(
                    (0..values.len())
                        .map(|o| {
                            if o % n == channel {
                                values[o] / (1.0 + v)
                            } else {
                                C64::new(0.0, 0.0)
                            }
                        })
                        .collect(),
                ),
                Effect::Delay { channel, .. } => Some(
                    (0..values.len())
                        .map(|o| {
                            if o % n == channel {
                                C64::new(0.0, -self.obs.omega_rad_s[o / n]) * values[o]
                            } else {
                                C64::new(0.0, 0.0)
                            }
                        })
                        .collect(),
                ),
                _ => None,
            };
            if let Some(col) = col {
                extra[q] = col;
                grid_jac[q] = Vec::new();
            }
            q += 1;
        }
        Ok(Linearised {
            values,
            n_out: n,
            n_params: p.len(),
            dh: Vec::new(),
            dedp: Vec::new(),
            rows,
            extra,
            grid_jac,
            factor: Some(factor),
        })
    }
}

impl LinearBias {
    /// Add `b0 + sum_q jac_q d_q` to `values`, `d_q = ln p_q - ln p0_q` (law) or
    /// `p_q - p0_q` (effects), and, when given, `jac_q / p_q` or `jac_q` to the Jacobian
    /// columns (created when empty).
    fn add_to(&self, p: &[f64], values: &mut [C64], jac: Option<&mut Vec<Vec<C64>>>) {
        for (o, v) in values.iter_mut().enumerate() {
            *v += self.b0[o];
        }
        for (q, col) in self.jac.iter().enumerate() {
            let d = if q < self.n_log {
                (p[q] / self.p0[q]).ln()
            } else {
                p[q] - self.p0[q]
            };
            for (v, a) in values.iter_mut().zip(col) {
                *v += a * d;
            }
        }
        if let Some(jac) = jac {
            if jac.is_empty() {
                *jac = vec![vec![C64::new(0.0, 0.0); values.len()]; self.jac.len()];
            }
            for (q, col) in self.jac.iter().enumerate() {
                for (j, a) in jac[q].iter_mut().zip(col) {
                    *j += if q < self.n_log { a / p[q] } else { *a };
                }
            }
        }
    }
}

/// Step in `ln p` of the central differences of the measurement bias in the law's parameters
/// (a posterior sd of `ln p` is a few 1e-4 on the default data: the slope is the one across
/// the posterior; the differencing error is second order in the step: 4e-8 of the slope on
/// the suite's test chain).
const BIAS_STEP_LN: f64 = 1e-4;

impl ForwardModel<'_> {
    /// The measurement model's bias `E[H1] - H` at `p` on the lines (no linearised bias set).
    fn bias_at(&self, p: &[f64]) -> Result<Vec<C64>, ForwardError> {
        let full = self.predict_structure(p, false)?;
        let exact = self.exact_on(&self.obs.omega_rad_s, p, false)?.0;
        Ok(full
            .values
            .iter()
            .zip(&exact.values)
            .map(|(a, b)| a - b)
            .collect())
    }

    /// Replace the measurement operator by its bias linearised at `p0` (the law's parameters
    /// in `ln p`, the free effects' in `p`): exact at `p0`, second order in the step elsewhere,
    /// and as cheap as the exact accelerance at the lines. The bias is a few per cent of `H` at
    /// the peaks and varies slowly with `p`: the neglected term is 2.7e-4 of `|H|` at the worst
    /// line 1 % from `p0` on the test chain, a quarter of that at 0.5 %
    /// (tests/suite/inference_likelihood.rs), so within a posterior (sds of a fraction of a per
    /// cent) it is far below the H1 random error; each run checks it on posterior draws
    /// (`bayes::linearisation`). `p0` holds the law's parameters; with effects in the model this
    /// does nothing (see [`Self::linearise_model_measurement`]), nor without a measurement
    /// model.
    pub fn linearise_measurement(&mut self, p0: &[f64]) -> Result<(), ForwardError> {
        if !self.effects.is_empty() {
            self.linear_bias = None;
            return Ok(());
        }
        self.linearise_model_measurement(p0)
    }

    /// [`Self::linearise_measurement`] at `p0` holding every parameter of the model (the
    /// law's, linearised in `ln p`, then the free effects', in `p`): the closed loop's searches
    /// on a term ROM run on it. The bias is the structure's: channel gains and delays act on it
    /// as on the exact response. Without a measurement model this does nothing.
    pub fn linearise_model_measurement(&mut self, p0: &[f64]) -> Result<(), ForwardError> {
        self.linear_bias = None;
        if self.obs.measurement.is_none() {
            return Ok(());
        }
        if p0.len() != self.n_params() {
            return Err(ForwardError::Setup(format!(
                "linearising the measurement bias: {} values for the model's {} parameters",
                p0.len(),
                self.n_params()
            )));
        }
        let nl = self.law.n_params();
        let full = self.predict_structure(p0, true)?;
        let exact = self.exact_on(&self.obs.omega_rad_s, p0, true)?.0;
        let b0 = full
            .values
            .iter()
            .zip(&exact.values)
            .map(|(a, b)| a - b)
            .collect();
        let mut jac: Vec<Vec<C64>> = full
            .jac
            .iter()
            .zip(&exact.jac)
            .zip(p0)
            .enumerate()
            .map(|(q, ((a, b), p))| {
                let s = if q < nl { *p } else { 1.0 };
                a.iter().zip(b).map(|(x, y)| (x - y) * s).collect()
            })
            .collect();
        // A shaker's force spectrum follows the drive-point response, so the kernel's weights
        // depend on the law's parameters too; the Jacobian above holds them fixed. That part is
        // small against the bias but not against the likelihood of a law that misfits by far
        // more than the noise (at 5e5 nats below the best law, it tilted the posterior by
        // several sds): the law's columns are central differences of the whole bias in `ln p`.
        // The free effects' columns keep the weights fixed: an effect's size starts at zero,
        // with no scale to difference it on.
        if self
            .obs
            .measurement
            .as_ref()
            .is_some_and(|m| m.spec.shaker.is_some())
        {
            for (q, col) in jac.iter_mut().enumerate().take(nl) {
                let mut p = p0.to_vec();
                p[q] = p0[q] * BIAS_STEP_LN.exp();
                let plus = self.bias_at(&p)?;
                p[q] = p0[q] * (-BIAS_STEP_LN).exp();
                let minus = self.bias_at(&p)?;
                for ((c, a), b) in col.iter_mut().zip(&plus).zip(&minus) {
                    *c = (a - b) / (2.0 * BIAS_STEP_LN);
                }
            }
        }
        self.linear_bias = Some(LinearBias {
            p0: p0.to_vec(),
            b0,
            jac,
            n_log: nl,
        });
        Ok(())
    }
}
