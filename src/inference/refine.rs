//! Refinements of a MAP that the inference and the closed loop share: the measurement bias
//! re-linearised at the MAP until the MAP stops moving, and the channels' error correlation
//! per line estimated at the MAP (the fixed point of "estimate at the MAP, search again").
//!
//! * **Re-linearisation.** With a linearised measurement model the bias `E[H1] - H` is
//!   linearised at a point `p_lin`; the search then finds the MAP of that linearisation. Setting
//!   `p_lin` to the MAP and searching again converges in 2-3 passes (the bias moves the optimum
//!   by a fraction of a per cent); at the end the linearised and the exact likelihood agree in
//!   value and gradient at the MAP.
//! * **Channel correlation.** The correlation per line (`R_l`, [`ChannelCorrelation`]) comes
//!   from the MAP's standardised residuals: the shrunk sample correlation over a window of
//!   lines, or the Welch H1's leakage structure (rank one along dE[H1]/df plus an isotropic
//!   share floored at [`LEAKAGE_EPS_MIN`]). The MAP under it moves the residuals a little, so
//!   the estimate and the search alternate [`CORRELATION_PASSES`] times.
//!
//! Tests: tests/suite/inference_likelihood.rs (the correlation models), and every Bayesian
//! study test through the pipeline.

use super::likelihood::{ChannelCorrelation, FrfPosterior, LikelihoodError};
use super::map::{find_map, MapError, MapParams, MapResult};
use crate::forward::ForwardError;

/// How the channels' error correlation per line is modelled.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CorrelationKind {
    /// Rank one along dE[H1]/df plus an estimated isotropic share (the Welch leakage jitter).
    Leakage,
    /// The shrunk sample correlation of the MAP residuals.
    Estimated,
}

