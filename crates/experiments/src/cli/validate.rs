//! `sysid validate --record RUN.json --data OTHER [--out validation.json]`: cross-validation —
//! the model identified on one record predicts another record of the same building from its
//! ground motion alone (free run, fit and NRMSE per channel, a band from the first record's
//! posterior), and its modes are set beside the other record's transfer-function peaks
//! (docs/validation.md).

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use models::dataset::{load_dir, MEASURED, META};
use models::description::StructureDescription;

use crate::record::RunRecord;
use crate::validation::cross::CrossValidation;
use crate::validation::{self, BAND_DRAWS};

/// Arguments of `sysid validate`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Run record of the identification (written by `sysid filter`).
    #[arg(long)]
    pub record: PathBuf,
    /// Another record of the same building (a data-set directory with `measured.csv`).
    #[arg(long)]
    pub data: PathBuf,
    /// Where to write the result (JSON).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Also draw `free_run.svg` and `transfer.svg` into this directory.
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Posterior draws for the band (0: no band).
    #[arg(long, default_value_t = BAND_DRAWS)]
    pub draws: usize,
}

/// Most draws accepted.
pub const MAX_DRAWS: usize = 10_000;

/// Reads and checks a run record.
pub fn read_record(path: &Path) -> Result<RunRecord> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("reading run record {}", path.display()))?;
    let r: RunRecord = serde_json::from_str(&text)
        .with_context(|| format!("{}: not a run record", path.display()))?;
    r.check()
        .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    Ok(r)
}

/// Refuses another record whose building differs from the identified one; returns notes on
/// what is assumed of it.
pub fn check_same_building(
    d: &StructureDescription,
    data: &models::dataset::LoadedDataset,
    dir: &Path,
) -> Result<Vec<String>> {
    let mut notes = Vec::new();
    match &data.meta {
        Some(meta) => {
            let other = meta
                .structure()
                .with_context(|| format!("{}", dir.join(META).display()))?;
            let mut diffs = Vec::new();
            if other.storeys != d.storeys {
                diffs.push(format!("storeys {} against {}", other.storeys, d.storeys));
            }
            if other.masses != d.masses {
                diffs.push(format!("masses {:?} against {:?}", other.masses, d.masses));
            }
            if other.hysteretic != d.hysteretic {
                diffs.push(format!(
                    "hysteretic storeys {:?} against {:?}",
                    other.hysteretic, d.hysteretic
                ));
            }
            if other.measurement != d.measurement {
                diffs.push(format!(
                    "measurement {} against {}",
                    other.measurement, d.measurement
                ));
            }
            if !diffs.is_empty() {
                bail!(
                    "{} describes another building than the record's: {} — cross-validation \
                     predicts a record of the same building",
                    dir.join(META).display(),
                    diffs.join(", ")
                );
            }
        }
        None => notes.push(format!(
            "{} has no {META}: taken to be a record of the identified building ({} storeys, \
             {} accelerations)",
            dir.display(),
            d.storeys,
            d.measurement
        )),
    }
    if let Some(&s) = data.sensors.iter().find(|&&s| s > d.storeys) {
        bail!(
            "{}: column a{s}: the identified building has only {} storeys",
            dir.join(MEASURED).display(),
            d.storeys
        );
    }
    if data.sensors != d.sensors {
        notes.push(format!(
            "measured storeys {:?} (the identification used {:?})",
            data.sensors, d.sensors
        ));
    }
    Ok(notes)
}

/// Runs `sysid validate`.
pub fn run(args: Args) -> Result<()> {
    if args.draws > MAX_DRAWS || args.draws == 1 {
        bail!(
            "--draws {}: give 0 (no band) or 2 to {MAX_DRAWS}",
            args.draws
        );
    }
    let record = read_record(&args.record)?;
    validation::check_identified(&record).with_context(|| format!("{}", args.record.display()))?;
    let d = validation::description_of(&record)
        .with_context(|| format!("{}", args.record.display()))?;
    let data = load_dir(&args.data)
        .with_context(|| format!("loading data set {}", args.data.display()))?;
    let notes = check_same_building(&d, &data, &args.data)?;
    for n in &notes {
        eprintln!("note: {n}");
    }
    let posterior = if args.draws == 0 {
        None
    } else {
        match validation::posterior_of(&record) {
            Ok(q) => Some(q),
            Err(e) => {
                eprintln!("note: no band: {e}");
                None
            }
        }
    };
    let q = posterior.as_ref().map(|q| (q, record.seed, record.run));
    let free = validation::free_run(&d, &data, &record.theta_val, q, args.draws)
        .with_context(|| format!("the free run on {}", args.data.display()))?;
    let modal = validation::modal(&d, &data, &record.theta_val);
    println!(
        "cross-validation: {} ({}, seed {}) identified on {}, predicting {}",
        record.algorithm,
        record.experiment,
        record.seed,
        args.record.display(),
        args.data.display()
    );
    print!("{}", validation::summary(Some(&free), Some(&modal)));
    let result = CrossValidation {
        record: args.record.display().to_string(),
        data: args.data.display().to_string(),
        algorithm: record.algorithm.clone(),
        seed: record.seed,
        run: record.run,
        structure: d,
        param_names: record.param_names.clone(),
        theta_val: record.theta_val.clone(),
        free_run: free,
        modal,
        notes,
    };
    if let Some(out) = &args.out {
        crate::sweep::write_atomic(out, &result)?;
        eprintln!("result written to {}", out.display());
    }
    if let Some(dir) = &args.plot {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        let (mut written, mut skipped) = (Vec::new(), Vec::new());
        let who = format!("{} on {}", record.algorithm, args.data.display());
        validation::figures::draw(
            Some(&result.free_run),
            Some(&result.modal),
            dir,
            &who,
            &mut written,
            &mut skipped,
        )?;
        for s in skipped {
            eprintln!("note: {s}");
        }
        for w in written {
            println!("{}", w.display());
        }
    }
    Ok(())
}
