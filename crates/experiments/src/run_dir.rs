//! The output directory of a study run: locked for the whole run, and the engine that writes the
//! study's records into it ([`open`]), as every study command (the paper reproduction, the
//! structure studies, a user's study) starts.

use std::path::Path;

use crate::engine::Engine;
use crate::error::Result;
use crate::sweep::lock::DirLock;
use crate::sweep::Shard;

/// Locks the output directory `out` for the whole run (until the lock is dropped) and gives the
/// engine that runs a study's sweeps into it: how every study command starts.
pub(crate) fn open(
    out: &Path,
    threads: usize,
    shard: Shard,
    progress: bool,
    resume: bool,
) -> Result<(DirLock, Engine<'_>)> {
    let lock = DirLock::acquire(out)?;
    let engine = Engine {
        out,
        threads,
        shard,
        progress,
        resume,
    };
    Ok((lock, engine))
}