/// Why a refinement failed.
#[derive(Debug, Clone, thiserror::Error)]
pub enum RefineError {
    #[error("measurement model: {0}")]
    Measurement(#[from] ForwardError),
    #[error(transparent)]
    Search(#[from] MapError),
    #[error("channel correlation: {0}")]
    Correlation(#[from] LikelihoodError),
}

/// At most this many re-linearisations of the measurement bias at the MAP (2-3 suffice: the
/// bias moves the optimum by a fraction of a per cent).
pub const MAX_RELINEARISATIONS: usize = 6;

/// Passes of (estimate the channels' correlation at the MAP, search the MAP again).
pub const CORRELATION_PASSES: usize = 2;

/// Floor on the leakage structure's isotropic share eps. Below about 1 % the rank-one structure
/// makes the differences between channels near exact, and then a model difference far below the
/// noise reads as information: on the independent frequency-domain virtual data (whose random
/// error also lies along dE[H1]/df) a floor of 1e-4 gave posterior sds of 1e-5 and put the truth
/// 9 sd away, at a 5e-5 relative parameter shift (the two codes' FE discretisations).
pub const LEAKAGE_EPS_MIN: f64 = 1e-2;

/// Take a polishing search's end point as the MAP (the start list stays the multistart's).
pub fn adopt(map: &mut MapResult, again: MapResult) {
    map.evaluations += again.evaluations;
    map.polish_steps += again.polish_steps;
    map.map_x = again.map_x;
    map.map_physical = again.map_physical;
    map.laplace = again.laplace;
}

/// One polishing search from the MAP (no multistart).
fn polish(
    post: &FrfPosterior<'_>,
    map: &MapResult,
    params: &MapParams,
) -> Result<MapResult, MapError> {
    find_map(
        post,
        Some(&map.map_x),
        &MapParams {
            n_starts: 0,
            ..params.clone()
        },
        &|| (),
    )
}

/// Re-linearise the measurement bias at the MAP and search again from it until the MAP stops
/// moving (relative 1e-7 in every law parameter); leaves the bias linearised at the final MAP,
/// where the linearised and the exact likelihood agree in value and gradient.
pub fn relinearise_to_map(
    post: &mut FrfPosterior<'_>,
    map: &mut MapResult,
    params: &MapParams,
    nl: usize,
) -> Result<(), RefineError> {
    for _ in 0..MAX_RELINEARISATIONS {
        let p_lin = map.map_physical[..nl].to_vec();
        post.likelihood.forward.linearise_measurement(&p_lin)?;
        let again = polish(post, map, params)?;
        let moved = again.map_physical[..nl]
            .iter()
            .zip(&p_lin)
            .map(|(a, b)| ((a - b) / b).abs())
            .fold(0.0, f64::max);
        adopt(map, again);
        if moved < 1e-7 {
            break;
        }
    }
    post.likelihood
        .forward
        .linearise_measurement(&map.map_physical[..nl])?;
    Ok(())
}

/// A move of the MAP, in posterior sds, below which [`relinearise_model_to_map`] stops: the
/// log posterior at the MAP is then off by about `(1e-3)^2 / 2` nats at most.
pub const RELINEARISED_MOVE_SD: f64 = 1e-3;

/// [`relinearise_to_map`] for a forward model with free effects: every parameter of the
/// forward model is linearised (the law's in `ln p`, the effects' in `p`), and the MAP has
/// stopped moving when no unconstrained coordinate of the forward model moves by more than
/// [`RELINEARISED_MOVE_SD`] of its Laplace sd (1e-7 when the Hessian is not positive
/// definite). Leaves the bias linearised at the final MAP, where the linearised and the exact
/// likelihood agree in value and gradient (so the MAP's Laplace evidence is the exact
/// model's, to that tolerance).
pub fn relinearise_model_to_map(
    post: &mut FrfPosterior<'_>,
    map: &mut MapResult,
    params: &MapParams,
) -> Result<(), RefineError> {
    let np = post.likelihood.forward.n_params();
    for _ in 0..MAX_RELINEARISATIONS {
        post.likelihood
            .forward
            .linearise_model_measurement(&map.map_physical[..np])?;
        let again = polish(post, map, params)?;
        if again.gave_up() {
            adopt(map, again);
            break;
        }
        let d = again.laplace.dim();
        let settled = (0..np).all(|q| {
            let tol = if again.laplace.positive_definite {
                RELINEARISED_MOVE_SD * again.laplace.cov_x[q * d + q].max(0.0).sqrt()
            } else {
                1e-7
            };
            (again.map_x[q] - map.map_x[q]).abs() <= tol
        });
        adopt(map, again);
        if settled {
            break;
        }
    }
    post.likelihood
        .forward
        .linearise_model_measurement(&map.map_physical[..np])?;
    Ok(())
}

/// The channels' error correlation per line from the standardised residuals at the physical
/// parameters `physical` (law's, then noise scales), over `window` lines.
pub fn correlation_at(
    post: &FrfPosterior<'_>,
    physical: &[f64],
    kind: CorrelationKind,
    window: usize,
    freq_hz: &[f64],
) -> Result<ChannelCorrelation, RefineError> {
    let (pl, pn) = physical.split_at(post.likelihood.forward.n_params());
    let s = post.likelihood.standardised(pl, pn)?;
    let n_out = post.likelihood.data.n_out;
    Ok(match kind {
        CorrelationKind::Estimated => ChannelCorrelation::estimate(&s, n_out, window)?,
        CorrelationKind::Leakage => {
            let pred = post.likelihood.forward.predict(pl, false)?;
            ChannelCorrelation::leakage(&pred.values, freq_hz, &s, n_out, window, LEAKAGE_EPS_MIN)?
        }
    })
}

/// The channel-correlation fixed point: [`CORRELATION_PASSES`] times, the correlation at the
/// MAP (lines `freq_hz`), then the MAP again under it (re-linearising the measurement bias
/// after each search when `relinearise`). Leaves the correlation of the last pass set in `post`.
pub fn correlation_fixed_point(
    post: &mut FrfPosterior<'_>,
    map: &mut MapResult,
    params: &MapParams,
    kind: CorrelationKind,
    window: usize,
    freq_hz: &[f64],
    relinearise: bool,
) -> Result<(), RefineError> {
    let nl = post.n_law();
    for _ in 0..CORRELATION_PASSES {
        let c = correlation_at(post, &map.map_physical, kind, window, freq_hz)?;
        post.likelihood.set_channel_correlation(Some(c))?;
        let again = polish(post, map, params)?;
        adopt(map, again);
        if relinearise {
            relinearise_to_map(post, map, params, nl)?;
        }
    }
    Ok(())
}
