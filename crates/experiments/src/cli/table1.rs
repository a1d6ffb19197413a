//! `sysid table1`: parses its arguments and calls [`crate::table1::write`].

use std::path::PathBuf;

/// Arguments of `sysid table1`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Output directory (created if needed).
    #[arg(long, default_value = "results/table1")]
    pub out: PathBuf,
}

/// Runs `sysid table1`.
pub fn run(args: Args, con: &mut crate::console::Console) -> crate::error::Result<()> {
    write!(con.out(), "{}", crate::table1::write(&args.out)?)?;
    Ok(())
}
