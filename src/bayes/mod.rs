//! The Bayesian stages of a run (`[inference]`), per level and model: the posterior over the
//! law's parameters (and the declared free effects and noise scales) through one forward
//! model, its multistart MAP with the Laplace approximation, the samplers, the evidence and
//! the model-comparison criteria, the parameter redundancy and the basin study; and across
//! levels, the level-to-level change of E*(w) and the evidence of shared law parameters.
//! Orchestration of the numerics in [`crate::forward`] and [`crate::inference`]; outside the
//! numerical core, below the pipeline: the stages take their parameters
//! ([`InferenceParams`]) and typed inputs ([`RunContext`]), never the study.
//!
//! | module | what it computes |
//! |---|---|
//! | [`posterior`] | the posterior of a model at a level; draws and sampler results |
//! | [`infer`] | MAP and samplers of every model at a level ([`infer_level`]) |
//! | [`linearisation`] | the linearised measurement bias checked on the draws, exact evidence |
//! | [`sample`] | NUTS and TMCMC with checkpoints |
//! | [`compare`] | evidence (Laplace, TMCMC, stepping-stone), widened priors, LOO, WAIC, PPC |
//! | [`redundancy`] | sensitivity SVD, posterior correlation, identifiability |
//! | [`basins`] | the MAP search and the RFM from space-filling starts, clustered into basins |
//! | [`levels`] | the change of E', E'' between two levels; shared against separate parameters |
//! | [`declared`] | the study's declared effects as forward-model effects of a level |
//! | [`mesh_allowance`] | the mesh's remaining discretisation error marginalised in the posteriors |
//!
//! The report writers turn the stages' results into tables, figures and report sections.

pub mod basins;
pub mod compare;
mod context;
pub mod declared;
pub mod infer;
pub mod levels;
pub mod linearisation;
pub mod mesh_allowance;
mod params;
pub mod posterior;
pub mod redundancy;
pub mod sample;

pub use basins::basins_of_level;
pub use context::{At, Checkpoints, PosteriorInputs, RunContext};
pub use infer::{infer_level, map_status, PosteriorResult};
pub use params::{stages_at, InferenceParams, SamplerParams};

use crate::stage::RunError;

/// A failed analysis step (`what` names the model and level) and why.
pub(crate) fn fail(what: String, e: impl std::fmt::Display) -> RunError {
    RunError::Analysis {
        analysis: what,
        message: e.to_string(),
    }
}

pub(crate) use crate::stage::input_error as input_err;
