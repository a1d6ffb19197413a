//! The one error of the workspace's libraries above the filters: `identify`'s, with its
//! helpers and macros, so that a study's `?` and an identification's meet in one type.

pub use identify::error::*;
