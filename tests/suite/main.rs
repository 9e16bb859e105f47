//! The integration suite: one test binary (one link of the library and its dependencies instead of
//! one per file, which kept CI within its disk). Filter by module: `cargo test --test suite rom_joint::`.

// Shared fixtures.
mod common_data;
mod numerics;
mod python_checks;
mod rom_model;
mod runner_common;
mod spring_model;

mod bayes_run;
mod circle_fit;
mod cli_errors;
mod cli_inspect;
mod cli_rom;
mod cli_simulate;
mod cli_structure_errors;
mod closed_loop;
mod closed_loop_fast;
mod closed_loop_td;
mod correlation;
mod csv_io;
mod data_checks;
mod declared_effects;
mod default_data;
mod default_study;
mod effects;
mod experiment;
mod fe_cantilever;
mod fe_element;
mod fe_joint;
mod frf_full;
mod iem;
mod inference_diagnostics;
mod inference_grid;
mod inference_likelihood;
mod inference_samplers;
mod material;
mod material_fit;
mod matrix_market;
mod measurement_model;
mod model_comparison;
mod modes;
mod output;
mod paper_joint;
mod plot;
mod replicates;
mod rfm;
mod rfm_gauss_newton;
mod rom;
mod rom_joint;
mod runner;
mod uff_fuzz;
mod uff_real_files;
mod uff_roundtrip;
mod validate;
mod virtual_experiment;
