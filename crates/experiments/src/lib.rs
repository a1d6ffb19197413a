//! # experiments
//!
//! The studies and the command-line tool, over one identification of the `identify` crate:
//! study descriptions, sweeps over runs, the engine that runs every study, reports with tested
//! verdicts, study figures, the Slurm cluster, the accuracy regression, and the subcommands of
//! the `sysid` command-line tool (module [`cli`]: each parses its flags, calls a library and
//! prints; nothing else uses it). What one identification is — its plan, pipeline, record,
//! checks and validation — lives in `identify`; this crate only runs it many times.
//!
//! - [`study`]: a study description (the paper's figures and every sweep of §9);
//! - [`sweep`]: parallel, resumable, shardable sweeps over runs;
//! - [`engine`]: runs any study description through a sweep; each study keeps only its summary
//!   and report;
//! - [`regression`]: the identification-accuracy regression check;
//! - [`scaling`]: the scaling study (chains of 3 to 40 storeys), its figures and report;
//! - [`verdict`]: the paper's statements decided by stated tests on the records (REPORT.md);
//! - [`reference`](mod@reference), [`likelihood`], [`information`]: the reference posterior, the likelihood
//!   over seeds, the information of a record;
//! - [`field_study`]: candidate models of real records, selected on held-out records;
//! - [`cluster`]: any study as a Slurm job array (submit, status, resubmit, finish);
//! - [`calibration`] and [`coverage`]: coverage of credible intervals over a sweep with known truth;
//! - [`fuzz`]: the fuzz driver of the command line and the Python package (`cargo xtask fuzz`).

pub mod calibration;
pub mod cli;
pub mod cli_reference;
pub mod cluster;
pub mod console;
pub mod coverage;
pub mod decimate;
pub mod discretisation;
pub mod engine;
pub mod error;
pub mod excitations;
pub mod field_study;
pub mod foreign;
pub mod fuzz;
pub mod headline;
pub mod information;
pub mod likelihood;
mod markdown;
pub(crate) mod pace;
pub(crate) mod project;
pub mod reference;
pub mod regression;
pub mod report;
pub mod reproduce;
mod run_dir;
pub mod scaling;
pub mod stats;
pub mod study;
pub mod sweep;
pub mod table1;
pub mod user_study;
pub mod verdict;
