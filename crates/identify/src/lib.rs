//! # identify
//!
//! One identification as a user runs it, from data to answer: the plan of the run (settled
//! once, the default rules beside it), the filter pipeline and the pool of filters, the run
//! record, the plausibility checks, the residuals, the validation without the truth (free run,
//! transfer functions, modal analysis) and the figures of one run. The studies, their engine,
//! reports and the `sysid` command-line tool live in the `experiments` crate above this one.
//!
//! - [`plan`]: the one typed plan of a run, settled once ([`rules`]: every default rule);
//! - [`pipeline`]: runs a plan (the runner, the observer, the pool of filters);
//! - [`identification`]: one identification as `sysid filter` runs it, and the decision on its
//!   record;
//! - [`choice`]: the noise level and damping form of a field identification, chosen by
//!   held-out prediction;
//! - [`record`]: the run record written for every run: types only, the leaf every analysis
//!   imports;
//! - [`checks`]: plausibility warnings on a finished run record;
//! - [`residuals`]: whiteness and size of the one-step prediction errors;
//! - [`validation`]: free run, transfer functions and modes of an identified building;
//! - [`metrics`]: θ_val, relative errors, CV(RMSE) and NRMSE (SPEC §7);
//! - [`observe`]: the observer that records traces and online errors during a run;
//! - [`settings`] and [`limits`]: the filter settings of a run and their limits;
//! - [`field`]: field data and the building a user describes;
//! - [`simulation`]: the data set a simulation request (`sysid simulate`) describes;
//! - [`figures`] and [`plot`]: the drawing layer and the figures of one run, from its record.

pub mod algorithm;
pub mod checks;
pub mod choice;
pub mod error;
pub mod field;
pub mod figures;
pub mod identification;
pub mod limits;
pub mod logger;
pub mod metrics;
pub mod observe;
pub mod pipeline;
pub mod plan;
pub mod plot;
mod pool;
pub mod record;
pub mod residuals;
pub mod rules;
pub mod scaled_prior;
pub mod settings;
pub mod simulation;
pub mod spread;
pub mod validation;
