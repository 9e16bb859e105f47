//! Effects the structure-and-law model may lack: named one-parameter extensions of the forward
//! model, each with its physics, SI unit, default prior and analytic
//! derivative.
//!
//! ```text
//!   gain of channel k:     E[H1]_k -> (1 + g) E[H1]_k                                  d/dg   = E[H1]_k
//!   delay of channel k:    E[H1]_k -> exp(-j w tau) E[H1]_k                            d/dtau = -j w (...)
//!   beam modulus factor:   K_b + j D_b -> (1 + b)(K_b + j D_b), so (no viscous C_b)
//!                          H(w, E*; b) = H(w / sqrt(1 + b), E* / (1 + b); 0) / (1 + b)   (exact scaling)
//!   Maxwell branch (tau):  E*(w) -> E*(w) + E_k j w tau / (1 + j w tau)                  d/dE_k = dH/dE' j w tau / (1 + j w tau)
//!   point mass at point P: M -> M + m b_P b_P^T (b_P the point's DOF weights; the measured
//!                          direction), so with D = -w^2 m and H_PP, H_oP, H_Pi read from the
//!                          engine (every measured point is an engine input):
//!                          H'_oi = H_oi - H_oP G D H_Pi,   G = (1 + D H_PP)^-1           (Sherman-Morrison-Woodbury)
//!   shaker (m_s on k_s):   force F read on the shaker's side of the stinger, at drive point d:
//!                          H''_od = H'_od s,   s = k_s / (k_s - w^2 m_s (1 + k_s H'_dd))
//!                          (armature -w^2 m_s x_s = F - f, stinger f = k_s (x_s - x_d));
//!                          m_s -> 0 gives H', k_s -> inf a point mass m_s at d
//!   resonator (m on k at P): a mass on a spring at point P, force read at the structure: the
//!                          point-mass identity with the frequency-dependent mass
//!                          m_eff(w) = m k / (k - w^2 m),   D = -w^2 m_eff,
//!                          dm_eff/dm = k^2 / (k - w^2 m)^2   (k -> inf gives a point mass m)
//!   degraded bond (x-range): E* S -> E* (S - d S_region), evaluated by an engine with the
//!                          region's term (crate::rom::terms, certified against the full model
//!                          with the strip degraded);  d/dd = -E* H_oG S_region,r H_Gi (reduced)
//!   adherend damping (g):  D_b -> D_b + g K_b (structural loss factor of the beam), a term
//!                          j g K_b of the same engine (offset j, no modulus part; with a beam
//!                          factor, (1 + b) j g K_b = j g K_b,actual);  d/dg = -j H_oG K_b,r H_Gi
//! ```
//!
//! Structural effects are exact algebraic transforms of the certified engine's receptances at
//! the observation points, so the ROM with an effect on is as accurate as the ROM itself: no
//! basis enrichment is needed (the mass identity needs only point receptances; the modulus
//! scaling evaluates the engine at another frequency inside its certified band). The point
//! mass acts in the measured direction only (a sensor's translational inertia along its axis).
//! The sensor mass acts in all three translations at its point: three point masses of the same
//! value at the point's x, y and z engine points (every one an engine input), `M -> M + m
//! (b_x b_x^T + b_y b_y^T + b_z b_z^T)`, the same Sherman-Morrison-Woodbury update with a 3 x 3
//! block, its derivative the sum of the three masses' columns (rotary inertia not modelled). The derivative in the beam factor is a central
//! difference (step 1e-6) of the exact transform; every other derivative is analytic. The
//! shaker acts after the point masses (on the drive-point receptance with the masses on); it
//! is tested against the full model with the moving mass as an extra DOF
//! ([`crate::fe::StructuralModel::with_shaker`], tests/suite/structural_effects.rs).

use crate::common::C64;
use crate::frf::FrfEngine;
use crate::stats::prior::Prior;

/// One kind of effect, with where it acts.
#[derive(Clone, Debug, PartialEq)]
pub enum Effect {
    /// Gain error of response channel `channel` (index into the observed outputs; `id` the
    /// channel's id for names).
    Gain { channel: usize, id: u32 },
    /// Time delay (s) of response channel `channel` against the force channel.
    Delay { channel: usize, id: u32 },
    /// A point mass (kg) at engine point `point` (an engine input), acting in the measured
    /// direction; `id` the point's id in the study.
    PointMass { point: usize, id: u32 },
    /// A sensor's mass (kg) at a point, acting in all three translations: `points` are the
    /// engine points (inputs) of the point's x, y and z directions; `id` the point's id.
    SensorMass { points: [usize; 3], id: u32 },
    /// The same sensor's mass (kg) at point `id`, in x, y and z, as a term of the engine's
    /// term ROM (`-w^2 m G`, `G` the mass matrix per unit mass over the point's three
    /// directions, [`crate::rom::terms::TermMap::Inertia`]): for an engine whose inputs are
    /// the measured directions only, such as the model on base springs (whose term ROM with
    /// every point's three directions as inputs would cost several times more per line).
    /// Named and typed as [`Effect::SensorMass`]: the two are the same physics.
    SensorMassTerm { id: u32 },
    /// Relative change of the adherends' (beam) modulus, `E_beam = (1 + b) E_beam,declared`.
    BeamModulus,
    /// A shaker's moving mass m_s (kg) on a stinger of stiffness `stiffness_n_m` at the drive
    /// point, with the force read on the shaker's side of the stinger (the force that drives
    /// the moving mass). A force gauge at the structure would not see the shaker at all.
    Shaker { stiffness_n_m: f64 },
    /// A resonator: a mass m (kg, the parameter) on a spring of stiffness `stiffness_n_m` at
    /// engine point `point` (an engine input), acting in the measured direction, with the force
    /// read at the structure: a compliant sensor or fixture mount, or a shaker's armature that
    /// stays attached while a gauge at the structure reads the force. It adds `-w^2 m_eff(w)`,
    /// `m_eff = m k / (k - w^2 m)`, to the dynamic stiffness at the point; `id` the point's id.
    Resonator {
        point: usize,
        id: u32,
        stiffness_n_m: f64,
    },
    /// One more Maxwell branch in the adhesive's law with relaxation time `tau_s` (s):
    /// `E* -> E* + E_k j w tau / (1 + j w tau)`, the parameter the branch modulus `E_k` (Pa).
    MaxwellBranch { tau_s: f64 },
    /// A degraded bond over the adhesive's x-range `[x_start_m, x_start_m + width_m]` (m):
    /// `E* S -> E* (S - d S_region)`, the parameter the loss fraction d in [0, 1) (the
    /// region keeps (1 - d) of its modulus). Needs an engine with the region's term
    /// ([`crate::rom::terms`]).
    DegradedBond { x_start_m: f64, width_m: f64 },
    /// A compliant base: distributed springs under the adhesive's lower face instead of a
    /// fixed face ([`crate::fe::base`]), the parameter the normal springs' compliance
    /// `c = 1 / k_n` (m^3/N; 0 is the fixed base), the tangential ones `k_t = k_n /
    /// normal_over_tangential`. Needs an engine with the base's term ([`crate::rom::terms`],
    /// a compliance term over the joint with its base free).
    BaseSprings { normal_over_tangential: f64 },
    /// Structural damping of the adherends (beam): `D_b -> D_b + g K_b`, the parameter the
    /// loss factor g (one-sided). Needs an engine with the term `K_b` ([`crate::rom::terms`]).
    AdherendDamping,
}

