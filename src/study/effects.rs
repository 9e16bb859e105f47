//! Declared effects (`[[structure.effects]]`) and the closed loop's settings (`[closed_loop]`)
//! of a study: effects the study knows of enter every forward model of the
//! run (fixed at their value, or free with a prior); the loop runs after inference.
//!
//! ```toml
//! [[structure.effects]]
//! type = "point_mass"     # point_mass | gain | delay | beam_modulus | maxwell_branch | shaker | resonator | degraded_bond | adherend_damping | base_springs
//! point = 4               # point id (point_mass); `channel = id` for gain and delay
//! value = 0.012           # SI (kg, 1, s, 1, Pa)
//! free = false            # true: a parameter to infer, with the default prior or prior = {...}
//! # tau = 1.6e-3          # s, the relaxation time of a maxwell_branch
//! # stinger_stiffness = 2e5  # N/m, a shaker's stinger (default 2e5); value = its moving mass (kg)
//! # type = "resonator" with point = 2 and stiffness = 2e5 (N/m, default 2e5): value = the mass
//! #   (kg) on a spring at the point, force read at the structure
//! # type = "degraded_bond" with x_start = 0.040 and width = 0.010 (m, inside the adhesive
//! #   block; default width 10 mm): value = the loss fraction d in [0, 1), E* -> (1 - d) E* there
//! # type = "base_springs": value = the compliance 1 / k_n (m^3/N) of springs under the adhesive's
//! #   lower face (0: fixed base); normal_over_tangential = k_n / k_t (default 3.5)
//! # type = "adherend_damping": value = the beam's structural loss factor g (D_b -> D_b + g K_b)
//!
//! [closed_loop]
//! enabled = true
//! candidates = "all"      # or a list of types / names: ["point_mass", "gain_ch3", "beam_modulus"]
//! max_effects = 2         # effects accepted at most (rounds of the loop)
//! evidence_threshold = 5.0  # nats of Laplace log-evidence gain an effect needs
//! p_threshold = 0.01      # only candidates whose score test has p below this are refitted
//! top = 3                 # candidates refitted per round
//! resonator_stiffness = 2e5  # N/m, the spring of the resonator candidates
//! mesh_allowance = false  # true: the adhesive's intervals include the mesh's discretisation
//!                         # error (parameters identified on the mesh and on it refined twice)
//! ```

use super::ctx::Ctx;
use super::StudyError;
use crate::inference::prior::Prior;
use serde::Deserialize;

/// Effect types a study may name (`type = ...`).
pub const EFFECT_TYPES: [&str; 10] = [
    "point_mass",
    "gain",
    "delay",
    "beam_modulus",
    "maxwell_branch",
    "shaker",
    "resonator",
    "degraded_bond",
    "base_springs",
    "adherend_damping",
];

/// `[[structure.effects]]` as written.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawEffect {
    #[serde(rename = "type")]
    pub kind: String,
    pub point: Option<u32>,
    pub channel: Option<u32>,
    pub value: Option<f64>,
    pub tau: Option<f64>,
    pub stinger_stiffness: Option<f64>,
    /// N/m, a resonator's spring (default 2e5).
    pub stiffness: Option<f64>,
    /// m, start of a degraded bond region.
    pub x_start: Option<f64>,
    /// m, width of a degraded bond region.
    pub width: Option<f64>,
    /// Base springs: ratio of normal to tangential stiffness (default 3.5).
    pub normal_over_tangential: Option<f64>,
    #[serde(default)]
    pub free: bool,
    pub prior: Option<super::inference::RawPrior>,
}

/// `[closed_loop]` as written.
#[derive(Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct RawClosedLoop {
    pub enabled: Option<bool>,
    pub candidates: Option<toml::Value>,
    pub max_effects: Option<usize>,
    pub evidence_threshold: Option<f64>,
    pub p_threshold: Option<f64>,
    pub top: Option<usize>,
    /// N/m, the spring of the resonator candidates.
    pub resonator_stiffness: Option<f64>,
    pub mesh_allowance: Option<bool>,
}

