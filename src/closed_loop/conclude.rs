//! The end of the loop, then the verdict ([`super::verdict`]):
//!
//! * residual consistent with noise: the smallest set of accepted effects that keeps it so.
//!   Latest acceptance first, each effect is refitted out of the model and left out when the
//!   normalised chi-square without it stays at most the null threshold. An effect can gain
//!   decisive evidence without being needed for a fit within the noise: at very high
//!   signal-to-noise a small model-form difference (a sensor's x and z inertia that the
//!   measured-direction mass leaves out) is absorbed by a proxy such as a beam factor of
//!   -0.01 %, which is not in the data;
//! * residual not consistent with noise: the drop-one check of the accepted effects under the
//!   likelihood widened to the residual left.

use super::null::NullCalibration;
use super::verdict::{assess, consistent, DropOne, NotNeeded, Verdict, VerdictParams};
use super::{fit_of, ClosedLoopError, ClosedLoopParams, ClosedLoopResult};
use crate::forward::Effects;
use crate::inference::likelihood::FrfPosterior;
use crate::inference::map::{find_map, MapParams, MapResult, SearchMethod};
use crate::inference::prior::Prior;

/// `post`'s model with the free effects named in `drop` removed (their priors too).
fn without(
    post: &mut FrfPosterior<'_>,
    effects: &Effects,
    priors: &[Prior],
    names: &[String],
    drop: &[String],
) -> Result<(), ClosedLoopError> {
    let mut e = effects.clone();
    e.terms
        .retain(|t| !(t.free && drop.contains(&t.effect.name())));
    post.likelihood.forward.set_effects(e)?;
    post.priors = priors
        .iter()
        .zip(names)
        .filter(|(_, n)| !drop.contains(n))
        .map(|(p, _)| p.clone())
        .collect();
    let mut n = post.likelihood.forward.param_names();
    n.extend(post.likelihood.noise_names().iter().cloned());
    post.names = n;
    Ok(())
}

/// The final model's state that the end-of-loop refits start from and restore: the search
/// settings (one warm Gauss-Newton start), the effects, priors and names, and the final fit.
struct FinalModel {
    map: MapParams,
    effects: Effects,
    priors: Vec<Prior>,
    names: Vec<String>,
    after: super::Fit,
}

impl FinalModel {
    fn of(post: &FrfPosterior<'_>, res: &ClosedLoopResult, loop_params: &ClosedLoopParams) -> Self {
        FinalModel {
            map: MapParams {
                n_starts: 0,
                search: SearchMethod::GaussNewton,
                ..loop_params.map.clone()
            },
            effects: post.likelihood.forward.effects.clone(),
            priors: post.priors.clone(),
            names: post.names.clone(),
            after: res.after.clone(),
        }
    }

    /// `post` without the effects named in `drop`.
    fn without(&self, post: &mut FrfPosterior<'_>, drop: &[String]) -> Result<(), ClosedLoopError> {
        without(post, &self.effects, &self.priors, &self.names, drop)
    }

    /// The warm refit of `post`'s current model from the final fit's values.
    fn refit(&self, post: &mut FrfPosterior<'_>) -> Result<MapResult, ClosedLoopError> {
        refit(post, &self.after.names, &self.after.values, &self.map)
    }

    /// [`FinalModel::refit`] that gives up once it cannot bring the normalised chi-square down
    /// to `threshold` ([`crate::inference::map::MapParams::give_up_above`]): its `-log p`
    /// stays above the final fit's plus the residual's allowance up to the threshold,
    /// `(threshold dof - chi2) / 2`, plus [`super::GIVE_UP_MARGIN_NATS`]. Leaving out an effect
    /// that the data need (a 12 g mass: chi-square 837 without it) otherwise sends the refit
    /// creeping at a residual hundreds of thousands of nats above the final fit's (186 s on a
    /// term ROM).
    fn refit_to_reach(
        &self,
        post: &mut FrfPosterior<'_>,
        threshold: f64,
    ) -> Result<MapResult, ClosedLoopError> {
        let res = &self.after.residuals;
        let allowance = (0.5 * (threshold * res.dof - res.chi2)).max(0.0);
        let map = MapParams {
            give_up_above: -self.after.log_posterior + allowance + super::GIVE_UP_MARGIN_NATS,
            ..self.map.clone()
        };
        refit(post, &self.after.names, &self.after.values, &map)
    }
}