/// Default ratio of normal to tangential base stiffness: that of a thin elastic layer with
/// Poisson's ratio 0.3 (`E_oed / G = 2 (1 - nu) / (1 - 2 nu) = 3.5`).
pub const DEFAULT_BASE_NORMAL_OVER_TANGENTIAL: f64 = 3.5;

/// The shapes of base springs the closed loop tries (ratios of normal to tangential
/// stiffness): the thin elastic layer ([`DEFAULT_BASE_NORMAL_OVER_TANGENTIAL`]) and equal
/// springs (a support as stiff in its plane as normal to it). The shape is not a detail: on
/// the independent compliant base (equal springs) the layer's shape absorbs the springs with
/// the adhesive's parameters 2-4 % high, equal springs recover them within 1 sd.
pub const BASE_SPRING_SHAPES: [f64; 2] = [DEFAULT_BASE_NORMAL_OVER_TANGENTIAL, 1.0];

/// The name of base springs of shape `normal_over_tangential`: `base_springs` for the default
/// shape, `base_springs_iso` for equal springs, else `base_springs_nt<ratio>`.
pub fn base_springs_name(normal_over_tangential: f64) -> String {
    if normal_over_tangential == DEFAULT_BASE_NORMAL_OVER_TANGENTIAL {
        "base_springs".into()
    } else if normal_over_tangential == 1.0 {
        "base_springs_iso".into()
    } else {
        format!("base_springs_nt{normal_over_tangential}")
    }
}

/// Name of the adherend-damping term and parameter.
pub const ADHEREND_DAMPING: &str = "adherend_damping";

/// Default width of a degraded-bond candidate at each end of the block (m).
pub const DEFAULT_BOND_STRIP_M: f64 = 0.010;

/// Default stinger stiffness of a shaker candidate (N/m): a thin steel rod some 10 cm long.
pub const DEFAULT_STINGER_STIFFNESS_N_M: f64 = 2e5;

/// Default spring of a resonator candidate (N/m): a compliant mount or a stinger-like link, the
/// shaker's default stinger (20 g on it resonates at 503 Hz).
pub const DEFAULT_RESONATOR_STIFFNESS_N_M: f64 = 2e5;

