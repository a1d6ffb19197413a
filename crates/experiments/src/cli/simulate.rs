//! `sysid simulate` (in progress).

/// Arguments of `sysid simulate`.
#[derive(Debug, clap::Args)]
pub struct Args {}

/// Runs `sysid simulate`.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("sysid simulate is not available yet")
}
