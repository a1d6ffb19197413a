//! `sysid import`: build a field-data set from real per-channel recordings and a channel map
//! (`docs/import.md`).
//!
//! The library does the work ([`models::import`]); this command prints what it did — every
//! repair and warning, also recorded in `import.json` — and the `sysid filter` command that
//! runs on the result, naming what the recordings cannot say (storeys, masses, hysteretic
//! storeys).

use crate::console::Console;
use crate::error::Context;
use models::import::{self, channel_map::ChannelMap};
use std::path::PathBuf;

/// Arguments of `sysid import`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The channel map (TOML): which file and column is the ground and which each storey,
    /// units, scale, sign and the repairs allowed. See docs/import.md.
    #[arg(long)]
    pub map: PathBuf,
    /// Output directory: a new directory, or an existing data set to replace.
    #[arg(long)]
    pub out: PathBuf,
}

/// Runs `sysid import`, its text to `con`.
pub fn run(args: Args, con: &mut Console) -> crate::error::Result<()> {
    let map = ChannelMap::load(&crate::project::locate(&args.map, "channel map")?)?;
    let imported = import::import(&map)?;
    let record = imported
        .write_dir(&args.out)
        .with_context(|| format!("writing the data set {}", args.out.display()))?;
    writeln!(
        con.out(),
        "imported {} samples at dt = {} s ({:.3} Hz), {:.3} s; ground and storey{} {}",
        record.samples,
        shown(record.dt),
        1.0 / record.dt,
        (record.samples - 1) as f64 * record.dt,
        if record.sensors.len() == 1 { "" } else { "s" },
        record
            .sensors
            .iter()
            .map(|s| s.to_string())
            .collect::<Vec<_>>()
            .join(", ")
    )?;
    for c in &record.channels {
        writeln!(
            con.out(),
            "  {:<9} {} ({} samples read{})",
            c.channel,
            c.file.display(),
            c.samples,
            c.recorded_as
                .as_ref()
                .map_or(String::new(), |r| format!(", {r}"))
        )?;
    }
    if record.repairs.is_empty() {
        writeln!(con.out(), "repairs: none")?;
    } else {
        writeln!(con.out(), "repairs:")?;
        for r in &record.repairs {
            writeln!(con.out(), "  {}: {}", r.channel, r.action)?;
        }
    }
    for w in &record.warnings {
        writeln!(con.out(), "warning: {w}")?;
    }
    let out = args.out.display();
    writeln!(
        con.out(),
        "wrote {out}/measured.csv and {out}/import.json (the sources, their SHA-256 and every \
         repair)"
    )?;
    writeln!(
        con.out(),
        "{}; e.g. with unit masses (k and c per unit mass):\n  sysid filter --algorithm \
         mpf-ekf2 --data {out} --storeys {} --hysteretic none --masses 1 --measurement {} \
         --out run.json",
        record.not_recorded,
        record.sensors.iter().max().copied().unwrap_or(1),
        record.measurement
    )?;
    Ok(())
}

/// `dt` as a person reads it: the mean of a grid's time stamps carries the rounding of their sum
/// (0.02 read from a V2 grid 3..1138 is 0.020000000000000004), shown to 12 significant digits.
/// The data set keeps the value itself.
fn shown(dt: f64) -> f64 {
    format!("{dt:.11e}").parse().unwrap_or(dt)
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_step_is_shown_without_its_rounding() {
        assert_eq!(super::shown(0.020000000000000004).to_string(), "0.02");
        assert_eq!(super::shown(0.01).to_string(), "0.01");
        assert_eq!(super::shown(1.0 / 120.0).to_string(), "0.00833333333333");
    }
}
