//! The candidate effects of the loop: the defaults of a level (a point mass and a resonator at
//! every measured point, a gain and a delay per channel, the beam modulus factor, the Maxwell
//! branches), the opt-in ones with matrices of their own (degraded-bond strips, adherend damping, base
//! springs: [`opt_in_term_candidates`]) and the sensor mass, as `[closed_loop] candidates`
//! admits them; and the effects the term ROM is built for ([`with_declared`]).

use crate::closed_loop::default_candidates_with;
use crate::fe::joint::JointSpec;
use crate::forward::Effect;
use crate::frf::FrfEngine;
use crate::stage::LevelData;
use crate::study::build::BuiltModel;
use crate::study::effects::{ClosedLoopSettings, DeclaredEffect, DeclaredKind};

/// The candidates that need the term ROM: a degraded-bond strip of `width_m` at each end of
/// the block ([`bond_candidates`]) and the adherend damping.
pub fn term_candidates(joint: Option<&JointSpec>, width_m: f64) -> Vec<Effect> {
    let mut out = bond_candidates(joint, width_m);
    out.push(Effect::AdherendDamping);
    out
}

/// The degraded-bond candidates of the loop on the mesher's `joint`: a strip of `width_m` at
/// each end of the block.
pub fn bond_candidates(joint: Option<&JointSpec>, width_m: f64) -> Vec<Effect> {
    let Some(spec) = joint else {
        return Vec::new(); // an imported structure has no mesher geometry to split
    };
    let g = &spec.geometry;
    let (a0, a1) = (
        g.adhesive_x_start_m,
        g.adhesive_x_start_m + g.adhesive_length_m,
    );
    if a1 - a0 < 2.0 * width_m {
        return Vec::new();
    }
    vec![
        Effect::DegradedBond {
            x_start_m: a0,
            width_m,
        },
        Effect::DegradedBond {
            x_start_m: a1 - width_m,
            width_m,
        },
    ]
}

/// Whether `settings` leave the loop's default candidates (no `[closed_loop]` section, no
/// `candidates` list, or `"all"`).
pub(crate) fn default_candidates(settings: Option<&ClosedLoopSettings>) -> bool {
    settings.is_none_or(|c| c.candidates.is_none())
}

/// The candidates with matrices of their own: on the mesher's joint, base springs (two shapes)
/// with the default candidates; a degraded-bond strip at each end of the block and the
/// adherend damping when `[closed_loop] candidates` asks for them (by type, e.g.
/// "degraded_bond", or by name). Those two stay opt-in: each evaluation with a bond is a dense
/// LU of the term ROM per line (on the paper's 5 mm joint with both strips, 219 unknowns after
/// the compression: 1-2 s per forward evaluation on 2000 fine lines, against milliseconds on
/// the pencil), and the adherend damping's term cannot share the springs' free-base model. The
/// springs' term ROM (156 vectors on the paper's joint) is built and certified once (about
/// 100 s) and cached.
pub(crate) fn opt_in_term_candidates(
    joint: Option<&JointSpec>,
    settings: Option<&ClosedLoopSettings>,
) -> Vec<Effect> {
    let mut all = term_candidates(joint, crate::forward::effects::DEFAULT_BOND_STRIP_M);
    if joint.is_some() {
        all.extend(crate::forward::effects::BASE_SPRING_SHAPES.iter().map(
            |&normal_over_tangential| Effect::BaseSprings {
                normal_over_tangential,
            },
        ));
    }
    // Base springs are among the default candidates; the others only when a list names them.
    let defaults = default_candidates(settings);
    all.into_iter()
        .filter(|e| {
            (defaults && matches!(e, Effect::BaseSprings { .. }))
                || settings.is_some_and(|c| c.names(|n| n == e.kind() || n == e.name()))
        })
        .collect()
}

