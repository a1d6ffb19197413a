//! # experiments
//!
//! Everything with I/O: experiment configs, sweeps over runs, metrics, run records, figures,
//! reports, and the subcommands of the `sysid` command-line tool (module [`cli`]: each parses its
//! flags, calls the library and prints; nothing else uses it).
//!
//! - [`limits`]: checks of user-given filter settings against the limits of `models::limits`;
//! - [`metrics`]: θ_val, relative errors, CV(RMSE) and NRMSE (SPEC §7);
//! - [`observe`]: the observer that records traces and online errors during a run;
//! - [`record`]: the run record written for every run: types only, the leaf every analysis
//!   imports;
//! - [`settings`]: the filter settings of a run;
//! - [`identification`]: one identification as `sysid filter` runs it, and the decision on its
//!   record;
//! - [`simulation`]: the data set a simulation request (`sysid simulate`) describes;
//! - [`regression`]: the identification-accuracy regression check;
//! - [`plot`]: the figures of one run, from its record;
//! - [`sweep`]: parallel, resumable, shardable sweeps over runs;
//! - [`engine`]: runs any study description through a sweep; each study keeps only its summary
//!   and report;
//! - [`scaling`]: the scaling study (chains of 3 to 40 storeys), its figures and report;
//! - [`verdict`]: the paper's statements decided by stated tests on the records (REPORT.md);
//! - [`checks`]: plausibility warnings on a finished run record;
//! - [`choice`]: the noise level and damping form of a field identification, chosen by
//!   held-out prediction;
//! - [`cluster`]: any study as a Slurm job array (submit, status, resubmit, finish);
//! - [`calibration`] and [`coverage`]: coverage of credible intervals over a sweep with known truth.

pub mod algorithm;
pub mod calibration;
pub mod checks;
pub mod choice;
pub mod cli;
pub mod cli_reference;
pub mod cluster;
pub mod coverage;
pub mod decimate;
pub mod discretisation;
pub mod engine;
pub mod error;
pub mod excitations;
pub mod field;
pub mod field_study;
pub mod figures;
pub mod headline;
pub mod identification;
pub mod information;
pub mod likelihood;
pub mod limits;
pub mod logger;
mod markdown;
pub mod metrics;
pub mod observe;
pub mod pace;
pub mod pipeline;
pub mod plan;
pub mod plot;
mod pool;
pub mod record;
pub mod reference;
pub mod regression;
pub mod report;
pub mod reproduce;
pub mod residuals;
pub mod rules;
mod run_dir;
pub mod scaled_prior;
pub mod scaling;
pub mod settings;
pub mod simulation;
pub mod stats;
pub mod study;
pub mod sweep;
pub mod table1;
pub mod user_study;
pub mod validation;
pub mod verdict;