impl Effect {
    /// Name of the effect's parameter, as in tables.
    pub fn name(&self) -> String {
        match self {
            Effect::Gain { id, .. } => format!("gain_ch{id}"),
            Effect::Delay { id, .. } => format!("delay_ch{id}"),
            Effect::PointMass { id, .. } => format!("mass_pt{id}"),
            Effect::SensorMass { id, .. } | Effect::SensorMassTerm { id } => {
                format!("mass3_pt{id}")
            }
            Effect::BeamModulus => "beam_modulus".into(),
            Effect::Shaker { .. } => "shaker_mass".into(),
            Effect::Resonator { id, .. } => format!("resonator_pt{id}"),
            Effect::MaxwellBranch { tau_s } => {
                format!("maxwell_fc{:.0}hz", 1.0 / (std::f64::consts::TAU * tau_s))
            }
            Effect::DegradedBond { x_start_m, width_m } => {
                format!("bond_x{:.1}mm_w{:.1}mm", 1e3 * x_start_m, 1e3 * width_m)
            }
            Effect::BaseSprings {
                normal_over_tangential,
            } => base_springs_name(*normal_over_tangential),
            Effect::AdherendDamping => ADHEREND_DAMPING.into(),
        }
    }
    /// Type of the effect (a study's `type` key).
    pub fn kind(&self) -> &'static str {
        match self {
            Effect::Gain { .. } => "gain",
            Effect::Delay { .. } => "delay",
            Effect::PointMass { .. } => "point_mass",
            Effect::SensorMass { .. } | Effect::SensorMassTerm { .. } => "sensor_mass",
            Effect::BeamModulus => "beam_modulus",
            Effect::Shaker { .. } => "shaker",
            Effect::Resonator { .. } => "resonator",
            Effect::MaxwellBranch { .. } => "maxwell_branch",
            Effect::DegradedBond { .. } => "degraded_bond",
            Effect::BaseSprings { .. } => "base_springs",
            Effect::AdherendDamping => ADHEREND_DAMPING,
        }
    }
    /// SI unit of the parameter.
    pub fn unit(&self) -> &'static str {
        match self {
            Effect::Gain { .. }
            | Effect::BeamModulus
            | Effect::DegradedBond { .. }
            | Effect::AdherendDamping => "1",
            Effect::Delay { .. } => "s",
            Effect::PointMass { .. }
            | Effect::SensorMass { .. }
            | Effect::SensorMassTerm { .. }
            | Effect::Shaker { .. }
            | Effect::Resonator { .. } => "kg",
            Effect::MaxwellBranch { .. } => "Pa",
            Effect::BaseSprings { .. } => "m^3/N",
        }
    }
    /// A sentence of physics for the report.
    pub fn physics(&self) -> String {
        match self {
            Effect::Gain { id, .. } => format!(
                "channel {id} reads (1 + g) times the true response: a sensitivity (calibration) error of its accelerometer or conditioner"
            ),
            Effect::Delay { id, .. } => format!(
                "channel {id} lags the force by tau: a phase growing linearly with frequency (anti-alias filter or acquisition skew)"
            ),
            Effect::PointMass { id, .. } => format!(
                "an undeclared mass m at point {id} (a sensor, cable or fixture) lowers the modes that move that point"
            ),
            Effect::SensorMass { id, .. } | Effect::SensorMassTerm { id } => format!(
                "an undeclared mass m at point {id} (a sensor, cable or fixture) with its inertia in x, y and z lowers the modes that move that point in any direction"
            ),
            Effect::BeamModulus => "the adherends' modulus differs from the declared one by a factor (1 + b): all beam-dominated modes shift by sqrt(1 + b)".into(),
            Effect::Shaker { stiffness_n_m } => format!(
                "a shaker's moving mass m_s on a {stiffness_n_m:.3e} N/m stinger at the drive point, with the force read on the shaker's side of the stinger, loads the drive point and adds a stinger-armature resonance"
            ),
            Effect::Resonator { id, stiffness_n_m, .. } => format!(
                "a mass m on a {stiffness_n_m:.3e} N/m spring at point {id} (a compliant sensor or fixture mount, or a shaker's armature with the force read at the structure) adds its own resonance at sqrt(k / m): it loads the point like a mass below that frequency and pins it there (an antiresonance)"
            ),
            Effect::MaxwellBranch { tau_s } => format!(
                "the adhesive relaxes also near {:.1} Hz (tau = {tau_s:.3e} s): one more Maxwell branch E_k j w tau / (1 + j w tau) adds stiffness above and loss around that frequency (the law's relaxation spectrum is too narrow, e.g. a fractional-law adhesive)",
                1.0 / (std::f64::consts::TAU * tau_s)
            ),
            Effect::DegradedBond { x_start_m, width_m } => format!(
                "the bond over x = {:.1}-{:.1} mm of the adhesive block keeps only (1 - d) of its modulus (a debonded or poorly cured strip): the joint softens where the peel and shear stresses concentrate",
                1e3 * x_start_m,
                1e3 * (x_start_m + width_m)
            ),
            Effect::BaseSprings { normal_over_tangential } => format!(
                "the base under the adhesive is not rigid: distributed springs of compliance c = 1 / k_n normal to it (and {normal_over_tangential} times softer in its plane) act in series with the adhesive layer, softening the joint much as a softer adhesive would (confounded with the adhesive's stiffness; the springs add no damping)"
            ),
            Effect::AdherendDamping => "the adherends (steel beam) dissipate energy: a structural loss factor g adds j g K_b to the beam's stiffness, widening the beam-dominated resonances by about g times the beam's share of the modal strain energy".into(),
        }
    }
    /// Value at which the effect is absent.
    pub fn null_value(&self) -> f64 {
        0.0
    }
    /// Whether the parameter is one-sided (a mass is >= 0): the score test is then one-sided
    /// (Self and Liang 1987: a 50:50 mixture of chi-square 0 and 1).
    pub fn one_sided(&self) -> bool {
        matches!(
            self,
            Effect::PointMass { .. }
                | Effect::SensorMass { .. }
                | Effect::SensorMassTerm { .. }
                | Effect::Shaker { .. }
                | Effect::Resonator { .. }
                | Effect::MaxwellBranch { .. }
                | Effect::DegradedBond { .. }
                | Effect::BaseSprings { .. }
                | Effect::AdherendDamping
        )
    }
    /// Whether the effect has matrices of its own: a term of the term ROM
    /// ([`crate::rom::terms`]), evaluated by a dense solve of the reduced system per line
    /// instead of the pencil's sums (seconds per evaluation on a measurement model's fine grid).
    pub fn has_term_matrices(&self) -> bool {
        matches!(
            self,
            Effect::DegradedBond { .. }
                | Effect::BaseSprings { .. }
                | Effect::AdherendDamping
                | Effect::SensorMassTerm { .. }
        )
    }
    /// Whether the score test at zero is one-sided: that of a one-sided effect whose column at
    /// zero points the way a small size acts. Not a resonator's: at zero its column is a rigid
    /// mass's (`dm_eff/dm = 1`), but above its own frequency a finite one has a negative
    /// effective mass, so data that carry one may score a rigid mass below zero.
    pub fn score_one_sided(&self) -> bool {
        self.one_sided() && !matches!(self, Effect::Resonator { .. })
    }
    /// Admissible range (open) of the parameter.
    pub fn bounds(&self) -> (f64, f64) {
        match self {
            Effect::Gain { .. } => (-0.9, 9.0),
            Effect::Delay { .. } => (-0.01, 0.01),
            Effect::PointMass { .. }
            | Effect::SensorMass { .. }
            | Effect::SensorMassTerm { .. }
            | Effect::Shaker { .. }
            | Effect::Resonator { .. } => (-1e-12, 10.0),
            Effect::BeamModulus => (-0.9, 9.0),
            Effect::MaxwellBranch { .. } => (-1e-6, 1e11),
            Effect::DegradedBond { .. } => (-1e-9, 1.0),
            Effect::BaseSprings { .. } => (-1e-18, 1e-6),
            Effect::AdherendDamping => (-1e-12, 1.0),
        }
    }
    /// Default prior when the effect is free: uniform over a stated plausible range (the
    /// evidence depends on it: a ten times wider range costs ln 10 = 2.3 nats).
    /// gain +-20 %, delay +-1 ms, mass 0-100 g (a sensor, a shaker's moving mass, a
    /// resonator's), beam modulus +-20 %, Maxwell branch modulus 0-20 MPa (a few times the stiffness of the paper's adhesive, E0 about 5 MPa).
    /// Degraded bond: loss fraction uniform on [0, 1). Base springs: compliance 0-1e-9 m^3/N.
    /// Adherend damping: loss factor uniform on [0, 0.01] (steel beams and bolted or clamped
    /// fixtures: 1e-4 to a few 1e-3).
    pub fn default_prior(&self) -> Prior {
        match self {
            Effect::Gain { .. } | Effect::BeamModulus => Prior::Uniform { lo: -0.2, hi: 0.2 },
            Effect::Delay { .. } => Prior::Uniform {
                lo: -1e-3,
                hi: 1e-3,
            },
            Effect::PointMass { .. }
            | Effect::SensorMass { .. }
            | Effect::SensorMassTerm { .. }
            | Effect::Shaker { .. }
            | Effect::Resonator { .. } => Prior::Uniform { lo: 0.0, hi: 0.1 },
            Effect::MaxwellBranch { .. } => Prior::Uniform { lo: 0.0, hi: 2e7 },
            Effect::DegradedBond { .. } => Prior::Uniform { lo: 0.0, hi: 1.0 },
            // k_n >= 1e9 N/m^3: about the adhesive layer's own E_oed / t (2e9 for the paper's
            // 10 mm of Sikaflex); a base softer than that is not a base.
            Effect::BaseSprings { .. } => Prior::Uniform { lo: 0.0, hi: 1e-9 },
            Effect::AdherendDamping => Prior::Uniform { lo: 0.0, hi: 0.01 },
        }
    }
    /// The factor `dE*/dE_k = j w tau / (1 + j w tau)` of a Maxwell branch at `omega` (zero
    /// for every other effect).
    pub fn law_factor(&self, omega_rad_s: f64) -> C64 {
        match self {
            Effect::MaxwellBranch { tau_s } => {
                let jwt = C64::new(0.0, omega_rad_s * tau_s);
                jwt / (1.0 + jwt)
            }
            _ => C64::new(0.0, 0.0),
        }
    }
    fn is_structural(&self) -> bool {
        matches!(
            self,
            Effect::PointMass { .. }
                | Effect::SensorMass { .. }
                | Effect::SensorMassTerm { .. }
                | Effect::Resonator { .. }
                | Effect::BeamModulus
                | Effect::Shaker { .. }
                | Effect::DegradedBond { .. }
                | Effect::BaseSprings { .. }
                | Effect::AdherendDamping
        )
    }
}

