//! The integration tests of `core-filters`, one test binary: each file beside this one is a module
//! (its tests are `<file>::<test>`), so the workspace links one executable where it linked one
//! per file.
//! `smc_no_alloc.rs` stays a binary of its own: it counts the process's allocations, which
//! other tests running beside it would move.

mod smc_common;

#[path = "coverage_linear.rs"]
mod coverage_linear;
#[path = "credible.rs"]
mod credible;
#[path = "kalman.rs"]
mod kalman;
#[path = "rejuvenation.rs"]
mod rejuvenation;
#[path = "resampling.rs"]
mod resampling;
#[path = "smc_linear.rs"]
mod smc_linear;
#[path = "smc_mpf.rs"]
mod smc_mpf;
#[path = "support.rs"]
mod support;
