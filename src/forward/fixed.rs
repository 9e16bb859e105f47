//! A study's declared structural effects at fixed values as an FRF engine, so that the
//! deterministic analyses (RFM, its leakage correction, FRAC) see the same structure as the
//! likelihood and the closed loop. The algebra is the forward model's own
//! ([`super::Effects::structural_sweep`], the transform of [`super::Effects::structural`] applied
//! to every input column):
//!
//! ```text
//!   beam factor b:   H(w, E*; b) = H0(w / sqrt(s), E* / s) / s,   s = 1 + b
//!   point masses P:  H' = H - H_:P X,   X = (I + D H_PP)^-1 D H_P:,   D = diag(-w^2 m)
//!                    S H' = S H - (S H)_:P X,   and dH' by the product rule
//! ```
//!
//! Every mass point must be an engine input (the run builds the deterministic engine with every
//! measured point as an input, so a mass at a measured point qualifies). The shaker and law
//! effects are not structural transforms of all columns, and a resonator's modes need its mass
//! as a DOF of the model, which the modal analyses do not build
//! ([`FixedEffectsEngine::unsupported`] names them); gains and delays are measurement effects,
//! undone on the data instead ([`measurement_factor`]).

use super::effects::{Effect, EffectTerm, Effects};
use crate::common::C64;
use crate::frf::{FrfEngine, FrfError, Sweep};

/// The engine `inner` with fixed point masses and a beam-modulus factor.
pub struct FixedEffectsEngine<'a> {
    inner: &'a dyn FrfEngine,
    /// The point masses and the beam factor of the effects given, at their values.
    effects: Effects,
    values: Vec<f64>,
}

impl<'a> FixedEffectsEngine<'a> {
    /// The engine with the point masses and beam factor of `effects` at their values (free
    /// ones at their starting values). Errors when a mass point is not an engine input.
    pub fn new(inner: &'a dyn FrfEngine, effects: &Effects) -> Result<Self, FrfError> {
        let terms: Vec<EffectTerm> = effects
            .terms
            .iter()
            .filter(|t| {
                matches!(
                    t.effect,
                    Effect::PointMass { .. } | Effect::SensorMass { .. } | Effect::BeamModulus
                )
            })
            .cloned()
            .collect();
        for t in &terms {
            let points: &[usize] = match &t.effect {
                Effect::PointMass { point, .. } => std::slice::from_ref(point),
                // A sensor mass is the same mass at its x, y and z points.
                Effect::SensorMass { points, .. } => points,
                _ => &[],
            };
            if let Some(&p) = points.iter().find(|p| !inner.inputs().contains(p)) {
                return Err(FrfError::BadInput(p));
            }
        }
        let values = terms.iter().map(|t| t.value).collect();
        Ok(FixedEffectsEngine {
            inner,
            effects: Effects { terms },
            values,
        })
    }

    /// Whether the wrapper changes anything.
    pub fn is_identity(&self) -> bool {
        self.masses().is_empty() && self.beam_factor() == 0.0
    }

    /// Names of the effects in `effects` that neither this engine nor [`measurement_factor`]
    /// applies (the shaker, resonators, law effects): the deterministic analyses run without them.
    pub fn unsupported(effects: &Effects) -> Vec<String> {
        effects
            .terms
            .iter()
            .filter(|t| {
                !matches!(
                    t.effect,
                    Effect::PointMass { .. }
                        | Effect::SensorMass { .. }
                        | Effect::BeamModulus
                        | Effect::Gain { .. }
                        | Effect::Delay { .. }
                )
            })
            .map(|t| t.effect.name())
            .collect()
    }
}

/// The measurement factor of output `k` at `omega` (rad/s) from the gains and delays of
/// `effects`: `(1 + g) exp(-j w tau)`. Data divided by it are the structure's response.
pub fn measurement_factor(effects: &Effects, k: usize, omega: f64) -> C64 {
    let mut f = C64::new(1.0, 0.0);
    for t in &effects.terms {
        match t.effect {
            Effect::Gain { channel, .. } if channel == k => f *= 1.0 + t.value,
            Effect::Delay { channel, .. } if channel == k => {
                f *= C64::from_polar(1.0, -omega * t.value)
            }
            _ => {}
        }
    }
    f
}

impl FixedEffectsEngine<'_> {
    /// The point masses as (output index, kg), a sensor mass once per direction.
    pub fn masses(&self) -> Vec<(usize, f64)> {
        let mut out = Vec::new();
        for (t, &m) in self.effects.terms.iter().zip(&self.values) {
            match &t.effect {
                Effect::PointMass { point, .. } => out.push((*point, m)),
                Effect::SensorMass { points, .. } => out.extend(points.iter().map(|&p| (p, m))),
                _ => {}
            }
        }
        out
    }
    /// The beam modulus factor b.
    pub fn beam_factor(&self) -> f64 {
        self.effects
            .terms
            .iter()
            .zip(&self.values)
            .filter(|(t, _)| matches!(t.effect, Effect::BeamModulus))
            .map(|(_, v)| v)
            .sum()
    }
}

impl FrfEngine for FixedEffectsEngine<'_> {
    /// Modes with the masses (the inner engine's, when it can add them) and the beam factor:
    /// the eigenvalues of (s K_b + j s D_b + E* S, M') are s times those of
    /// (K_b + j D_b + (E*/s) S, M'), with the same M'-normalised shapes, so phi^T S phi is
    /// unchanged.
    fn complex_modes(
        &self,
        modulus_pa: C64,
        n_modes: usize,
    ) -> Option<Result<Vec<crate::frf::EngineMode>, FrfError>> {
        let s = 1.0 + self.beam_factor();
        let r = self
            .inner
            .complex_modes_with_masses(modulus_pa / s, n_modes, &self.masses())?;
        Some(r.map(|mut modes| {
            for m in &mut modes {
                m.lambda *= s;
            }
            modes
        }))
    }

    fn n_out(&self) -> usize {
        self.inner.n_out()
    }

    fn inputs(&self) -> &[usize] {
        self.inner.inputs()
    }

    fn sweep_into(
        &self,
        omega_rad_s: &[f64],
        modulus_pa: &[C64],
        with_derivatives: bool,
        out: &mut Sweep,
    ) -> Result<(), FrfError> {
        crate::frf::check_line_lengths(omega_rad_s, modulus_pa)?;
        if self.effects.terms.is_empty() {
            return self
                .inner
                .sweep_into(omega_rad_s, modulus_pa, with_derivatives, out);
        }
        self.effects
            .structural_sweep(
                self.inner,
                omega_rad_s,
                modulus_pa,
                with_derivatives,
                &self.values,
                out,
            )
            .map_err(|e| FrfError::Other(e.to_string()))
    }
}
