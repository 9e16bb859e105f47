//! `rfmlab diagnose STUDY.toml`: the closed loop ([`crate::closed_loop`]) at every level of the
//! study's `[inference]` section, for its first model (or the one asked for), with the default
//! candidates: a point mass at every measured point, a gain and a delay per channel, the beam
//! modulus factor (left out when the adherend has viscous damping `C_b`, where its exact
//! scaling does not hold), the Maxwell branches, and the fractional Zener law as an alternative
//! law ([`crate::closed_loop::alternative`]; opt-out in `[closed_loop] candidates`); on a
//! meshed joint, when `candidates` names it, also a sensor mass (x, y and z) at every measured
//! point. Each level ends with a
//! verdict ([`crate::closed_loop::verdict`]) against a null level calibrated on replicates of
//! the fitted model. Writes the parquet tables `residuals`, `candidates`, `closed_loop`,
//! `verdict`, `signatures` and a markdown summary `closed_loop.md` (its first line the status
//! per level) into `<output_dir>.diagnose/`.
//!
//! The same loop is a stage of a run (`[closed_loop]` in a study with `[inference]`,
//! [`crate::pipeline`]). One concern per file:
//!
//! | file | what it holds |
//! |---|---|
//! | `params.rs` | the stage's typed settings ([`DiagnoseParams`]) and what it runs on ([`LoopInputs`]) |
//! | `of_study.rs` | the settings made from a validated study: the one file that reads a [`crate::study::Study`] |
//! | `command.rs` | `rfmlab diagnose`: a study's loop into a results folder of its own |
//! | `directions.rs` | the engine of a pass with every point's three directions, on the first pass's for the measured ones |
//! | `stage.rs` | the loop at every level: its start, the term ROM, the loop, the verdict |
//! | `candidates.rs` | the candidate effects, from the joint's model and `[closed_loop] candidates` |
//! | `terms.rs` | the term ROM of the effects with matrices of their own |
//! | `term_box.rs` | the term ROM's modulus box and the band of the levels |
//! | `conclude.rs` | the null level of the measurement chain and the verdict |
//! | `summary.rs` | what the loop found, per level |
//! | `tables.rs`, `level_tables.rs` | the parquet tables, and writing them with the figures |
//! | `markdown.rs` | `closed_loop.md` and the loop's section of the run's report |
//! | [`prepared`] | a study's posteriors evaluated outside a run (the Python binding) |
//!
//! Below the entry points ([`diagnose_study`], [`diagnose_into`], [`DiagnoseParams::of`],
//! [`params_of`]) nothing takes a study: the stage takes its params and typed inputs.

mod candidates;
mod command;
mod conclude;
mod directions;
mod level_tables;
mod markdown;
pub mod mesh;
mod of_study;
mod params;
pub mod prepared;
mod stage;
mod summary;
mod tables;
mod term_box;
pub mod terms;

pub use candidates::{bond_candidates, term_candidates, with_declared};
pub use command::{diagnose_into, diagnose_into_as, diagnose_study};
pub use markdown::{report_section, status_line};
pub use of_study::{params_of, wants_sensor_mass, StudyPosterior};
pub use params::{DiagnoseParams, LevelPosterior, LoopInputs, NullChainParams, TermParams};
pub use stage::loop_stage;
pub use summary::{DiagnoseLevel, DiagnoseSummary, LevelResult, LoopOutcome, ParameterChange};
pub use tables::{loop_tables, write_loop};
pub use term_box::{band_of, outside_box, term_modulus_range};