/// `conclusion` without the accepted effects named in `gone` (their `name = size +- sd unit`
/// entries, as the loop wrote them), so that it lists only the effects kept.
fn strike(
    conclusion: &str,
    accepted: &[(crate::forward::Effect, f64, f64)],
    gone: &[String],
) -> String {
    let mut c = conclusion.to_string();
    for (e, v, s) in accepted.iter().filter(|(e, _, _)| gone.contains(&e.name())) {
        let entry = super::accepted_entry(e, *v, *s);
        for pat in [format!("{entry}; "), format!("; {entry}"), entry] {
            if c.contains(&pat) {
                c = c.replacen(&pat, "", 1);
                break;
            }
        }
    }
    if c.is_empty() || c.starts_with('.') {
        c = format!("no effect kept{c}");
    }
    c
}

/// `res` after the effects in `dropped` were removed and the model refitted (`r`, on `post`'s
/// current model): the final fit, the conclusion and the accepted list without them, and each
/// one's refit marked not accepted with the reason `why(name)`.
fn remove_accepted(
    post: &FrfPosterior<'_>,
    res: &mut ClosedLoopResult,
    r: &MapResult,
    dropped: &[String],
    why: impl Fn(&str) -> Option<String>,
) -> Result<(), ClosedLoopError> {
    res.after = fit_of(post, r)?;
    res.conclusion = strike(&res.conclusion, &res.accepted, dropped);
    res.accepted
        .retain(|(e, _, _)| !dropped.contains(&e.name()));
    for c in res.candidates.iter_mut() {
        if let Some(refit) = c.refit.as_mut().filter(|r| r.accepted) {
            if let Some(reason) = why(&c.effect.name()) {
                refit.accepted = false;
                refit.verdict = super::RefitVerdict::Removed(reason);
            }
        }
    }
    Ok(())
}

/// The warm Gauss-Newton refit of `post`'s current model from the physical values of `names`
/// in `values` (the final fit's, restricted to the model's parameters), on the linearised
/// measurement bias when the model has a term of the term ROM
/// ([`super::search_on_linearised_bias`]).
fn refit(
    post: &mut FrfPosterior<'_>,
    names: &[String],
    values: &[f64],
    map: &MapParams,
) -> Result<MapResult, ClosedLoopError> {
    let p0: Vec<f64> = post
        .names
        .iter()
        .map(|n| {
            names
                .iter()
                .position(|m| m == n)
                .map_or(f64::NAN, |i| values[i])
        })
        .collect();
    if p0.iter().any(|x| !x.is_finite()) {
        return Err(ClosedLoopError::Setup(
            "drop-one refit: a parameter of the reduced model is not in the final fit".into(),
        ));
    }
    let x = post.unconstrained(&p0);
    Ok(super::search_on_linearised_bias(post, &p0, map, |post| {
        find_map(post, Some(&x), map, &|| {})
    })?)
}

/// The drop-one check (when the final residual is not consistent with `null`) and the
/// verdict. `post` holds the final model on entry and on return (without any dropped effect).
pub fn conclude(
    post: &mut FrfPosterior<'_>,
    mut res: ClosedLoopResult,
    null: &NullCalibration,
    freq_hz: &[f64],
    ids: &[u32],
    loop_params: &ClosedLoopParams,
    params: &VerdictParams,
) -> Result<(ClosedLoopResult, Verdict), ClosedLoopError> {
    if res.accepted.is_empty() {
        let v = assess(&res, null, freq_hz, ids, Vec::new(), Vec::new(), params);
        return Ok((res, v));
    }
    if consistent(&res, null) {
        let not_needed = leave_out_unneeded(post, &mut res, null, loop_params)?;
        let v = assess(&res, null, freq_hz, ids, Vec::new(), not_needed, params);
        return Ok((res, v));
    }
    let kappa = (res.after.residuals.chi2_normalised / null.mean).max(1.0);
    let fin = FinalModel::of(post, &res, loop_params);
    let n_data = post.likelihood.data.values.len();
    let after = &fin.after;
    let mut checks = Vec::new();
    for (e, _, _) in &res.accepted {
        let name = e.name();
        loop_params
            .progress
            .say(&format!("drop-one check of {name}"));
        fin.without(post, std::slice::from_ref(&name))?;
        let gain = match fin.refit(post) {
            Ok(r) => {
                if r.laplace.positive_definite && after.positive_definite {
                    after.log_evidence - r.laplace.log_evidence
                } else {
                    after.log_posterior
                        - r.laplace.log_posterior()
                        - 0.5 * (2.0 * n_data as f64).ln()
                }
            }
            Err(_) => f64::NAN,
        };
        let scaled = gain / kappa;
        checks.push(DropOne {
            effect: name,
            gain,
            scaled_gain: scaled,
            kappa,
            kept: !(scaled < params.threshold_nats),
        });
    }
    let dropped: Vec<String> = checks
        .iter()
        .filter(|d| !d.kept)
        .map(|d| d.effect.clone())
        .collect();
    fin.without(post, &dropped)?;
    if !dropped.is_empty() {
        let r = fin.refit(post)?;
        remove_accepted(post, &mut res, &r, &dropped, |name| {
            checks.iter().find(|d| d.effect == name && !d.kept).map(|d| {
                format!(
                    "accepted, then dropped: {:.1} nats / kappa {:.2} = {:.1} < {} in the final model",
                    d.gain, d.kappa, d.scaled_gain, params.threshold_nats
                )
            })
        })?;
        res.conclusion = format!(
            "{}. Dropped after the loop (evidence not decisive once the likelihood is widened to the residual left): {}",
            res.conclusion,
            dropped.join(", ")
        );
    }
    let v = assess(&res, null, freq_hz, ids, checks, Vec::new(), params);
    Ok((res, v))
}

