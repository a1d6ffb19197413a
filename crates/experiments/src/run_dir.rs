//! The output directory of a study run: locked for the whole run, and the engine that writes the
//! study's records into it ([`open`]), as every study command (the paper reproduction, the
//! structure studies, a user's study) starts.

use std::path::Path;

use crate::engine::{Engine, RunMode};
use crate::error::Result;
use crate::sweep::lock::DirLock;

/// Locks the output directory `out` for the whole run (until the lock is dropped) and gives the
/// engine that runs a study's sweeps into it: how every study command starts.
pub(crate) fn open(out: &Path, mode: RunMode) -> Result<(DirLock, Engine<'_>)> {
    let lock = DirLock::acquire(out)?;
    Ok((lock, Engine { out, mode }))
}
