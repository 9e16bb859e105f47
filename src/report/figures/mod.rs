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
