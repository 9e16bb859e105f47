//! The end of the loop at a level: the null level of the level's measurement chain
//! ([`crate::closed_loop::null`]), then the drop-one check and the verdict
//! ([`crate::closed_loop::conclude`]).

use super::params::NullChainParams;
use crate::closed_loop::{ClosedLoopParams, ClosedLoopResult};
use crate::stage::{LevelData, RunError};

/// The null level of the level's measurement chain ([`crate::closed_loop::null`]: replicate
/// Welch experiments of the fitted model through the declared estimator, else the noise
/// model's own errors), then the drop-one check and the verdict
/// ([`crate::closed_loop::conclude`]). Their wall times join the result's `timings`
/// (`null level`, `verdict`).
pub(crate) fn verdict_of(
    chain_params: &NullChainParams,
    level: &LevelData,
    post: &mut crate::inference::likelihood::FrfPosterior<'_>,
    res: ClosedLoopResult,
    params: &ClosedLoopParams,
) -> Result<
    (
        ClosedLoopResult,
        crate::closed_loop::verdict::Verdict,
        crate::closed_loop::null::NullCalibration,
    ),
    RunError,
> {
    use crate::closed_loop::null::{calibrate, Chain, NullParams};
    let fail = |m: String| RunError::Analysis {
        analysis: format!("verdict of the closed loop at {}", level.name),
        message: m,
    };
    let chain = match &chain_params.estimator {
        Some(e) => {
            let nb = (e.fs_hz * e.block_s).round() as usize;
            let n_d = match &post.likelihood.noise.scale {
                crate::inference::likelihood::Scale::Coherence { n_averages, .. } => *n_averages,
                _ => 0.0,
            };
            // Blocks: the file's count, else the count whose Welch equivalent is n_d.
            let blocks = level.n_averages.map(|n| n as usize).unwrap_or_else(|| {
                (1..=20_000)
                    .min_by(|&a, &b| {
                        let f = |n| {
                            (crate::experiment::estimator::effective_averages(
                                e.window,
                                nb,
                                nb / 2,
                                n,
                            ) - n_d)
                                .abs()
                        };
                        f(a).total_cmp(&f(b))
                    })
                    .unwrap_or(200)
            });
            let spec = crate::stage::measurement::estimator_spec(e, &level.freq_hz);
            let force = chain_params.force_of(&level.name);
            Chain::Welch(Box::new(crate::experiment::ChainParams {
                force_rms_n: force,
                band_hz: spec.force_band_hz,
                fs_hz: e.fs_hz,
                block_s: e.block_s,
                n_averages: blocks,
                window: e.window,
                shaker: e.shaker,
                lines_hz: level.freq_hz.clone(),
                mode: crate::experiment::Mode::FrequencyDomain,
                ..Default::default()
            }))
        }
        None => Chain::NoiseModel,
    };
    params
        .progress
        .say(&format!("{}: null level of the residual", level.name));
    let np = NullParams {
        seed: chain_params.seed,
        ..NullParams::default()
    };
    let null = calibrate(post, &res.after.values, &chain, &level.response_ids, &np)
        .map_err(|e| fail(e.to_string()))?;
    let t_verdict = std::time::Instant::now();
    let vp = crate::closed_loop::verdict::VerdictParams {
        threshold_nats: params.threshold_nats,
        p_threshold: params.p_threshold,
        ..Default::default()
    };
    let (res, v) = crate::closed_loop::conclude::conclude(
        post,
        res,
        &null,
        &level.freq_hz,
        &level.response_ids,
        params,
        &vp,
    )
    .map_err(|e| fail(e.to_string()))?;
    let mut res = res;
    res.timings.push(("null level".into(), null.seconds));
    res.timings
        .push(("verdict".into(), t_verdict.elapsed().as_secs_f64()));
    Ok((res, v, null))
}
