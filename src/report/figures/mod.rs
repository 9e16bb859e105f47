//! The figures of a run, drawn when the plan asks for them (`[output] figures`), each as
//! `<name>.png` and `<name>.svg` in the results folder:
//!
//! * [`identification`]: per level the FRFs, SCC and ACC, convergence and E*(f) of the
//!   deterministic identification;
//! * [`posterior`]: trace and pair plots per level and model, posterior bands of E*(f) per
//!   model;
//! * [`levels`]: posterior bands of every model and level, identifiability, basin maps.

mod identification;
mod levels;
mod posterior;

use crate::bayes::PosteriorResult;
use crate::pipeline::Results;
use crate::stage::RunError;
use std::path::Path;

/// Draw every figure of `results` into `dir`; returns (file name of the PNG, caption), in the
/// order report.md shows them.
pub(super) fn draw(dir: &Path, results: &Results) -> Result<Vec<(String, String)>, RunError> {
    let posts: Vec<&PosteriorResult> = results.posteriors().collect();
    let mut f = identification::draw_figures(dir, results.levels(), results.level_results())?;
    f.extend(posterior::figures(dir, &posts)?);
    f.extend(levels::figures(dir, results.level_results())?);
    Ok(f)
}

/// E'(f) and E''(f) (Pa) of `law` on `freq_hz` at every `step`-th draw of `draws`: the curves
/// of a posterior band figure, `(storage, loss)` one row per draw used.
fn modulus_bands(
    law: &dyn crate::material::ConstitutiveModel,
    draws: &crate::bayes::posterior::Draws,
    freq_hz: &[f64],
    step: usize,
) -> (Vec<Vec<f64>>, Vec<Vec<f64>>) {
    let nl = law.n_params();
    let (mut storage, mut loss) = (Vec::new(), Vec::new());
    for r in (0..draws.chain.len()).step_by(step) {
        let par: Vec<f64> = (0..nl).map(|k| draws.values[k][r]).collect();
        let e: Vec<crate::common::C64> = freq_hz
            .iter()
            .map(|f| law.modulus(&par, std::f64::consts::TAU * f))
            .collect();
        storage.push(e.iter().map(|z| z.re).collect());
        loss.push(e.iter().map(|z| z.im).collect());
    }
    (storage, loss)
}
