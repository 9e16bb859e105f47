//! The stages of a study's run, sequenced by [`crate::pipeline`] (`rfmlab run STUDY.toml`) and
//! `rfmlab check STUDY.toml`. It sits outside the numerical core (like `study`, `output`,
//! `plot`) and wires them together:
//!
//! 1. load the measured data of every level (UFF58, [`crate::data::frf_set_from_uff`]) and check
//!    it ([`crate::data::check_level`]: excitation channel present, band covered);
//! 2. build the structural model ([`crate::study::build::build_model`]) and the FRF engine: the
//!    certified ROM ([`crate::rom::build_rom`], over the band and a modulus range covering every
//!    model's initial E*(w) and plausible results, prepared for the band's lines) or the full
//!    model ([`crate::frf::FullModel`]) when `solver.engine = "full"`; its inputs are all measured
//!    points (the RFM needs a square engine, see [`crate::rfm`]);
//! 3. per level, the measured accelerance column H'_X,ij (i = channels, j = the excitation point)
//!    and the analyses: per-line RFM (paper eq. 10-11, Fig. 13/18), Model 1 over bands (case
//!    study 1), circle fit (Table 2) and IEM (eq. 20, Table 3), global RFM per model (eq. 37,
//!    Tables 4-5), correlation (FRAC eq. 38, SCC eq. 39, ACC eq. 40) and sensitivities (Fig. 9);
//! 4. the tables, figures and report sections of the results (`report/tables/` lists the
//!    tables, their columns and units), written by [`crate::report::write`] in one atomic
//!    folder swap.

pub use crate::pipeline::{check_study, CheckSummary};
pub use crate::stage::preflight;
pub(crate) mod settings;

pub use crate::stage::{Event, LevelData, LevelTruth, RunError};
// Old paths, removed once every caller moved.
pub(crate) use crate::identify::frf_of;
pub use crate::identify::{BandConstantResult, GlobalResult, IemBandResult, SensitivityCurves};
pub use crate::pipeline::results::LevelResults;
pub use crate::pipeline::{ModelSummary, RunOptions, RunSummary};
pub mod closed_loop {
    pub use crate::diagnose::*;
}
pub use crate::diagnose::{prepared, terms};
mod bayes_paths;
pub use crate::bayes::{basins, compare, levels, redundancy};
pub use bayes_paths::{declared, posterior};
/// Old path of [`crate::bayes`], removed once every caller moved.
pub mod bayes {
    pub use crate::bayes::*;
}

use crate::study::build::BuiltModel;
use crate::study::Study;
use std::path::PathBuf;

/// Old path of [`crate::stage::data::load_levels`], removed once every caller moved.
pub fn load_levels(study: &Study, built: &BuiltModel) -> Result<Vec<LevelData>, RunError> {
    crate::stage::data::load_levels(study.measurements.as_ref(), built, &study.file)
}

/// Old path of [`crate::stage::rom_cache_dir`].
pub fn rom_cache_dir(study: &Study) -> PathBuf {
    crate::stage::rom_cache_dir(&study.output_dir)
}
