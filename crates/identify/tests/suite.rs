//! The integration tests of `identify`, one test binary: each file beside this one is a module
//! (its tests are `<file>::<test>`), so the workspace links one executable where it linked one
//! per file.

#[path = "building_chain.rs"]
mod building_chain;
#[path = "field_scaled_prior.rs"]
mod field_scaled_prior;
#[path = "figures.rs"]
mod figures;
#[path = "interrupt.rs"]
mod interrupt;
#[path = "legibility.rs"]
mod legibility;
#[path = "mass_damping.rs"]
mod mass_damping;
#[path = "pool.rs"]
mod pool;
#[path = "substeps_auto.rs"]
mod substeps_auto;
#[path = "validation.rs"]
mod validation;
