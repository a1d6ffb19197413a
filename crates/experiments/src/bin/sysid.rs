//! `sysid`: online Bayesian identification of hysteretic structures from the command line.

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(name = "sysid", version, about = "Online Bayesian identification of hysteretic structures")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    match cli.command {}
}