/// An effect with its value, fixed or free.
#[derive(Clone, Debug, PartialEq)]
pub struct EffectTerm {
    pub effect: Effect,
    /// Value (SI) when fixed; the starting value when free.
    pub value: f64,
    /// Free: its value is a parameter of the forward model, after the law's.
    pub free: bool,
}

/// The effects of a forward model (none by default: the model is then unchanged).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Effects {
    pub terms: Vec<EffectTerm>,
}

/// What the structural part returns on a grid: accelerance `[line * n_out + k]`, its
/// derivative in E' (when asked), the drive-point accelerance, and one derivative column per
/// term (zero for channel effects; only when asked).
pub(crate) struct StructuralColumns {
    pub h: Vec<C64>,
    pub dh: Vec<C64>,
    /// `b_o^T S H_in` with the masses on (only for a full sweep, [`Effects::structural_sweep`]).
    pub sh: Vec<C64>,
    pub drive: Vec<C64>,
    pub d_terms: Vec<Vec<C64>>,
}

/// Dense complex solve of a small system (Gaussian elimination with partial pivoting);
/// returns `None` when singular.
pub(super) fn small_solve(a: &[C64], n: usize, b: &[C64], nrhs: usize) -> Option<Vec<C64>> {
    let mut a = a.to_vec();
    let mut x = b.to_vec();
    for c in 0..n {
        let piv = (c..n).max_by(|&i, &j| a[i * n + c].norm().total_cmp(&a[j * n + c].norm()))?;
        if a[piv * n + c].norm() == 0.0 {
            return None;
        }
        if piv != c {
            for k in 0..n {
                a.swap(c * n + k, piv * n + k);
            }
            for k in 0..nrhs {
                x.swap(c * nrhs + k, piv * nrhs + k);
            }
        }
        for r in c + 1..n {
            let f = a[r * n + c] / a[c * n + c];
            for k in c..n {
                let v = a[c * n + k];
                a[r * n + k] -= f * v;
            }
            for k in 0..nrhs {
                let v = x[c * nrhs + k];
                x[r * nrhs + k] -= f * v;
            }
        }
    }
    for c in (0..n).rev() {
        for k in 0..nrhs {
            let mut s = x[c * nrhs + k];
            for j in c + 1..n {
                s -= a[c * n + j] * x[j * nrhs + k];
            }
            x[c * nrhs + k] = s / a[c * n + c];
        }
    }
    Some(x)
}

impl Effects {
    pub fn is_empty(&self) -> bool {
        self.terms.is_empty()
    }
    /// Number of free parameters.
    pub fn n_free(&self) -> usize {
        self.terms.iter().filter(|t| t.free).count()
    }
    /// Names of the free parameters, in order.
    pub fn free_names(&self) -> Vec<String> {
        self.terms
            .iter()
            .filter(|t| t.free)
            .map(|t| t.effect.name())
            .collect()
    }
    /// Values of all terms, with the free ones taken from `free` (in order).
    pub fn values(&self, free: &[f64]) -> Vec<f64> {
        let mut it = free.iter();
        self.terms
            .iter()
            .map(|t| {
                if t.free {
                    *it.next().unwrap_or(&t.value)
                } else {
                    t.value
                }
            })
            .collect()
    }
    /// Whether any term has matrices of its own ([`Effect::has_term_matrices`]).
    pub fn has_term_matrices(&self) -> bool {
        self.terms.iter().any(|t| t.effect.has_term_matrices())
    }
    /// Whether any term changes the structure.
    pub fn has_structural(&self) -> bool {
        self.terms.iter().any(|t| t.effect.is_structural())
    }

