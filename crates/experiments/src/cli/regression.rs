//! `sysid regression` (in progress).

/// Arguments of `sysid regression`.
#[derive(Debug, clap::Args)]
pub struct Args {}

/// Runs `sysid regression`.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("sysid regression is not available yet")
}