/// Where a declared effect acts, by the study's ids (resolved to engine indices by the run's stages).
#[derive(Clone, Debug, PartialEq)]
pub enum DeclaredKind {
    PointMass {
        point: u32,
    },
    Gain {
        channel: u32,
    },
    Delay {
        channel: u32,
    },
    BeamModulus,
    MaxwellBranch {
        tau_s: f64,
    },
    /// A shaker's moving mass on a stinger (N/m) at the drive point, force read on the shaker
    /// side.
    Shaker {
        stiffness_n_m: f64,
    },
    /// A mass on a spring (N/m) at a point, force read at the structure.
    Resonator {
        point: u32,
        stiffness_n_m: f64,
    },
    /// A degraded bond over `[x_start_m, x_start_m + width_m]` (m) of the adhesive block (checked
    /// against the block by the run's model building, which assembles the region).
    DegradedBond {
        x_start_m: f64,
        width_m: f64,
    },
    /// Springs under the adhesive's lower face (value: the normal compliance 1 / k_n, m^3/N).
    BaseSprings {
        normal_over_tangential: f64,
    },
    /// Structural loss factor g of the adherends: D_b -> D_b + g K_b.
    AdherendDamping,
}

/// A validated declared effect.
#[derive(Clone, Debug, PartialEq)]
pub struct DeclaredEffect {
    pub kind: DeclaredKind,
    /// Value (SI); the start when free.
    pub value: f64,
    pub free: bool,
    /// The prior when free (None: the effect's default prior).
    pub prior: Option<Prior>,
    /// The key in the study file (`structure.effects[i]`), for messages.
    pub key: String,
}

/// The validated `[closed_loop]` section.
#[derive(Clone, Debug, PartialEq)]
pub struct ClosedLoopSettings {
    pub enabled: bool,
    /// None: all candidates; else the types or parameter names to try.
    pub candidates: Option<Vec<String>>,
    pub max_effects: usize,
    pub evidence_threshold_nats: f64,
    pub p_threshold: f64,
    pub top: usize,
    /// Spring of the resonator candidates (N/m).
    pub resonator_stiffness_n_m: f64,
    /// The adhesive's intervals include the mesh's discretisation error, estimated from the
    /// parameters identified on the study's mesh and on it refined twice per direction.
    pub mesh_allowance: bool,
}

impl Default for ClosedLoopSettings {
    fn default() -> Self {
        ClosedLoopSettings {
            enabled: true,
            candidates: None,
            max_effects: 4,
            evidence_threshold_nats: 5.0,
            p_threshold: 0.01,
            top: 3,
            resonator_stiffness_n_m: crate::forward::effects::DEFAULT_RESONATOR_STIFFNESS_N_M,
            mesh_allowance: false,
        }
    }
}

impl ClosedLoopSettings {
    /// Whether a candidate of type `kind` named `name` is to be tried.
    pub fn admits(&self, kind: &str, name: &str) -> bool {
        self.candidates
            .as_ref()
            .is_none_or(|c| c.iter().any(|s| s == kind || s == name))
    }

    /// Whether `candidates` lists an entry for which `matches` holds (`"all"` lists none): how
    /// the opt-in candidates are asked for.
    pub fn names(&self, matches: impl Fn(&str) -> bool) -> bool {
        self.candidates
            .as_ref()
            .is_some_and(|c| c.iter().any(|s| matches(s)))
    }
}

/// Whether `declared` holds a point mass or a resonator (the likelihood's engine then needs the
/// receptances at its point for the Sherman-Morrison-Woodbury update).
pub fn declares_attachment(declared: &[DeclaredEffect]) -> bool {
    declared.iter().any(|d| {
        matches!(
            d.kind,
            DeclaredKind::PointMass { .. } | DeclaredKind::Resonator { .. }
        )
    })
}

