//! `sysid filter` (in progress).

/// Arguments of `sysid filter`.
#[derive(Debug, clap::Args)]
pub struct Args {}

/// Runs `sysid filter`.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("sysid filter is not available yet")
}
