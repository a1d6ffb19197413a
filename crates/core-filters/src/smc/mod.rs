//! Particle filters on run-time dimensions.
//!
//! - [`model`]: the capability traits a model implements (augmented state space, conditionally
//!   linear, conditionally quadratic), with staged transitions for semi-implicit schemes.
pub mod model;
