//! The end of the loop: the drop-one check of the accepted effects when the residual is not
//! consistent with noise, then the verdict ([`super::verdict`]).

use super::null::NullCalibration;
use super::verdict::{assess, consistent, DropOne, Verdict, VerdictParams};
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

/// The warm Gauss-Newton refit of `post`'s current model from the physical values of `names`
/// in `values` (the final fit's, restricted to the model's parameters).
fn refit(
    post: &FrfPosterior<'_>,
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
    Ok(find_map(post, Some(&x), map, &|| {})?)
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
    if consistent(&res, null) || res.accepted.is_empty() {
        let v = assess(&res, null, freq_hz, ids, Vec::new(), params);
        return Ok((res, v));
    }
    let kappa = (res.after.residuals.chi2_normalised / null.mean).max(1.0);
    let map = MapParams {
        n_starts: 0,
        search: SearchMethod::GaussNewton,
        ..loop_params.map.clone()
    };
    let effects = post.likelihood.forward.effects.clone();
    let priors = post.priors.clone();
    let names = post.names.clone();
    let n_data = post.likelihood.data.values.len();
    let after = res.after.clone();
    let mut checks = Vec::new();
    for (e, _, _) in &res.accepted {
        let name = e.name();
        loop_params
            .progress
            .say(&format!("drop-one check of {name}"));
        without(post, &effects, &priors, &names, std::slice::from_ref(&name))?;
        let gain = match refit(post, &after.names, &after.values, &map) {
            Ok(r) => {
                if r.laplace.positive_definite && after.positive_definite {
                    after.log_evidence - r.laplace.log_evidence
                } else {
                    after.log_posterior
                        - (r.laplace.log_likelihood + r.laplace.log_prior)
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
    without(post, &effects, &priors, &names, &dropped)?;
    if !dropped.is_empty() {
        let r = refit(post, &after.names, &after.values, &map)?;
        res.after = fit_of(post, &r)?;
        res.accepted
            .retain(|(e, _, _)| !dropped.contains(&e.name()));
        for c in res.candidates.iter_mut() {
            if let Some(r) = c.refit.as_mut().filter(|r| r.accepted) {
                if let Some(d) = checks
                    .iter()
                    .find(|d| d.effect == c.effect.name() && !d.kept)
                {
                    r.accepted = false;
                    r.verdict = format!(
                        "accepted, then dropped: {:.1} nats / kappa {:.2} = {:.1} < {} in the final model",
                        d.gain, d.kappa, d.scaled_gain, params.threshold_nats
                    );
                }
            }
        }
        res.conclusion = format!(
            "{}. Dropped after the loop (evidence not decisive once the likelihood is widened to the residual left): {}",
            res.conclusion,
            dropped.join(", ")
        );
    }
    let v = assess(&res, null, freq_hz, ids, checks, params);
    Ok((res, v))
}
