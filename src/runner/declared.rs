//! The study's declared effects ([`crate::study::effects`]) as forward-model effects of one
//! level: point ids to engine point indices, channel ids to the level's output order; and
//! the closed loop's candidate list under a study's `[closed_loop]` settings.

use super::{LevelData, RunError};
use crate::forward::{Effect, EffectTerm, Effects};
use crate::inference::prior::Prior;
use crate::study::effects::{ClosedLoopSettings, DeclaredKind};
use crate::study::Study;

/// The forward-model effects of `study`'s declared effects at `level` (engine points
/// `engine_point_ids`, in the engine's order), and the priors of the free ones in order.
pub fn level_effects(
    study: &Study,
    engine_point_ids: &[u32],
    level: &LevelData,
) -> Result<(Effects, Vec<Prior>), RunError> {
    let mut terms = Vec::new();
    let mut priors = Vec::new();
    for d in &study.declared_effects {
        let point = |id: u32, k: &str| {
            engine_point_ids
                .iter()
                .position(|&p| p == id)
                .ok_or_else(|| {
                    super::study_err(
                        study,
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
                    super::study_err(
                        study,
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
            DeclaredKind::DegradedBond { x_start_m, width_m } => {
                Effect::DegradedBond { x_start_m, width_m }
            }
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