    /// Check the terms against the engine and the observed channels.
    pub fn check(
        &self,
        engine: &dyn FrfEngine,
        n_channels: usize,
    ) -> Result<(), super::ForwardError> {
        let mut seen = Vec::new();
        for t in &self.terms {
            let name = t.effect.name();
            if seen.contains(&name) {
                return Err(super::ForwardError::Setup(format!(
                    "effect {name} is declared twice"
                )));
            }
            seen.push(name.clone());
            match t.effect {
                Effect::Gain { channel, .. } | Effect::Delay { channel, .. }
                    if channel >= n_channels =>
                {
                    return Err(super::ForwardError::Setup(format!(
                        "effect {name}: channel index {channel} is not observed ({n_channels} channels)"
                    )));
                }
                Effect::PointMass { point, .. } if !engine.inputs().contains(&point) => {
                    return Err(super::ForwardError::Setup(format!(
                        "effect {name}: point index {point} is not an input of the engine (a point mass needs the receptances of its point)"
                    )));
                }
                Effect::Resonator { point, .. } if !engine.inputs().contains(&point) => {
                    return Err(super::ForwardError::Setup(format!(
                        "effect {name}: point index {point} is not an input of the engine (a resonator needs the receptances of its point)"
                    )));
                }
                Effect::Resonator { stiffness_n_m, .. }
                    if !(stiffness_n_m.is_finite() && stiffness_n_m > 0.0) =>
                {
                    return Err(super::ForwardError::Setup(format!(
                        "effect {name}: spring stiffness {stiffness_n_m} N/m must be finite and > 0"
                    )));
                }
                Effect::SensorMass { points, .. }
                    if points.iter().any(|p| !engine.inputs().contains(p)) =>
                {
                    return Err(super::ForwardError::Setup(format!(
                        "effect {name}: the point's x, y and z directions (engine points {points:?}) must all be inputs of the engine (a sensor mass needs the receptances of all three)"
                    )));
                }
                Effect::Shaker { stiffness_n_m }
                    if !(stiffness_n_m.is_finite() && stiffness_n_m > 0.0) =>
                {
                    return Err(super::ForwardError::Setup(format!(
                        "effect {name}: stinger stiffness {stiffness_n_m} N/m must be finite and > 0"
                    )));
                }
                Effect::DegradedBond { .. }
                | Effect::BaseSprings { .. }
                | Effect::AdherendDamping
                | Effect::SensorMassTerm { .. }
                    if !engine.term_names().contains(&name) =>
                {
                    return Err(super::ForwardError::Setup(format!(
                        "effect {name}: the engine has no term for this effect (build it with rom::term_build::build_term_rom; terms: {:?})",
                        engine.term_names()
                    )));
                }
                Effect::MaxwellBranch { tau_s } if !(tau_s.is_finite() && tau_s > 0.0) => {
                    return Err(super::ForwardError::Setup(format!(
                        "effect {name}: relaxation time {tau_s} s must be positive"
                    )));
                }
                _ => {}
            }
            let (lo, hi) = t.effect.bounds();
            if !(t.value > lo && t.value < hi) {
                return Err(super::ForwardError::Setup(format!(
                    "effect {name}: value {} {} is outside ({lo}, {hi})",
                    t.value,
                    t.effect.unit()
                )));
            }
        }
        Ok(())
    }

    /// The beam modulus factor b among `values` (one per term; 0 without the effect).
    fn beam_factor(&self, values: &[f64]) -> f64 {
        self.terms
            .iter()
            .zip(values)
            .find(|(t, _)| matches!(t.effect, Effect::BeamModulus))
            .map_or(0.0, |(_, v)| *v)
    }

    /// The full sweep of `inner` (every output, every input column: receptance, and with
    /// `derivs` its E' derivative and `S H`) with this set's point masses and beam factor at
    /// `values` (one per term): what the deterministic analyses (RFM, IEM, FRAC) see of a
    /// study's declared effects. The same transform as the likelihood's columns
    /// ([`Self::structural`]), applied to each input column; the shaker and law effects are
    /// not structural transforms of all columns and are left out by the caller.
    pub(crate) fn structural_sweep(
        &self,
        inner: &dyn FrfEngine,
        omega: &[f64],
        modulus: &[C64],
        derivs: bool,
        values: &[f64],
        out: &mut crate::frf::Sweep,
    ) -> Result<(), super::ForwardError> {
        let beam = self.beam_factor(values);
        let scale = 1.0 + beam;
        if scale <= 0.0 {
            return Err(super::ForwardError::Setup(format!(
                "beam modulus factor {beam} leaves no beam stiffness"
            )));
        }
        let w_eng: Vec<f64> = omega.iter().map(|w| w / scale.sqrt()).collect();
        let e_eng: Vec<C64> = modulus.iter().map(|e| e / scale).collect();
        let sw = inner.sweep(&w_eng, &e_eng, derivs)?;
        let inputs = inner.inputs();
        let (n_out, n_in) = (sw.n_out, sw.n_in);
        let outputs: Vec<usize> = (0..n_out).collect();
        *out = crate::frf::Sweep::zeros(omega.len(), n_out, n_in, derivs);
        if sw.sh.is_empty() {
            out.sh.clear();
        }
        for (j, &input) in inputs.iter().enumerate() {
            let col = self.transform(
                &sw, inputs, input, &outputs, omega, derivs, values, scale, true,
            )?;
            for l in 0..omega.len() {
                for o in 0..n_out {
                    let (k, at) = (l * n_out + o, out.idx(l, o, j));
                    out.h[at] = col.h[k];
                    if derivs {
                        out.dh_de[at] = col.dh[k];
                    }
                    if !col.sh.is_empty() {
                        out.sh[at] = col.sh[k];
                    }
                }
            }
        }
        Ok(())
    }

    /// The engine inputs whose columns a sweep with these effects reads: the excitation
    /// `input` and every point a mass, sensor mass or resonator loads.
    pub(crate) fn inputs_needed(&self, input: usize) -> Vec<usize> {
        let mut out = vec![input];
        for t in &self.terms {
            match t.effect {
                Effect::PointMass { point, .. } | Effect::Resonator { point, .. } => {
                    out.push(point)
                }
                Effect::SensorMass { points, .. } => out.extend(points),
                _ => {}
            }
        }
        out
    }

