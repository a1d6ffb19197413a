//! The integration tests of `models`, one test binary: each file beside this one is a module
//! (its tests are `<file>::<test>`), so the workspace links one executable where it linked one
//! per file.
//! `rejuvenation_no_alloc.rs` stays a binary of its own: it counts the process's allocations, which
//! other tests running beside it would move.

mod filtering_support;
mod fuzz_common;

#[path = "building_chain.rs"]
mod building_chain;
#[path = "chain_filters.rs"]
mod chain_filters;
#[path = "filtering_consistency.rs"]
mod filtering_consistency;
#[path = "filtering_damping_bias.rs"]
mod filtering_damping_bias;
#[path = "filtering_derivatives.rs"]
mod filtering_derivatives;
#[path = "filtering_discretisation.rs"]
mod filtering_discretisation;
#[path = "fuzz_import.rs"]
mod fuzz_import;
#[path = "fuzz_readers.rs"]
mod fuzz_readers;
#[path = "import.rs"]
mod import;
#[path = "inputs_bounded.rs"]
mod inputs_bounded;
#[path = "physics.rs"]
mod physics;
#[path = "readers.rs"]
mod readers;
#[path = "second_law.rs"]
mod second_law;
