//! Every table of a run, built in memory from its results ([`crate::output::Table`]: columns
//! with their units) and held by [`crate::pipeline::Results`]; [`crate::report::write`]
//! writes each as `<name>.parquet`, the units in the file metadata key `rfmlab.units`. One
//! file per part of the run, each listing its tables, columns and units:
//!
//! * [`identification`]: the deterministic identification (`frf`, `parameters`,
//!   `iterations`, `correlation`, `correlation_curves`, `modulus`, `svd`, `modal`,
//!   `sensitivity`);
//! * [`posterior`]: the `[inference]` part (`draws`, `summary`, `starts`, `laplace`,
//!   `sampler_runs`);
//! * [`comparison`]: the model comparison (`evidence`, `model_comparison`, `ppc`,
//!   `predictive`, `pointwise_loglik`);
//! * [`levels`]: across levels, redundancy and basins (`level_change`, `level_evidence`,
//!   `redundancy`, `basins`).

pub(crate) mod comparison;
mod identification;
pub(crate) mod levels;
pub(crate) mod posterior;

pub(crate) use posterior::summaries;

use crate::bayes::PosteriorResult;
use crate::output::Table;
use crate::pipeline::LevelResults;
use crate::stage::{LevelData, RunError};

/// Every table of a run, in the order they are written: the deterministic ones, then the
/// inference, comparison and across-level ones (those only when computed).
pub(crate) fn all(levels: &[LevelData], results: &[LevelResults]) -> Result<Vec<Table>, RunError> {
    let mut out = identification::tables(levels, results)?;
    let posts: Vec<&PosteriorResult> = results.iter().flat_map(|r| r.posteriors.iter()).collect();
    out.extend(posterior::tables(levels, &posts)?);
    out.extend(comparison::tables(&posts)?);
    out.extend(levels::tables(results)?);
    Ok(out)
}
