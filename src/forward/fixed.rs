//! A study's declared structural effects at fixed values as an FRF engine, so that the
//! deterministic analyses (RFM, its leakage correction, FRAC) see the same structure as the
//! likelihood and the closed loop ([`super::Effects::structural`]).
//!
//! ```text
//!   beam factor b:   H(w, E*; b) = H0(w / sqrt(s), E* / s) / s,   s = 1 + b
//!                    dH/dE' = dH0/dE'(...) / s^2,   S H = (S H0)(...) / s
//!   point masses P:  H' = H - H_:P X,         X = (I + D H_PP)^-1 D H_P:,   D = diag(-w^2 m)
//!                    S H' = S H - (S H)_:P X                       (rows: any output)
//!                    dH' = dH - dH_:P X - H_:P Y,  Y = (I + D H_PP)^-1 D (dH_P: - dH_PP X)
//! ```
//!
//! The mass identity is Woodbury's on M + sum m_k b_k b_k^T; its E'-derivative follows from
//! d(A^-1) = -A^-1 dA A^-1 with A = I + D H_PP. Every mass point must be an engine input (the
//! run builds the deterministic engine with every measured point as an input, so a mass
//! at a measured point qualifies). Exact algebra on the certified engine's outputs: the
//! wrapped engine is as accurate as the engine. The shaker and law effects are not
//! structural transforms of all columns ([`FixedEffectsEngine::unsupported`] names them);
//! gains and delays are measurement effects, undone on the data instead
//! ([`measurement_factor`]).

use super::effects::{small_solve, Effect, Effects};
use crate::common::C64;
use crate::frf::{FrfEngine, FrfError, Sweep};

/// The engine `inner` with fixed point masses and a beam-modulus factor.
pub struct FixedEffectsEngine<'a> {
    inner: &'a dyn FrfEngine,
    /// (output index, input position, mass kg).
    masses: Vec<(usize, usize, f64)>,
    /// Beam modulus factor b (`E_beam = (1 + b) E_beam,declared`).
    beam: f64,
}

impl<'a> FixedEffectsEngine<'a> {
    /// The engine with the point masses and beam factor of `effects` at their values (free
    /// ones at their starting values). Errors when a mass point is not an engine input.
    pub fn new(inner: &'a dyn FrfEngine, effects: &Effects) -> Result<Self, FrfError> {
        let mut masses = Vec::new();
        let mut beam = 0.0;
        for t in &effects.terms {
            match t.effect {
                // A sensor mass is the same mass at its x, y and z points.
                Effect::PointMass { .. } | Effect::SensorMass { .. } => {
                    let points: &[usize] = match &t.effect {
                        Effect::PointMass { point, .. } => std::slice::from_ref(point),
                        Effect::SensorMass { points, .. } => points,
                        _ => unreachable!("matched above"),
                    };
                    for &point in points {
                        let pos = inner
                            .inputs()
                            .iter()
                            .position(|&j| j == point)
                            .ok_or(FrfError::BadInput(point))?;
                        masses.push((point, pos, t.value));
                    }
                }
                Effect::BeamModulus => beam += t.value,
                _ => {}
            }
        }
        Ok(FixedEffectsEngine {
            inner,
            masses,
            beam,
        })
    }

    /// Whether the wrapper changes anything.
    pub fn is_identity(&self) -> bool {
        self.masses.is_empty() && self.beam == 0.0
    }

