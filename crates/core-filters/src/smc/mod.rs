//! Particle filters on run-time dimensions.
//!
//! - [`model`]: the capability traits a model implements (augmented state space, conditionally
//!   linear, conditionally quadratic), with staged transitions for semi-implicit schemes;
//! - [`store`]: flat, preallocated particle storage;
//! - [`runner`]: the one runner (resampling, ancestors, observers) and the [`runner::Filter`]
//!   adapter trait;
//! - [`rejuvenation`]: the Liu–West move of the sampled static parameters after resampling
//!   (off unless a run asks for it);
//! - [`batch`]: the batch layer that runs a filter's per-particle step for four particles at once
//!   in SIMD lanes, bit for bit as one at a time;
//! - [`bootstrap`], [`mlnrbpf`], [`storvik`], [`mpf`]: the four filters (SPEC §5), each a small
//!   adapter around its per-particle step.

pub mod batch;
pub mod bootstrap;
pub mod linear_plan;
pub mod mlnrbpf;
pub mod model;
pub mod mpf;
pub mod rejuvenation;
pub mod runner;
pub mod store;
pub mod storvik;

pub use rejuvenation::{LiuWest, StaticParam, Support};
pub use runner::{
    run, Filter, Observer, Posterior, RunSummary, SmcConfig, StepInfo, StepInput, StepOutput,
};
pub use store::{Particles, Shape};
