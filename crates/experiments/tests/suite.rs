//! The studies' and the `sysid` command's integration tests, one test binary: each file beside
//! this one is a module (its tests are `<file>::<test>`), so the workspace links one executable
//! where it linked one per file. `settle_once.rs` stays a binary of its own: it reads the
//! process's settling counters, which other tests running beside it would move.

mod common;

#[path = "calibration.rs"]
mod calibration;
#[path = "checks.rs"]
mod checks;
#[path = "cli_filter.rs"]
mod cli_filter;
#[path = "cli_import.rs"]
mod cli_import;
#[path = "cli_summary.rs"]
mod cli_summary;
#[path = "cli_validate.rs"]
mod cli_validate;
#[path = "cluster.rs"]
mod cluster;
#[path = "cluster_submit.rs"]
mod cluster_submit;
#[path = "coloured_noise.rs"]
mod coloured_noise;
#[path = "coverage.rs"]
mod coverage;
#[path = "discrepancy.rs"]
mod discrepancy;
#[path = "discretisation.rs"]
mod discretisation;
#[path = "excitations.rs"]
mod excitations;
#[path = "foreign.rs"]
mod foreign;
#[path = "fuzz_cli.rs"]
mod fuzz_cli;
#[path = "fuzz_configs.rs"]
mod fuzz_configs;
#[path = "generated_docs.rs"]
mod generated_docs;
#[path = "harness.rs"]
mod harness;
#[path = "held_out_choice.rs"]
mod held_out_choice;
#[path = "information.rs"]
mod information;
#[path = "inputs_settings.rs"]
mod inputs_settings;
#[path = "inputs_simulate.rs"]
mod inputs_simulate;
#[path = "inputs_structure.rs"]
mod inputs_structure;
#[path = "interval_spread.rs"]
mod interval_spread;
#[path = "learned_noise.rs"]
mod learned_noise;
#[path = "loglik.rs"]
mod loglik;
#[path = "merge_cli.rs"]
mod merge_cli;
#[path = "named_excitation.rs"]
mod named_excitation;
#[path = "plan.rs"]
mod plan;
#[path = "plot.rs"]
mod plot;
#[path = "predictive_band.rs"]
mod predictive_band;
#[path = "python_build_reuse.rs"]
mod python_build_reuse;
#[path = "readme_walkthrough.rs"]
mod readme_walkthrough;
#[path = "record_numbers.rs"]
mod record_numbers;
#[path = "records.rs"]
mod records;
#[path = "reference.rs"]
mod reference;
#[path = "regression.rs"]
mod regression;
#[path = "rejuvenation.rs"]
mod rejuvenation;
#[path = "reliability.rs"]
mod reliability;
#[path = "reliability_figures.rs"]
mod reliability_figures;
#[path = "reliability_fuzz_found.rs"]
mod reliability_fuzz_found;
#[path = "reliability_inputs.rs"]
mod reliability_inputs;
#[path = "reliability_outputs.rs"]
mod reliability_outputs;
#[path = "residuals.rs"]
mod residuals;
#[path = "scaling.rs"]
mod scaling;
#[path = "sparse_sensors.rs"]
mod sparse_sensors;
#[path = "substep_check.rs"]
mod substep_check;
#[path = "user_study.rs"]
mod user_study;
#[path = "verdict.rs"]
mod verdict;
#[path = "whiteness_calibration.rs"]
mod whiteness_calibration;
