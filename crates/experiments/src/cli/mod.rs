//! Subcommands of `sysid`, one module each. Each module exposes `Args` (clap) and `run`.

pub mod cluster;
pub mod field_study;
pub mod filter;
pub mod import;
pub mod loglik;
pub mod merge;
pub mod plot;
pub mod reference;
pub mod regression;
pub mod reproduce;
pub mod scaling;
pub mod simulate;
pub mod study;
pub mod table1;
pub mod validate;
