//! The study's declared effects ([`crate::study::effects`]) as forward-model effects of one
//! level: point ids to engine point indices, channel ids to the level's output order (errors
//! name the effect's key in the study file); the deterministic analyses' view of a level with
//! fixed point masses and beam factor ([`FixedEffectsEngine`]); and the closed loop's
//! candidate list under a study's `[closed_loop]` settings. Checked by the suite's
//! `declared_effects` and `fixed_effects` tests.

use super::input_err;
use crate::forward::fixed::FixedEffectsEngine;
use crate::forward::{Effect, EffectTerm, Effects};
use crate::inference::prior::Prior;
use crate::stage::{LevelData, RunError};
use crate::study::effects::{ClosedLoopSettings, DeclaredEffect, DeclaredKind};
use std::path::Path;

/// The forward-model effects of the declared effects `declared` (of the study file `file`)
/// at `level` (engine points `engine_point_ids`, in the engine's order), and the priors of
/// the free ones in order.
pub fn level_effects(
    declared: &[DeclaredEffect],
    file: &Path,
    engine_point_ids: &[u32],
    level: &LevelData,
) -> Result<(Effects, Vec<Prior>), RunError> {
    let mut terms = Vec::new();
    let mut priors = Vec::new();
    for d in declared {
        let point = |id: u32, k: &str| {
            engine_point_ids
                .iter()
                .position(|&p| p == id)
                .ok_or_else(|| {
                    input_err(
                        file,
                        format!("{}.{k}", d.key),
                        format!("point {id} is not a point of the structure's model"),
                    )
                })
        };
        let channel = |id: u32| {
            level
                .response_ids
                .iter()
                .position(|&r| r == id)
                .ok_or_else(|| {
                    input_err(
                        file,
                        format!("{}.channel", d.key),
                        format!(
                            "level {}: no response channel at point {id} (channels {:?}); declare gains and delays on measured channels",
                            level.name, level.response_ids
                        ),
                    )
                })
        };
        let effect = match d.kind {
            DeclaredKind::PointMass { point: id } => Effect::PointMass {
                point: point(id, "point")?,
                id,
            },
            DeclaredKind::Gain { channel: id } => Effect::Gain {
                channel: channel(id)?,
                id,
            },
            DeclaredKind::Delay { channel: id } => Effect::Delay {
                channel: channel(id)?,
                id,
            },
            DeclaredKind::BeamModulus => Effect::BeamModulus,
            DeclaredKind::MaxwellBranch { tau_s } => Effect::MaxwellBranch { tau_s },
            DeclaredKind::Shaker { stiffness_n_m } => Effect::Shaker { stiffness_n_m },
            DeclaredKind::Resonator {
                point: id,
                stiffness_n_m,
            } => Effect::Resonator {
                point: point(id, "point")?,
                id,
                stiffness_n_m,
            },
            DeclaredKind::DegradedBond { x_start_m, width_m } => {
                Effect::DegradedBond { x_start_m, width_m }
            }
            DeclaredKind::BaseSprings {
                normal_over_tangential,
            } => Effect::BaseSprings {
                normal_over_tangential,
            },
            DeclaredKind::AdherendDamping => Effect::AdherendDamping,
        };
        let mut value = d.value;
        if d.free {
            let prior = d.prior.clone().unwrap_or_else(|| effect.default_prior());
            // A free effect starts at its declared value, or at its prior's median when that
            // value is outside the prior's open support (a mass declared free at 0).
            let (lo, hi) = effect.bounds();
            if !(prior.contains(value) && value > lo && value < hi) {
                value = prior.to_physical(prior.quantile_x(0.5));
            }
            priors.push(prior);
        }
        terms.push(EffectTerm {
            effect,
            value,
            free: d.free,
        });
    }
    Ok((Effects { terms }, priors))
}

