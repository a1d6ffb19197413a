//! `sysid simulate`: simulate a structure under an excitation and write a data-set directory
//! (`measured.csv`, `truth.csv`, `dataset.json`; SPEC §2).
//!
//! Every flag is checked against `models::limits` before anything is generated, and the
//! directory is written under a temporary name and swapped into place
//! ([`models::dataset::Dataset::write_dir`]): an interrupted `simulate` leaves the previous data
//! set or the new one, never a mix.

use crate::error::Context;
use models::dataset;
use models::readers::Units;
use std::path::PathBuf;

use identify::simulation::{dataset_config, SimulationRequest};

/// Units of a CSV excitation record.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum UnitsArg {
    /// Multiples of g = 9.81 m/s².
    G,
    /// m/s².
    #[value(name = "m/s2")]
    Ms2,
}

/// Arguments of `sysid simulate`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Structure preset: paper-3dof, paper-3dof-harmonic, shear-chain (the paper's storey values, any --storeys) or building-chain (k = 2000 per storey, the scaling study's buildings: docs/scaling.md)
    #[arg(long, default_value = "paper-3dof")]
    pub preset: String,
    /// Master seed of the random streams.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Run index (selects independent noise streams for the same seed).
    #[arg(long, default_value_t = 0)]
    pub run: u64,
    /// Output directory: a new directory, or an existing data set to replace.
    #[arg(long)]
    pub out: PathBuf,
    /// Excitation: elcentro, kanai-tajimi, harmonic, a vendored real record by name
    /// (el-centro-1940, loma-prieta-1989, … : see data/ground_motions/PROVENANCE.md), or a path to
    /// a `.csv` (`t,acc`) or `.AT2` record. Default: the preset's own.
    #[arg(long)]
    pub excitation: Option<String>,
    /// Units of a CSV record.
    #[arg(long, value_enum, default_value = "g")]
    pub units: UnitsArg,
    /// Amplitude scale (default: 3.0 for El Centro and Kanai–Tajimi, 1.0 otherwise).
    #[arg(long)]
    pub scale: Option<f64>,
    /// Duration in seconds (default: the whole record, 31.18 s for synthetic inputs).
    #[arg(long)]
    pub duration: Option<f64>,
    /// Number of storeys (same per-storey values as the preset).
    #[arg(long)]
    pub storeys: Option<usize>,
    /// Storeys with a Bouc–Wen element, 1-based and increasing, e.g. `1,4` (each with the
    /// preset's β = 2, γ = 1, n = 2), or `none` for a linear building. Default: storey 1.
    #[arg(long)]
    pub hysteretic: Option<String>,
    /// Measured storeys, 1-based and increasing, e.g. `1,3,5`. Default: every storey.
    #[arg(long)]
    pub sensors: Option<String>,
    /// Measure absolute accelerations ẍ + ü_g instead of relative ones.
    #[arg(long)]
    pub absolute: bool,
    /// Noise s.d. as a fraction of each clean signal's RMS.
    #[arg(long, default_value_t = 0.1)]
    pub noise_fraction: f64,
}

impl Args {
    /// The simulation the flags describe (everything but `--out`).
    pub fn request(&self) -> SimulationRequest {
        SimulationRequest {
            preset: self.preset.clone(),
            seed: self.seed,
            run: self.run,
            excitation: self.excitation.clone(),
            units: match self.units {
                UnitsArg::G => Units::G,
                UnitsArg::Ms2 => Units::MetersPerSecond2,
            },
            scale: self.scale,
            duration: self.duration,
            storeys: self.storeys,
            hysteretic: self.hysteretic.clone(),
            sensors: self.sensors.clone(),
            absolute: self.absolute,
            noise_fraction: self.noise_fraction,
        }
    }
}

/// Runs `sysid simulate`.
pub fn run(args: Args, con: &mut crate::console::Console) -> crate::error::Result<()> {
    let config = dataset_config(&args.request())?;
    let ds = dataset::generate(&config)?;
    ds.write_dir(&args.out)
        .with_context(|| format!("writing the data set to {}", args.out.display()))?;
    let meta = ds.meta();
    let r_summary: Vec<String> = meta
        .max_abs_r
        .iter()
        .zip(&meta.saturation)
        .zip(&meta.bouc_wen_storeys)
        .map(|((m, s), st)| match s {
            Some(s) => format!("max|r{}|/sat = {:.3}", st + 1, m / s),
            None => format!("max|r{}| = {:.4}", st + 1, m),
        })
        .collect();
    let acc: Vec<String> = ds
        .sensors
        .channel_names()
        .iter()
        .zip(&ds.rms.acc)
        .map(|(c, a)| format!("{c} {a:.4}"))
        .collect();
    writeln!(
        con.out(),
        "{}: {} storeys, {} accelerations at storeys {:?}; {} samples, dt = {} s, {:.2} s; {}; \
         RMS ug = {:.4}, acc = [{}] m/s²",
        args.out.display(),
        ds.chain.storeys(),
        ds.sensors.kind(),
        ds.sensors.one_based(),
        ds.len(),
        ds.dt,
        ds.t.last().copied().unwrap_or(0.0),
        if r_summary.is_empty() {
            "linear (no Bouc–Wen element)".to_string()
        } else {
            r_summary.join(", ")
        },
        ds.rms.ug,
        acc.join(", ")
    )?;
    Ok(())
}
