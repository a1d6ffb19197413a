//! `sysid table1` (in progress).

/// Arguments of `sysid table1`.
#[derive(Debug, clap::Args)]
pub struct Args {}

/// Runs `sysid table1`.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("sysid table1 is not available yet")
}