/// The candidates that `settings` admit out of `all`.
pub fn admitted(all: Vec<Effect>, settings: Option<&ClosedLoopSettings>) -> Vec<Effect> {
    match settings {
        None => all,
        Some(s) => all
            .into_iter()
            .filter(|e| s.admits(e.kind(), &e.name()))
            .collect(),
    }
}

/// The deterministic analyses' view of a level with declared effects: the engine with the
/// fixed point masses and beam factor ([`FixedEffectsEngine`]; free effects at their declared
/// values) and the full model with them (for the modes when the engine cannot give them).
pub struct DeterministicView<'a> {
    pub engine: FixedEffectsEngine<'a>,
    pub built: crate::study::build::BuiltModel,
}

/// [`DeterministicView`] of `level` under the declared effects `declared` (of the study file
/// `file`), or `None` when no declared effect changes the structure.
pub fn deterministic_view<'a>(
    declared: &[DeclaredEffect],
    file: &Path,
    engine: &'a dyn crate::frf::FrfEngine,
    built: &crate::study::build::BuiltModel,
    level: &LevelData,
) -> Result<Option<DeterministicView<'a>>, RunError> {
    if declared.is_empty() {
        return Ok(None);
    }
    let ids: Vec<u32> = built.model.points.iter().map(|p| p.id).collect();
    let (effects, _) = level_effects(declared, file, &ids, level)?;
    let fail = |m: String| RunError::Analysis {
        analysis: format!(
            "declared effects in the deterministic analyses at {}",
            level.name
        ),
        message: m,
    };
    let wrapped = FixedEffectsEngine::new(engine, &effects).map_err(|e| {
        fail(format!(
            "{e}: a declared point mass must sit at a measured point (the RFM's engine has the measured points as inputs)"
        ))
    })?;
    if wrapped.is_identity() {
        return Ok(None);
    }
    let mut model = built
        .model
        .with_point_masses(&wrapped.masses())
        .map_err(|e| fail(e.to_string()))?;
    let s = 1.0 + wrapped.beam_factor();
    model.k_b.val_mut().iter_mut().for_each(|v| *v *= s);
    if let Some(d) = model.d_b.as_mut() {
        d.val_mut().iter_mut().for_each(|v| *v *= s);
    }
    Ok(Some(DeterministicView {
        engine: wrapped,
        built: crate::study::build::BuiltModel {
            model,
            mesh: built.mesh.clone(),
            excitation: built.excitation,
            dof_axes: built.dof_axes.clone(),
            discretisation: built.discretisation.clone(),
        },
    }))
}

/// A report sentence on the declared effects in the deterministic analyses: point masses and
/// the beam factor enter the RFM, IEM and FRAC; gains, delays, the shaker, resonators and law
/// effects only the likelihood and the closed loop. `None` without declared effects.
pub fn deterministic_note(declared: &[DeclaredEffect]) -> Option<String> {
    if declared.is_empty() {
        return None;
    }
    let (mut inside, mut outside) = (Vec::new(), Vec::new());
    for d in declared {
        match d.kind {
            DeclaredKind::PointMass { .. } | DeclaredKind::BeamModulus => {
                inside.push(d.key.clone())
            }
            _ => outside.push(d.key.clone()),
        }
    }
    let mut s = String::from("Declared effects (`[[structure.effects]]`): ");
    if !inside.is_empty() {
        s.push_str(&format!(
            "{} (point masses, beam modulus) are in the deterministic analyses (RFM, IEM, FRAC: the engine's receptances and modes transformed exactly) and in the Bayesian layer at their declared values",
            inside.join(", ")
        ));
    }
    if !outside.is_empty() {
        if !inside.is_empty() {
            s.push_str("; ");
        }
        s.push_str(&format!(
            "{} (gains, delays, shaker, resonators, law effects) are in the Bayesian layer and the closed loop only: the deterministic RFM, IEM and FRAC above run without them",
            outside.join(", ")
        ));
    }
    s.push('.');
    Some(s)
}
