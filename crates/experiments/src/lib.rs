//! # experiments
//!
//! Everything with I/O: experiment configs, sweeps over runs, metrics, run records, figures,
//! reports, and the subcommands of the `sysid` command-line tool (module [`cli`]).

pub mod cli;
