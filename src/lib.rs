//! rfmlab: identification of viscoelastic constitutive models of adhesives in bonded
//! joints from measured frequency response functions (FRFs).
//!
//! Module map, from the command line down (a module imports only modules below it):
//!
//! | module | what it holds |
//! |---|---|
//! | [`report`] | results -> parquet, figures, report.md, manifest.json in one atomic folder swap; `run_study`; the material command's files |
//! | [`pipeline`] | the public API: study -> [`pipeline::Plan`] (typed `*Params` per stage) -> [`pipeline::run`] -> [`Results`] with every table; `check` |
//! | [`design`] | test planning (`rfmlab design`): candidate sensor places, the likelihood's Fisher information with the noise the measurement chain will give, greedy search with exchange, design.parquet and design.md |
//! | [`diagnose`] | the closed loop as a stage of a run and `rfmlab diagnose`: candidate effects and their term ROM, the loop at every level, its verdict, tables and markdown |
//! | [`bayes`] | the Bayesian stages of a run: posterior per model and level, MAP, samplers, evidence and comparison criteria, redundancy, basins, the comparison across levels |
//! | [`identify`] | the deterministic identification of a level: RFM per line, per band and per model, circle fit + IEM, correlation, sensitivities, the leakage fixed point |
//! | [`stage`] | what the stages share: a level's measured data, progress events, the run's error; loading the levels, the model, the FRF engines, the measurement model, the pre-flight |
//! | [`validate`] | statistical validation of the Bayesian layer (SBC, coverage, model selection, quadrature), sharded |
//! | [`simulate`] | the virtual experiment of an experiment file (`rfmlab simulate`) and its UFF58 + truth files |
//! | [`study`] | study files: TOML as written -> validated typed study |
//! | [`closed_loop`] | the closed loop's numerics: residuals, score tests, refits, alternative laws, confounding, the verdict |
//! | [`material_fit`] | material-level loop on measured E'(w), E''(w) (DMA): posterior, residual tests, Kramers-Kronig check |
//! | [`inference`] | likelihood, MAP (argmin multistart, Levenberg-Marquardt), samplers (NUTS, TMCMC), evidence, diagnostics |
//! | [`forward`] | the forward model: engine + law + effects + H1 measurement model -> predicted H1 and its Jacobian |
//! | [`rfm`] | response function method updating (paper eq. 9-11, 37) |
//! | [`rom`] | certified reduced-order model and the pencil sweep |
//! | [`modes`] | complex modes of (K_b + E* S, M), sparse real eigensolver |
//! | [`experiment`] | virtual experiment: random excitation, H1 and coherence |
//! | [`frf`] | the FRF engine interface and the full-model sweep with sensitivities (paper eq. 44-47) |
//! | [`plot`] | PNG/SVG figures |
//! | [`modal`] | circle-fit modal analysis |
//! | [`fe`] | 20-node hexahedra, structured mesher, sparse assembly of M, K_b, S; Matrix Market import |
//! | [`linalg`] | sparse and small dense linear-algebra helpers |
//! | [`data`] | measured FRF data model, UFF58 and CSV readers and writers |
//! | [`output`] | parquet tables, manifest, atomic writes |
//! | [`material`] | constitutive models E*(w; p) with analytic Jacobians (Models 1-5, fractional Zener, generalized Maxwell) |
//! | [`correlation`] | FRAC, SCC, ACC (paper eq. 38-40) |
//! | [`iem`] | inverse eigensensitivity method (paper eq. 20) |
//! | [`stats`] | priors of parameters and effects, the chi-square tail and the normal quantile |
//! | [`common`] | shared small types: complex scalar, directions, units |
//! | [`fs_atomic`] | atomic file replacement (unique temporary sibling, fsync, rename) for every writer |
//!
//! The numerical modules (from `closed_loop` down, except `plot` and `output`) never import
//! `study`, `output`, `plot` or the CLI. Below the pipeline, every stage takes its `*Params` and typed inputs, never the
//! whole study; only the plan's constructors and the single-stage entry points read one.
//!
//! # The public API
//! A study file -> [`Study::load`] -> [`Study::plan`] (typed `*Params` per stage) ->
//! [`pipeline::run`] with a [`pipeline::Executor`] (ROM cache, progress observers,
//! cancellation, timings) -> [`Results`] in memory -> [`report::write`] (parquet, figures,
//! report.md, manifest.json, swapped into place as one folder). The CLI's `rfmlab run` is
//! this path.
//!
//! ```
//! use rfmlab::{pipeline, Study};
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let study = Study::load("studies/default.toml")?;
//! let mut plan = study.plan()?;
//! // A plan can be edited before it runs: here Model 4 at Level 1 only, without the
//! // per-line estimates, sensitivities and figures.
//! plan.identification.models.retain(|m| m.name == "model4");
//! plan.data.levels.retain(|l| l.name == "L1");
//! plan.identification.per_line = false;
//! plan.identification.sensitivity = false;
//! plan.figures = false;
//! let results = pipeline::run(&plan, &mut pipeline::Executor::new())?;
//! let m4 = results.identified_at("L1", "model4").expect("model4 ran at L1");
//! assert!(m4.frac_updated.iter().all(|&f| f > 0.99));
//! // The data were simulated with E0 = 6.67 MPa (studies/data/paper_virtual.truth.json).
//! let e0 = m4.identified[m4.names.iter().position(|n| n == "E0").unwrap()];
//! assert!((e0 / 6.67e6 - 1.0).abs() < 0.03, "E0 = {e0} Pa");
//! // Every table of the results folder, in memory (polars DataFrames).
//! assert!(results.table("parameters").unwrap().height() == 4);
//! let dir = std::env::temp_dir().join(format!("rfmlab-doc-{}", std::process::id()));
//! let written = rfmlab::report::write(&results, dir.join("default"))?;
//! assert!(written.files.iter().any(|f| f == "parameters.parquet"));
//! # std::fs::remove_dir_all(&dir)?;
//! # Ok(())
//! # }
//! ```

// Index loops are the clearest form of many linear-algebra kernels here, and `!(x > 0.0)` is
// the deliberate NaN-rejecting form of a positivity check.
#![allow(clippy::needless_range_loop, clippy::neg_cmp_op_on_partial_ord)]

pub mod bayes;
pub mod closed_loop;
pub mod common;
pub mod correlation;
pub mod data;
pub mod design;
pub mod diagnose;
pub mod discretisation;
pub mod experiment;
pub mod fe;
pub mod forward;
pub mod frf;
pub mod fs_atomic;
pub mod identify;
pub mod iem;
pub mod inference;
pub mod linalg;
pub mod material;
pub mod material_fit;
pub mod modal;
pub mod modes;
pub mod output;
pub mod pipeline;
pub mod plot;
pub mod report;
pub mod rfm;
#[allow(clippy::needless_borrow)]
pub mod rom;
pub mod simulate;
pub mod stage;
pub mod stats;
pub mod study;
pub mod validate;

pub use pipeline::Results;
pub use study::Study;