/// The accepted effects of a level whose residual is consistent with `null`, latest first,
/// left out while the model refitted without them stays at most the threshold. `post` and
/// `res` hold the final model on return (without the effects left out).
fn leave_out_unneeded(
    post: &mut FrfPosterior<'_>,
    res: &mut ClosedLoopResult,
    null: &NullCalibration,
    loop_params: &ClosedLoopParams,
) -> Result<Vec<NotNeeded>, ClosedLoopError> {
    let fin = FinalModel::of(post, res, loop_params);
    let mut out: Vec<NotNeeded> = Vec::new();
    let mut dropped: Vec<String> = Vec::new();
    let mut best: Option<MapResult> = None;
    for (e, size, _) in res.accepted.iter().rev() {
        let name = e.name();
        loop_params.progress.say(&format!(
            "is {name} needed for a residual within the noise?"
        ));
        let mut trial = dropped.clone();
        trial.push(name.clone());
        fin.without(post, &trial)?;
        let Ok(r) = fin.refit_to_reach(post, null.threshold) else {
            continue;
        };
        let chi2 = fit_of(post, &r)?.residuals.chi2_normalised;
        if chi2 <= null.threshold {
            out.push(NotNeeded {
                effect: name.clone(),
                size: *size,
                unit: e.unit().to_string(),
                chi2_without: chi2,
            });
            dropped = trial;
            best = Some(r);
        }
    }
    fin.without(post, &dropped)?;
    let Some(r) = best else {
        return Ok(out);
    };
    remove_accepted(post, res, &r, &dropped, |name| {
        out.iter().find(|d| d.effect == name).map(|d| {
            format!(
                "accepted, then left out: not needed for a residual consistent with noise (chi-square {:.3} without it, threshold {:.3})",
                d.chi2_without, null.threshold
            )
        })
    })?;
    let left: Vec<String> = out.iter().map(NotNeeded::entry).collect();
    res.conclusion = format!(
        "{}. Left out after the loop (the residual is consistent with noise without them): {}",
        res.conclusion,
        left.join(", ")
    );
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::strike;
    use crate::forward::Effect;

    #[test]
    fn strike_keeps_only_the_effects_kept() {
        let accepted = vec![
            (Effect::PointMass { point: 2, id: 3 }, 8.9895e-3, 5.8e-6),
            (Effect::BeamModulus, -1.3719e-4, 1.8e-5),
        ];
        let c = "mass_pt3 = 8.9895e-3 +- 5.8e-6 kg; beam_modulus = -1.3719e-4 +- 1.8e-5 1";
        assert_eq!(
            strike(c, &accepted, &["beam_modulus".into()]),
            "mass_pt3 = 8.9895e-3 +- 5.8e-6 kg"
        );
        assert_eq!(
            strike(c, &accepted, &["mass_pt3".into()]),
            "beam_modulus = -1.3719e-4 +- 1.8e-5 1"
        );
        assert_eq!(
            strike(
                "beam_modulus = -1.3719e-4 +- 1.8e-5 1. The starting fit has E0 at the edge",
                &accepted,
                &["beam_modulus".into()]
            ),
            "no effect kept. The starting fit has E0 at the edge"
        );
    }
}