    /// Structural part: the engine's receptances transformed by the beam factor and the point
    /// masses at `values` (one per term), read as accelerance at `outputs` driven at `input`.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn structural(
        &self,
        engine: &dyn FrfEngine,
        input: usize,
        outputs: &[usize],
        omega: &[f64],
        modulus: &[C64],
        derivs: bool,
        values: &[f64],
    ) -> Result<StructuralColumns, super::ForwardError> {
        // Only the columns the effects read, the excitation's and the loaded points', at the
        // rows they read: the outputs and those points. An effect with a term of its own
        // sweeps the terms' engine whole.
        let needed = self.inputs_needed(input);
        let rows: Vec<usize> = outputs.iter().chain(&needed).copied().collect();
        let fewer = (!self.has_term_matrices())
            .then(|| crate::frf::narrowed(engine, &needed, &rows))
            .flatten();
        let engine: &dyn FrfEngine = fewer.as_deref().unwrap_or(engine);
        let mut out =
            self.structural_values(engine, input, outputs, omega, modulus, derivs, values)?;
        if derivs {
            // The beam factor's column by a central difference of the exact transform.
            for (t, term) in self.terms.iter().enumerate() {
                if matches!(term.effect, Effect::BeamModulus) && term.free {
                    let step = 1e-6;
                    let mut vp = values.to_vec();
                    vp[t] += step;
                    let hp =
                        self.structural_values(engine, input, outputs, omega, modulus, false, &vp)?;
                    vp[t] -= 2.0 * step;
                    let hm =
                        self.structural_values(engine, input, outputs, omega, modulus, false, &vp)?;
                    out.d_terms[t] =
                        hp.h.iter()
                            .zip(&hm.h)
                            .map(|(a, b)| (a - b) / (2.0 * step))
                            .collect();
                }
            }
        }
        Ok(out)
    }

    #[allow(clippy::too_many_arguments)]
    fn structural_values(
        &self,
        engine: &dyn FrfEngine,
        input: usize,
        outputs: &[usize],
        omega: &[f64],
        modulus: &[C64],
        derivs: bool,
        values: &[f64],
    ) -> Result<StructuralColumns, super::ForwardError> {
        let beam = self.beam_factor(values);
        let scale = 1.0 + beam;
        let w_eng: Vec<f64> = omega.iter().map(|w| w / scale.sqrt()).collect();
        let e_eng: Vec<C64> = modulus.iter().map(|e| e / scale).collect();
        // Degraded bond regions: extra terms -d E* S_region of the engine (c = -d E*_eng,
        // since (1 + b)(K_b + j D_b) + E* (S - d S_r) = (1 + b)(K_b + j D_b + E*_eng (S - d S_r))).
        // Adherend damping: the term j g K_b (c = j g in the engine's coordinates too).
        let names = engine.term_names();
        let mut coefs = Vec::new();
        let mut term_of = Vec::new();
        // Base springs: the engine's compliance term (rom::terms::TermMap::Compliance, offset
        // 1) at v_eng = v (1 + b): the engine's Z is the true one divided by (1 + b), springs
        // K_s / v included, so dH/dv = dH_eng/dv_eng (the transform divides by scale^2).
        for (t, (term, v)) in self.terms.iter().zip(values).enumerate() {
            let (value, offset, per_modulus, dscale) = match term.effect {
                Effect::DegradedBond { .. } => (*v, C64::new(0.0, 0.0), -1.0, scale),
                // (1 + b) j g K_b of the actual beam is j g K_b of the engine's.
                Effect::AdherendDamping => (*v, C64::new(0.0, 1.0), 0.0, scale),
                Effect::BaseSprings { .. } => (*v * scale, C64::new(1.0, 0.0), 0.0, scale * scale),
                // -w^2 m G of the actual structure is -w_eng^2 m G of the engine's.
                Effect::SensorMassTerm { .. } => (*v, C64::new(1.0, 0.0), 0.0, scale),
                _ => continue,
            };
            let name = term.effect.name();
            let index = names.iter().position(|n| *n == name).ok_or_else(|| {
                super::ForwardError::Setup(format!(
                    "effect {name} needs an engine with its term (a ROM with terms, rom::terms)"
                ))
            })?;
            coefs.push(crate::frf::TermCoef {
                index,
                value,
                offset,
                per_modulus,
            });
            term_of.push((t, dscale));
        }
        if coefs.is_empty() {
            let sw = engine.sweep(&w_eng, &e_eng, derivs)?;
            return self.transform(
                &sw,
                engine.inputs(),
                input,
                outputs,
                omega,
                derivs,
                values,
                scale,
                false,
            );
        }
        let (mut sw, cols) = engine.sweep_terms(&w_eng, &e_eng, &coefs, derivs)?;
        let mut res = self.transform(
            &sw,
            engine.inputs(),
            input,
            outputs,
            omega,
            derivs,
            values,
            scale,
            false,
        )?;
        if derivs {
            // The transforms (masses, shaker) are linear in the receptances' derivative: the
            // E' path carries dH_eng/dd (times the scale, as it divides by scale^2).
            for ((t, dscale), col) in term_of.iter().zip(cols) {
                sw.dh_de = col.iter().map(|x| x * dscale).collect();
                let r = self.transform(
                    &sw,
                    engine.inputs(),
                    input,
                    outputs,
                    omega,
                    true,
                    values,
                    scale,
                    false,
                )?;
                res.d_terms[*t] = r.dh;
            }
        }
        Ok(res)
    }

    /// The transforms of the engine's sweep `sw` (at w / sqrt(scale), E* / scale) by the
    /// beam factor `scale`, the point masses and the shaker: accelerance, or receptance with
    /// `receptance` (then also `S H`, when `sw` has it).
    #[allow(clippy::too_many_arguments)]
    fn transform(
        &self,
        sw: &crate::frf::Sweep,
        inputs: &[usize],
        input: usize,
        outputs: &[usize],
        omega: &[f64],
        derivs: bool,
        values: &[f64],
        scale: f64,
        receptance: bool,
    ) -> Result<StructuralColumns, super::ForwardError> {
        let zero = C64::new(0.0, 0.0);
        let pos = |p: usize| inputs.iter().position(|&j| j == p);
        let jin = pos(input).ok_or(crate::frf::FrfError::BadInput(input))?;
        // Masses: (term index, point, engine input position, value, spring). A sensor mass is
        // three masses of the same value at its x, y and z points (M + m (w_x w_x^T + w_y w_y^T
        // + w_z w_z^T)); its derivative is the sum of the three columns. A resonator is a mass
        // on a spring: the same update with its effective mass ([`effective_mass`]).
        let masses: Vec<(usize, usize, usize, f64, Option<f64>)> = self
            .terms
            .iter()
            .zip(values)
            .enumerate()
            .flat_map(|(t, (term, v))| match term.effect {
                Effect::PointMass { point, .. } => pos(point)
                    .map(|j| (t, point, j, *v, None))
                    .into_iter()
                    .collect::<Vec<_>>(),
                Effect::Resonator {
                    point,
                    stiffness_n_m,
                    ..
                } => pos(point)
                    .map(|j| (t, point, j, *v, Some(stiffness_n_m)))
                    .into_iter()
                    .collect(),
                Effect::SensorMass { points, .. } => points
                    .iter()
                    .filter_map(|&p| pos(p).map(|j| (t, p, j, *v, None)))
                    .collect(),
                _ => Vec::new(),
            })
            .collect();
        let np = masses.len();
        let n = outputs.len();
        let nl = omega.len();
        let with_sh = receptance && derivs && !sw.sh.is_empty();
        let mut res = StructuralColumns {
            h: Vec::with_capacity(nl * n),
            dh: Vec::with_capacity(if derivs { nl * n } else { 0 }),
            sh: Vec::with_capacity(if with_sh { nl * n } else { 0 }),
            drive: Vec::with_capacity(nl),
            d_terms: if derivs {
                vec![vec![zero; nl * n]; self.terms.len()]
            } else {
                Vec::new()
            },
        };
        // The drive point's derivatives (E' and per term), needed by a shaker.
        let mut drive_dh: Vec<C64> = Vec::with_capacity(if derivs { nl } else { 0 });
        let mut drive_dt: Vec<Vec<C64>> = if derivs {
            vec![vec![zero; nl]; self.terms.len()]
        } else {
            Vec::new()
        };
        let shaker =
            self.terms
                .iter()
                .zip(values)
                .enumerate()
                .find_map(|(t, (term, v))| match term.effect {
                    Effect::Shaker { stiffness_n_m } => Some((t, stiffness_n_m, *v)),
                    _ => None,
                });
        // Targets: the outputs, then the drive point.
        let targets: Vec<usize> = outputs.iter().copied().chain([input]).collect();
        for (l, &w) in omega.iter().enumerate() {
            let acc = if receptance { 1.0 } else { -w * w };
            // Receptance (scaled back) and its E' derivative between point i and input pos j.
            let r = |i: usize, j: usize| sw.h[sw.idx(l, i, j)] / scale;
            let dr = |i: usize, j: usize| sw.dh_de[sw.idx(l, i, j)] / (scale * scale);
            let sr = |i: usize, j: usize| sw.sh[sw.idx(l, i, j)] / scale;
            if np == 0 {
                for (ti, &o) in targets.iter().enumerate() {
                    if ti == n {
                        res.drive.push(acc * r(o, jin));
                        if derivs {
                            drive_dh.push(acc * dr(o, jin));
                        }
                    } else {
                        res.h.push(acc * r(o, jin));
                        if derivs {
                            res.dh.push(acc * dr(o, jin));
                        }
                        if with_sh {
                            res.sh.push(acc * sr(o, jin));
                        }
                    }
                }
                continue;
            }
            // A = I + D H_PP (np x np), D = diag(-w^2 m_eff), with dm_eff/dm per mass.
            let (m_eff, dm_eff): (Vec<f64>, Vec<f64>) =
                masses.iter().map(|m| effective_mass(m.3, m.4, w)).unzip();
            let d: Vec<C64> = m_eff.iter().map(|m| C64::new(-w * w * m, 0.0)).collect();
            let mut a = vec![zero; np * np];
            for (p, mp) in masses.iter().enumerate() {
                for (q, mq) in masses.iter().enumerate() {
                    a[p * np + q] = d[p] * r(mp.1, mq.2) + if p == q { 1.0 } else { 0.0 };
                }
            }
            // u = G D H_Pi (np), and for the E' derivative also G D dH_Pi and G D dH_PP u.
            let hpi: Vec<C64> = masses.iter().map(|m| r(m.1, jin)).collect();
            let dhpi: Vec<C64> = hpi.iter().zip(&d).map(|(h, d)| d * h).collect();
            let u = small_solve(&a, np, &dhpi, 1).ok_or_else(|| {
                super::ForwardError::Frf(format!(
                    "the point masses make the structure singular at {} rad/s",
                    w
                ))
            })?;
            let (du, dpp_u) = if derivs {
                let x: Vec<C64> = masses
                    .iter()
                    .zip(&d)
                    .map(|(m, d)| d * dr(m.1, jin))
                    .collect();
                let du = small_solve(&a, np, &x, 1).expect("same matrix as above");
                // y = G D dH_PP u
                let z: Vec<C64> = (0..np)
                    .map(|p| {
                        d[p] * (0..np)
                            .map(|q| dr(masses[p].1, masses[q].2) * u[q])
                            .sum::<C64>()
                    })
                    .collect();
                let y = small_solve(&a, np, &z, 1).expect("same matrix as above");
                (du, y)
            } else {
                (Vec::new(), Vec::new())
            };
            // c = H_Pi - H_PP u: the mass points' responses with the masses on.
            let c: Vec<C64> = (0..np)
                .map(|p| {
                    hpi[p]
                        - (0..np)
                            .map(|q| r(masses[p].1, masses[q].2) * u[q])
                            .sum::<C64>()
                })
                .collect();
            for (ti, &o) in targets.iter().enumerate() {
                let hop: Vec<C64> = masses.iter().map(|m| r(o, m.2)).collect();
                let corr: C64 = hop.iter().zip(&u).map(|(a, b)| a * b).sum();
                let val = acc * (r(o, jin) - corr);
                if ti == n {
                    res.drive.push(val);
                } else {
                    res.h.push(val);
                    if with_sh {
                        // S H' = S H - (S H)_:P u: the same correction of the S-weighted rows.
                        let s_corr: C64 = masses.iter().zip(&u).map(|(m, b)| sr(o, m.2) * b).sum();
                        res.sh.push(acc * (sr(o, jin) - s_corr));
                    }
                }
                if derivs {
                    let dhop: Vec<C64> = masses.iter().map(|m| dr(o, m.2)).collect();
                    let dcorr: C64 = dhop.iter().zip(&u).map(|(a, b)| a * b).sum::<C64>()
                        + hop.iter().zip(&du).map(|(a, b)| a * b).sum::<C64>()
                        - hop.iter().zip(&dpp_u).map(|(a, b)| a * b).sum::<C64>();
                    let v = acc * (dr(o, jin) - dcorr);
                    if ti == n {
                        drive_dh.push(v);
                    } else {
                        res.dh.push(v);
                    }
                }
            }
            if derivs {
                // dH'_oi/dd_p = -g_p c_p with g = H_oP A^-1 (the receptance row to the mass
                // points with the masses on) and c = H_Pi - H_PP u; d_p = -w^2 m_eff,p, so
                // dd_p/dm_p = -w^2 dm_eff,p/dm_p.
                for (k, &o) in targets.iter().enumerate() {
                    let hop: Vec<C64> = masses.iter().map(|mm| r(o, mm.2)).collect();
                    let g = row_times_inverse(&a, np, &hop);
                    for (p, m) in masses.iter().enumerate() {
                        let v = acc * (w * w * dm_eff[p]) * g[p] * c[p];
                        if k == n {
                            drive_dt[m.0][l] += v;
                        } else {
                            res.d_terms[m.0][l * n + k] += v;
                        }
                    }
                }
            }
        }
        if let Some((t, k_s, m_s)) = shaker {
            apply_shaker(&mut res, omega, n, t, k_s, m_s, &drive_dh, &drive_dt);
        }
        Ok(res)
    }
}