/// The candidates at `level` that `settings` admit: the defaults at its channels (a point mass
/// and a resonator on `settings`' spring where a channel's point is an input of `engine`), the
/// sensor masses, the Maxwell branches over its band, then `with_terms` (the opt-in term candidates); without the beam factor when
/// the adherend has viscous damping `C_b` (its exact scaling needs none).
pub(crate) fn level_candidates(
    level: &LevelData,
    engine: &dyn FrfEngine,
    built: &BuiltModel,
    with_terms: &[Effect],
    settings: Option<&ClosedLoopSettings>,
) -> Vec<Effect> {
    let mass_points: Vec<(usize, u32)> = level
        .column
        .outputs
        .iter()
        .zip(&level.response_ids)
        .filter(|(o, _)| engine.inputs().contains(o))
        .map(|(o, id)| (*o, *id))
        .collect();
    let resonator_stiffness = settings.map_or(
        crate::forward::effects::DEFAULT_RESONATOR_STIFFNESS_N_M,
        |s| s.resonator_stiffness_n_m,
    );
    let mut candidates =
        default_candidates_with(&level.response_ids, &mass_points, resonator_stiffness);
    candidates.extend(sensor_mass_candidates(
        &built.model.points,
        engine.inputs(),
        &level.response_ids,
    ));
    let band = (
        level.freq_hz.first().copied().unwrap_or(0.0),
        level.freq_hz.last().copied().unwrap_or(0.0),
    );
    candidates.extend(crate::closed_loop::maxwell_candidates(band));
    candidates.extend(with_terms.iter().cloned());
    // The beam factor's exact scaling needs an adherend without viscous damping C_b.
    if built.model.c_b.is_some() {
        candidates.retain(|c| !matches!(c, Effect::BeamModulus));
    }
    crate::bayes::declared::admitted(candidates, settings)
}

/// Whether `settings` admit the alternative law, the fractional Zener (type
/// "alternative_law", name "fractional_zener"; admitted without `[closed_loop]`).
pub(crate) fn admits_alternative_law(settings: Option<&ClosedLoopSettings>) -> bool {
    settings.is_none_or(|c| {
        c.admits(
            crate::closed_loop::alternative::ALTERNATIVE_LAW,
            crate::closed_loop::alternative::FRACTIONAL_ZENER,
        )
    })
}

/// `candidates` (keyed "closed_loop.candidates") and the `declared` degraded bonds, base
/// springs and adherend damping (keyed by their `structure.effects[i]`).
pub fn with_declared(declared: &[DeclaredEffect], candidates: &[Effect]) -> Vec<(Effect, String)> {
    let mut out: Vec<(Effect, String)> = declared
        .iter()
        .filter_map(|d| match d.kind {
            DeclaredKind::DegradedBond { x_start_m, width_m } => {
                Some((Effect::DegradedBond { x_start_m, width_m }, d.key.clone()))
            }
            DeclaredKind::BaseSprings {
                normal_over_tangential,
            } => Some((
                Effect::BaseSprings {
                    normal_over_tangential,
                },
                d.key.clone(),
            )),
            DeclaredKind::AdherendDamping => Some((Effect::AdherendDamping, d.key.clone())),
            _ => None,
        })
        .collect();
    out.extend(
        candidates
            .iter()
            .map(|e| (e.clone(), "closed_loop.candidates".to_string())),
    );
    out
}

/// A sensor-mass candidate (x, y and z) at every measured point whose three directions are
/// engine inputs.
fn sensor_mass_candidates(
    points: &[crate::fe::ObservationPoint],
    inputs: &[usize],
    ids: &[u32],
) -> Vec<Effect> {
    use crate::common::Axis;
    ids.iter()
        .filter_map(|&id| {
            let at = |axis: Axis| {
                points
                    .iter()
                    .position(|p| p.id == id && p.direction.axis == axis)
                    .filter(|k| inputs.contains(k))
            };
            Some(Effect::SensorMass {
                points: [at(Axis::X)?, at(Axis::Y)?, at(Axis::Z)?],
                id,
            })
        })
        .collect()
}
