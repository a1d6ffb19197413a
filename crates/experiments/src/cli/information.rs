//! `sysid information`: the information limit of a linear record ([`crate::information`]) —
//! the maximum-likelihood θ̂, its error and the Cramér–Rao s.d. of every parameter, beside the
//! answers of run records on the same data; or, with `--summary`, several limits and records
//! side by side.

use std::path::PathBuf;

use crate::error::{bail, Context, Result};
use crate::field::StructureSettings;
use crate::information::{information_limit, on_data, summary, table, InformationLimit, REL_STEP};
use crate::likelihood::{Candidate, ScoredData};
use crate::record::RunRecord;
use models::dataset::{load_dir, MEASURED};

/// Arguments of `sysid information`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Data-set directory of a linear building (no hysteretic storeys).
    #[arg(long, required_unless_present = "limit")]
    pub data: Option<PathBuf>,
    /// Run records to put beside the limit (identified on these data).
    pub records: Vec<PathBuf>,
    /// Start Newton's ascent at this run record's θ_val (default: the data set's true θ).
    #[arg(long)]
    pub start: Option<PathBuf>,
    /// Filter settings of the model (as `sysid filter --config`). Default: the model
    /// `sysid filter --algorithm mpf-ekf2` builds for these data.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Central-difference step relative to each parameter's start value.
    #[arg(long, default_value_t = REL_STEP)]
    pub step: f64,
    /// Write the limit (JSON) here.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Instead of computing a limit: put this limit file (JSON written by --out; repeat the
    /// option for several data sets) beside the run records given, matched to it by data set —
    /// a summary over the data sets, then each data set's table.
    #[arg(long, conflicts_with_all = ["data", "start", "config"])]
    pub limit: Vec<PathBuf>,
    /// Also write the table to this file.
    #[arg(long)]
    pub table: Option<PathBuf>,
}

fn read_records(paths: &[PathBuf]) -> Result<Vec<RunRecord>> {
    paths.iter().map(|p| crate::sweep::read_record(p)).collect()
}

pub fn run(args: Args) -> Result<()> {
    let records = read_records(&args.records)?;
    let text = if !args.limit.is_empty() {
        let limits = args
            .limit
            .iter()
            .map(|p| {
                let text = std::fs::read_to_string(p)
                    .with_context(|| format!("reading {}", p.display()))?;
                serde_json::from_str::<InformationLimit>(&text)
                    .with_context(|| format!("{}: not an information limit", p.display()))
            })
            .collect::<Result<Vec<_>>>()?;
        let mut text = summary(&limits, &records)?;
        for l in &limits {
            let mine: Vec<RunRecord> = records.iter().filter(|r| on_data(r, l)).cloned().collect();
            text.push_str(&format!("\n### {}\n\n", l.data));
            text.push_str(&table(l, &mine)?);
        }
        text
    } else {
        let Some(dir) = &args.data else {
            bail!("--data: the data set to compute the limit of");
        };
        let data = load_dir(dir).with_context(|| format!("loading data set {}", dir.display()))?;
        let chain = data
            .true_chain()
            .context("rebuilding the data set's structure")?;
        let settings = match &args.config {
            Some(path) => Some(crate::limits::load_filter_settings(path)?),
            None => None,
        };
        let config_name = args.config.as_ref().map(|p| p.display().to_string());
        let measured = dir.join(MEASURED);
        let on = ScoredData {
            data: &data,
            chain: chain.as_ref(),
            measured: &measured,
            name: &dir.display().to_string(),
            flags: &StructureSettings::default(),
            settings,
            config: config_name.as_deref(),
        };
        let start = args
            .start
            .as_ref()
            .map(|p| Candidate::from_record(p))
            .transpose()?;
        let limit = information_limit(&on, start.as_ref(), args.step, &mut |l| eprintln!("{l}"))?;
        if let Some(out) = &args.out {
            let json = serde_json::to_string_pretty(&limit)?;
            crate::sweep::write_bytes_atomic(out, json.as_bytes())?;
        }
        table(&limit, &records)?
    };
    print!("{text}");
    if let Some(out) = &args.table {
        crate::sweep::write_bytes_atomic(out, text.as_bytes())?;
    }
    Ok(())
}