/// The effective mass `m_eff` at `omega` of a mass `m` on a spring `k` (rigid without one) and
/// its derivative in `m`:
///
/// ```text
///   m_eff = m k / (k - w^2 m),   dm_eff/dm = k^2 / (k - w^2 m)^2
/// ```
///
/// (the mass's equation `-w^2 m x_m = k (x_P - x_m)` solved for the force `k (x_m - x_P)` it puts
/// on the point, `w^2 m_eff x_P`). At the resonator's own frequency the point is pinned: there
/// `k - w^2 m` is moved off zero by a rounding unit of `k`, which leaves the update finite (it
/// tends to `H_PP^-1 H_Pi` there).
fn effective_mass(m: f64, spring: Option<f64>, omega: f64) -> (f64, f64) {
    let Some(k) = spring else {
        return (m, 1.0);
    };
    let mut den = k - omega * omega * m;
    if den == 0.0 {
        den = k * f64::EPSILON;
    }
    (m * k / den, (k / den) * (k / den))
}

/// The shaker at the drive point, applied to the accelerances in `res` (values and derivative
/// columns) in place. With the drive-point receptance `H_dd = A_dd / (-w^2)` (point masses on)
/// and the force `F` read on the shaker's side of the stinger,
///
/// ```text
///   s = f / F = k_s / (k_s - w^2 m_s (1 + k_s H_dd)),   A'_o = A_o s
///   ds/dtheta = s^2 w^2 m_s dH_dd/dtheta               (theta: E', any other term)
///   ds/dm_s   = s^2 w^2 (1 + k_s H_dd) / k_s
/// ```
///
/// (armature: `-w^2 m_s x_s = F - f`; stinger: `f = k_s (x_s - x_d)`; structure: `x = H f`).
/// `res.drive` keeps the structure's drive-point accelerance (what a gauge at the structure
/// would measure against), so a measurement model's shaker colouring is unchanged.
#[allow(clippy::too_many_arguments)]
fn apply_shaker(
    res: &mut StructuralColumns,
    omega: &[f64],
    n: usize,
    term: usize,
    k_s: f64,
    m_s: f64,
    drive_dh: &[C64],
    drive_dt: &[Vec<C64>],
) {
    // Derivative columns exist (one per term, the shaker among them) only when asked.
    let derivs = !res.d_terms.is_empty();
    for (l, &w) in omega.iter().enumerate() {
        let w2 = w * w;
        let h_dd = res.drive[l] / -w2;
        let q = 1.0 + k_s * h_dd;
        let s = k_s / (k_s - w2 * m_s * q);
        let s2w2m = s * s * w2 * m_s;
        // dH_dd = dA_dd / (-w^2)
        let ds_de = if derivs {
            s2w2m * drive_dh[l] / -w2
        } else {
            C64::new(0.0, 0.0)
        };
        let ds_dt: Vec<C64> = if derivs {
            drive_dt.iter().map(|c| s2w2m * c[l] / -w2).collect()
        } else {
            Vec::new()
        };
        let ds_dm = s * s * w2 * q / k_s;
        for k in 0..n {
            let i = l * n + k;
            let a = res.h[i];
            if derivs {
                res.dh[i] = res.dh[i] * s + a * ds_de;
                for (t, col) in res.d_terms.iter_mut().enumerate() {
                    col[i] = if t == term {
                        a * ds_dm
                    } else {
                        col[i] * s + a * ds_dt[t]
                    };
                }
            }
            res.h[i] = a * s;
        }
    }
}

/// `x^T = h^T A^-1` for the small matrix `A = I + D H_PP` (row-major): the receptance row
/// between a point and the mass points with the masses on, `H_oP (I + D H_PP)^-1`.
fn row_times_inverse(a: &[C64], n: usize, h: &[C64]) -> Vec<C64> {
    let at: Vec<C64> = (0..n * n).map(|i| a[(i % n) * n + i / n]).collect();
    small_solve(&at, n, h, 1).unwrap_or_else(|| vec![C64::new(0.0, 0.0); n])
}