/// Validate `[[structure.effects]]` against the study's points (`point_ids`).
pub(super) fn effects(
    ctx: &Ctx,
    raw: &[RawEffect],
    point_ids: &[u32],
) -> Result<Vec<DeclaredEffect>, StudyError> {
    let mut out: Vec<DeclaredEffect> = Vec::new();
    for (i, r) in raw.iter().enumerate() {
        let key = format!("structure.effects[{i}]");
        let point_of = |k: &str, v: Option<u32>| -> Result<u32, StudyError> {
            let id = v.ok_or_else(|| {
                ctx.err(
                    format!("{key}.{k}"),
                    format!(
                        "type \"{}\" needs `{k}` = the id of one of [[structure.points]] ({point_ids:?})",
                        r.kind
                    ),
                )
            })?;
            if point_ids.contains(&id) {
                Ok(id)
            } else {
                Err(ctx.err(
                    format!("{key}.{k}"),
                    format!("point id {id} does not exist: use one of the ids of [[structure.points]] ({point_ids:?})"),
                ))
            }
        };
        let not = |k: &str, present: bool| -> Result<(), StudyError> {
            if present {
                Err(ctx.err(
                    format!("{key}.{k}"),
                    format!("type \"{}\" takes no `{k}`: remove it", r.kind),
                ))
            } else {
                Ok(())
            }
        };
        if r.kind != "shaker" {
            not("stinger_stiffness", r.stinger_stiffness.is_some())?;
        }
        if r.kind != "resonator" {
            not("stiffness", r.stiffness.is_some())?;
        }
        if r.kind != "degraded_bond" {
            not("x_start", r.x_start.is_some())?;
            not("width", r.width.is_some())?;
        }
        if r.kind != "base_springs" {
            not("normal_over_tangential", r.normal_over_tangential.is_some())?;
        }
        let kind = match r.kind.as_str() {
            "point_mass" => {
                not("channel", r.channel.is_some())?;
                not("tau", r.tau.is_some())?;
                DeclaredKind::PointMass {
                    point: point_of("point", r.point)?,
                }
            }
            "gain" | "delay" => {
                not("point", r.point.is_some())?;
                not("tau", r.tau.is_some())?;
                let channel = point_of("channel", r.channel)?;
                if r.kind == "gain" {
                    DeclaredKind::Gain { channel }
                } else {
                    DeclaredKind::Delay { channel }
                }
            }
            "beam_modulus" => {
                not("point", r.point.is_some())?;
                not("channel", r.channel.is_some())?;
                not("tau", r.tau.is_some())?;
                DeclaredKind::BeamModulus
            }
            "adherend_damping" => {
                not("point", r.point.is_some())?;
                not("channel", r.channel.is_some())?;
                not("tau", r.tau.is_some())?;
                DeclaredKind::AdherendDamping
            }
            "maxwell_branch" => {
                not("point", r.point.is_some())?;
                not("channel", r.channel.is_some())?;
                let tau = r.tau.ok_or_else(|| {
                    ctx.err(
                        format!("{key}.tau"),
                        "type \"maxwell_branch\" needs `tau`, the branch's relaxation time in s",
                    )
                })?;
                DeclaredKind::MaxwellBranch {
                    tau_s: ctx.positive(&format!("{key}.tau"), tau, "s")?,
                }
            }
            "shaker" => {
                not("point", r.point.is_some())?;
                not("channel", r.channel.is_some())?;
                not("tau", r.tau.is_some())?;
                let k = r
                    .stinger_stiffness
                    .unwrap_or(crate::forward::effects::DEFAULT_STINGER_STIFFNESS_N_M);
                DeclaredKind::Shaker {
                    stiffness_n_m: ctx.positive(&format!("{key}.stinger_stiffness"), k, "N/m")?,
                }
            }
            "resonator" => {
                not("channel", r.channel.is_some())?;
                not("tau", r.tau.is_some())?;
                let k = r
                    .stiffness
                    .unwrap_or(crate::forward::effects::DEFAULT_RESONATOR_STIFFNESS_N_M);
                DeclaredKind::Resonator {
                    point: point_of("point", r.point)?,
                    stiffness_n_m: ctx.positive(&format!("{key}.stiffness"), k, "N/m")?,
                }
            }
            "degraded_bond" => {
                not("point", r.point.is_some())?;
                not("channel", r.channel.is_some())?;
                not("tau", r.tau.is_some())?;
                let x0 = r.x_start.ok_or_else(|| {
                    ctx.err(
                        format!("{key}.x_start"),
                        "type \"degraded_bond\" needs `x_start`, the start of the region in m (inside the adhesive block)",
                    )
                })?;
                if !x0.is_finite() {
                    return Err(ctx.err(
                        format!("{key}.x_start"),
                        format!("must be a finite position in m, got {x0}"),
                    ));
                }
                let w = r
                    .width
                    .unwrap_or(crate::forward::effects::DEFAULT_BOND_STRIP_M);
                DeclaredKind::DegradedBond {
                    x_start_m: x0,
                    width_m: ctx.positive(&format!("{key}.width"), w, "m")?,
                }
            }
            "base_springs" => {
                not("point", r.point.is_some())?;
                not("channel", r.channel.is_some())?;
                not("tau", r.tau.is_some())?;
                let q = r
                    .normal_over_tangential
                    .unwrap_or(crate::forward::effects::DEFAULT_BASE_NORMAL_OVER_TANGENTIAL);
                DeclaredKind::BaseSprings {
                    normal_over_tangential: ctx.positive(
                        &format!("{key}.normal_over_tangential"),
                        q,
                        "(ratio)",
                    )?,
                }
            }
            o => {
                return Err(ctx.err(
                    format!("{key}.type"),
                    format!(
                        "unknown effect \"{o}\": use one of {}",
                        EFFECT_TYPES
                            .iter()
                            .map(|t| format!("\"{t}\""))
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                ))
            }
        };
        let value = match r.value {
            Some(v) => v,
            None if r.free => 0.0,
            None => {
                return Err(ctx.err(
                    format!("{key}.value"),
                    "missing: give the effect's value in SI units, or free = true to infer it",
                ))
            }
        };
        let (unit, lo, hi, nonneg) = match kind {
            DeclaredKind::PointMass { .. } => ("kg", 0.0, 10.0, true),
            DeclaredKind::Gain { .. } => ("1 (relative)", -0.9, 9.0, false),
            DeclaredKind::Delay { .. } => ("s", -0.01, 0.01, false),
            DeclaredKind::BeamModulus => ("1 (relative)", -0.9, 9.0, false),
            DeclaredKind::MaxwellBranch { .. } => ("Pa", 0.0, 1e11, true),
            DeclaredKind::Shaker { .. } => ("kg", 0.0, 10.0, true),
            DeclaredKind::Resonator { .. } => ("kg", 0.0, 10.0, true),
            DeclaredKind::DegradedBond { .. } => ("1 (loss fraction)", 0.0, 1.0, true),
            DeclaredKind::BaseSprings { .. } => ("m^3/N (compliance 1 / k_n)", 0.0, 1e-6, true),
            DeclaredKind::AdherendDamping => ("1 (loss factor)", 0.0, 1.0, true),
        };
        if !value.is_finite() || (nonneg && value < 0.0) {
            return Err(ctx.err(
                format!("{key}.value"),
                format!(
                    "must be a non-negative number in {unit}, got {value}: a {} cannot be negative",
                    r.kind
                ),
            ));
        }
        if value < lo || value >= hi {
            return Err(ctx.err(
                format!("{key}.value"),
                format!("{value} {unit} is outside the admissible range [{lo}, {hi}) of a {}: give it in SI units", r.kind),
            ));
        }
        let prior = match &r.prior {
            None => None,
            Some(p) if r.free => Some(effect_prior(ctx, &format!("{key}.prior"), p, nonneg)?),
            Some(_) => {
                return Err(ctx.err(
                    format!("{key}.prior"),
                    "a prior needs free = true (a fixed effect has no prior): remove it or set free = true",
                ))
            }
        };
        if out.iter().any(|e| e.kind == kind) {
            return Err(ctx.err(
                key,
                "the same effect is declared twice: keep one entry (a mass per point, a gain and a delay per channel, one beam modulus, one branch per tau)",
            ));
        }
        out.push(DeclaredEffect {
            kind,
            value,
            free: r.free,
            prior,
            key,
        });
    }
    Ok(out)
}

/// The prior of a free effect: `uniform` or `truncated_normal` over any finite range (gains,
/// delays and the beam factor are signed); the positive families of `[inference.priors]` for
/// the non-negative ones (mass, branch modulus).
fn effect_prior(
    ctx: &Ctx,
    key: &str,
    r: &super::inference::RawPrior,
    nonneg: bool,
) -> Result<Prior, StudyError> {
    let need = |v: Option<f64>, k: &str| {
        v.filter(|v| v.is_finite()).ok_or_else(|| {
            ctx.err(
                format!("{key}.{k}"),
                format!("family \"{}\" needs a finite `{k}`", r.family),
            )
        })
    };
    let p = match r.family.as_str() {
        "uniform" => Prior::Uniform {
            lo: need(r.lo, "lo")?,
            hi: need(r.hi, "hi")?,
        },
        "truncated_normal" => Prior::TruncatedNormal {
            mean: need(r.mean, "mean")?,
            sd: need(r.sd, "sd")?,
            lo: need(r.lo, "lo")?,
            hi: need(r.hi, "hi")?,
        },
        _ if nonneg => return super::inference::prior(ctx, key, r),
        o => {
            return Err(ctx.err(
                format!("{key}.family"),
                format!(
                "prior family \"{o}\" for a signed effect: use \"uniform\" or \"truncated_normal\""
            ),
            ))
        }
    };
    let ok = match p {
        Prior::Uniform { lo, hi } => lo < hi && (!nonneg || lo >= 0.0),
        Prior::TruncatedNormal { sd, lo, hi, .. } => sd > 0.0 && lo < hi && (!nonneg || lo >= 0.0),
        _ => true,
    };
    if !ok {
        return Err(ctx.err(
            key,
            "needs lo < hi (lo >= 0 for a mass or a branch modulus) and sd > 0",
        ));
    }
    Ok(p)
}

/// Validate `[closed_loop]`.
pub(super) fn closed_loop(ctx: &Ctx, r: &RawClosedLoop) -> Result<ClosedLoopSettings, StudyError> {
    let d = ClosedLoopSettings::default();
    let candidates = match &r.candidates {
        None => None,
        Some(toml::Value::String(s)) if s == "all" => None,
        Some(toml::Value::Array(a)) => {
            let mut v = Vec::new();
            for (i, x) in a.iter().enumerate() {
                let Some(s) = x.as_str() else {
                    return Err(ctx.err(
                        format!("closed_loop.candidates[{i}]"),
                        "must be a string: an effect type (e.g. \"point_mass\") or a parameter name (e.g. \"mass_pt4\")",
                    ));
                };
                // (An alternative law, the fractional Zener, and a sensor's mass in x, y and z
                // are candidates of the loop too, not declarable effects.)
                let known_type = EFFECT_TYPES.contains(&s)
                    || s == "alternative_law"
                    || s == "sensor_mass"
                    || s == "discretisation";
                let known_name = [
                    "mass_pt",
                    "mass3_pt",
                    "resonator_pt",
                    "gain_ch",
                    "delay_ch",
                    "maxwell_fc",
                    "bond_x",
                ]
                .iter()
                .any(|p| s.starts_with(p))
                    || s == "beam_modulus"
                    || s == "fractional_zener";
                if !(known_type || known_name) {
                    return Err(ctx.err(
                        format!("closed_loop.candidates[{i}]"),
                        format!("unknown candidate \"{s}\": use \"all\" or effect types ({}, sensor_mass, alternative_law, discretisation) or names such as \"mass_pt4\", \"gain_ch3\", \"fractional_zener\"", EFFECT_TYPES.join(", ")),
                    ));
                }
                v.push(s.to_string());
            }
            if v.is_empty() {
                return Err(ctx.err(
                    "closed_loop.candidates",
                    "is empty: list at least one candidate, or \"all\"",
                ));
            }
            Some(v)
        }
        Some(_) => {
            return Err(ctx.err(
                "closed_loop.candidates",
                "must be \"all\" or a list of effect types / names",
            ))
        }
    };
    let evidence = r.evidence_threshold.unwrap_or(d.evidence_threshold_nats);
    if !(evidence.is_finite() && evidence >= 0.0) {
        return Err(ctx.err(
            "closed_loop.evidence_threshold",
            format!("must be a non-negative number of nats, got {evidence} (default 5)"),
        ));
    }
    let p = r.p_threshold.unwrap_or(d.p_threshold);
    if !(p > 0.0 && p <= 1.0) {
        return Err(ctx.err(
            "closed_loop.p_threshold",
            format!("must lie in (0, 1], got {p} (default 0.01; 1 refits the top candidates whatever their p)"),
        ));
    }
    let max_effects = r.max_effects.unwrap_or(d.max_effects);
    if max_effects == 0 {
        return Err(ctx.err(
            "closed_loop.max_effects",
            "must be at least 1 (or enabled = false)",
        ));
    }
    let top = r.top.unwrap_or(d.top);
    if top == 0 {
        return Err(ctx.err("closed_loop.top", "must be at least 1 (default 3)"));
    }
    let resonator_stiffness_n_m = ctx.positive(
        "closed_loop.resonator_stiffness",
        r.resonator_stiffness.unwrap_or(d.resonator_stiffness_n_m),
        "N/m",
    )?;
    Ok(ClosedLoopSettings {
        enabled: r.enabled.unwrap_or(true),
        candidates,
        max_effects,
        evidence_threshold_nats: evidence,
        p_threshold: p,
        top,
        resonator_stiffness_n_m,
        mesh_allowance: r.mesh_allowance.unwrap_or(d.mesh_allowance),
    })
}
