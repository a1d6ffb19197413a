//! Subcommands of `sysid`, one module each. Each module exposes `Args` (clap) and `run`.