    /// Names of the effects in `effects` that neither this engine nor [`measurement_factor`]
    /// applies (the shaker, law effects): the deterministic analyses run without them.
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
    /// The point masses as (output index, kg).
    pub fn masses(&self) -> Vec<(usize, f64)> {
        self.masses.iter().map(|&(p, _, m)| (p, m)).collect()
    }
    /// The beam modulus factor b.
    pub fn beam_factor(&self) -> f64 {
        self.beam
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
        let s = 1.0 + self.beam;
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
        let s = 1.0 + self.beam;
        if s <= 0.0 {
            return Err(FrfError::Other(format!(
                "beam modulus factor {} leaves no beam stiffness",
                self.beam
            )));
        }
        if self.beam == 0.0 {
            self.inner
                .sweep_into(omega_rad_s, modulus_pa, with_derivatives, out)?;
        } else {
            let w: Vec<f64> = omega_rad_s.iter().map(|w| w / s.sqrt()).collect();
            let e: Vec<C64> = modulus_pa.iter().map(|e| e / s).collect();
            self.inner.sweep_into(&w, &e, with_derivatives, out)?;
            out.h.iter_mut().for_each(|v| *v /= s);
            out.sh.iter_mut().for_each(|v| *v /= s);
            out.dh_de.iter_mut().for_each(|v| *v /= s * s);
        }
        if self.masses.is_empty() {
            return Ok(());
        }
        let (n_out, n_in, np) = (out.n_out, out.n_in, self.masses.len());
        let derivs = with_derivatives && !out.dh_de.is_empty();
        for (l, &w) in omega_rad_s.iter().enumerate() {
            let at = |v: &[C64], o: usize, i: usize| v[(l * n_out + o) * n_in + i];
            let d: Vec<f64> = self.masses.iter().map(|m| -w * w * m.2).collect();
            // A = I + D H_PP, row a scaled by d_a.
            let mut a = vec![C64::new(0.0, 0.0); np * np];
            for (ra, ma) in self.masses.iter().enumerate() {
                for (cb, mb) in self.masses.iter().enumerate() {
                    a[ra * np + cb] = d[ra] * at(&out.h, ma.0, mb.1);
                }
                a[ra * np + ra] += 1.0;
            }
            let mut rhs = vec![C64::new(0.0, 0.0); np * n_in];
            for (ra, ma) in self.masses.iter().enumerate() {
                for i in 0..n_in {
                    rhs[ra * n_in + i] = d[ra] * at(&out.h, ma.0, i);
                }
            }
            let singular = || {
                FrfError::Other(format!(
                    "point masses: I + D H_PP is singular at line {l} ({w} rad/s)"
                ))
            };
            let x = small_solve(&a, np, &rhs, n_in).ok_or_else(singular)?;
            let y = if derivs {
                for (ra, ma) in self.masses.iter().enumerate() {
                    for i in 0..n_in {
                        let mut v = at(&out.dh_de, ma.0, i);
                        for (cb, mb) in self.masses.iter().enumerate() {
                            v -= at(&out.dh_de, ma.0, mb.1) * x[cb * n_in + i];
                        }
                        rhs[ra * n_in + i] = d[ra] * v;
                    }
                }
                Some(small_solve(&a, np, &rhs, n_in).ok_or_else(singular)?)
            } else {
                None
            };
            // Corrections from the unmodified values, then applied (H_:P and dH_:P are read
            // before they change).
            let mut dh_new = Vec::new();
            if let Some(y) = &y {
                dh_new.reserve(n_out * n_in);
                for o in 0..n_out {
                    for i in 0..n_in {
                        let mut v = at(&out.dh_de, o, i);
                        for (cb, mb) in self.masses.iter().enumerate() {
                            v -= at(&out.dh_de, o, mb.1) * x[cb * n_in + i]
                                + at(&out.h, o, mb.1) * y[cb * n_in + i];
                        }
                        dh_new.push(v);
                    }
                }
            }
            let correct = |v: &[C64]| -> Vec<C64> {
                let mut r = Vec::with_capacity(n_out * n_in);
                for o in 0..n_out {
                    for i in 0..n_in {
                        let mut c = at(v, o, i);
                        for (cb, mb) in self.masses.iter().enumerate() {
                            c -= at(v, o, mb.1) * x[cb * n_in + i];
                        }
                        r.push(c);
                    }
                }
                r
            };
            let h_new = correct(&out.h);
            let sh_new = if out.sh.is_empty() {
                Vec::new()
            } else {
                correct(&out.sh)
            };
            let base = l * n_out * n_in;
            out.h[base..base + n_out * n_in].copy_from_slice(&h_new);
            if !sh_new.is_empty() {
                out.sh[base..base + n_out * n_in].copy_from_slice(&sh_new);
            }
            if !dh_new.is_empty() {
                out.dh_de[base..base + n_out * n_in].copy_from_slice(&dh_new);
            }
        }
        Ok(())
    }
}
