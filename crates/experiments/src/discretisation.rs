//! Beyond the paper: the discretisation study (`experiments/discretisation.toml` at the paper's
//! dt = 0.005 s and `experiments/discretisation-100hz.toml` at dt = 0.01 s; derivation and
//! mechanism check in `docs/discretisation.md`). The marginalised filters run with forward Euler
//! (the paper's, SPEC §3) and with semi-implicit (symplectic) Euler on the same data sets; this
//! module takes over the Fig. 7 sweep's Euler records where they are the same jobs, and (in the
//! report) compares the schemes run by run.

use std::collections::{BTreeMap, HashMap};
use std::sync::atomic::{AtomicUsize, Ordering};

use anyhow::Result;
use models::filtering::Discretisation;

use crate::pipeline::Algorithm;
use crate::record::RunRecord;
use crate::reproduce::{algorithm_stats, AlgorithmStats};
use crate::study::{Job, Study};

/// The studies of the discretisation section, in the order they run (after the paper's).
pub const STUDIES: [&str; 2] = ["discretisation", "discretisation-100hz"];

/// The sweep whose records the Euler arm may take over (same data sets, same settings).
pub const SOURCE: &str = "fig7";

/// The scheme a record was computed with (its configuration's `filter.discretisation`).
pub fn scheme(r: &RunRecord) -> Option<Discretisation> {
    r.config
        .get("filter")?
        .get("discretisation")
        .and_then(|v| serde_json::from_value(v.clone()).ok())
}

/// Records of an earlier sweep of the same reproduction that a job may take over: only when the
/// record's fingerprint (data, settings, seed, run, algorithm, numerics version) is the job's,
/// i.e. when computing the job again would give the same record.
#[derive(Debug, Default)]
pub struct Reuse {
    by_fingerprint: HashMap<String, RunRecord>,
    taken: AtomicUsize,
}

impl Reuse {
    /// The completed and failed records alike (a failure is the job's result too).
    pub fn new<'a>(records: impl IntoIterator<Item = &'a RunRecord>) -> Self {
        Self {
            by_fingerprint: records
                .into_iter()
                .filter_map(|r| Some((r.fingerprint.as_ref()?.sha256.clone(), r.clone())))
                .collect(),
            taken: AtomicUsize::new(0),
        }
    }

    /// The job's record: taken over (relabelled with `study`'s name) when an earlier record has
    /// the job's fingerprint, computed otherwise.
    pub fn run(&self, study: &Study, job: &Job) -> Result<RunRecord> {
        if !self.by_fingerprint.is_empty() {
            if let Some(r) = self.by_fingerprint.get(&study.job_fingerprint(job)?) {
                self.taken.fetch_add(1, Ordering::Relaxed);
                let mut r = r.clone();
                r.experiment.clone_from(&study.name);
                return Ok(r);
            }
        }
        study.run_job(job)
    }

    /// How many records were taken over.
    pub fn taken(&self) -> usize {
        self.taken.load(Ordering::Relaxed)
    }
}

/// The algorithms of the study, in the report's order.
pub const ALGORITHMS: [Algorithm; 3] = [Algorithm::MlnRbpf, Algorithm::Storvik, Algorithm::MpfEkf2];

/// The schemes compared.
pub const SCHEMES: [Discretisation; 2] = [Discretisation::Euler, Discretisation::Symplectic];

/// The records of one study, algorithm and scheme.
pub fn arm<'a>(
    records: &'a [RunRecord],
    algorithm: Algorithm,
    d: Discretisation,
) -> Vec<&'a RunRecord> {
    records
        .iter()
        .filter(|r| r.algorithm == algorithm.name() && scheme(r) == Some(d))
        .collect()
}

/// Statistics per study, algorithm and scheme (`summary.json`), labelled `<algorithm>/<scheme>`.
pub fn summary(
    records: &BTreeMap<&'static str, Vec<RunRecord>>,
) -> Vec<(&'static str, Vec<AlgorithmStats>)> {
    STUDIES
        .iter()
        .filter_map(|name| Some((*name, records.get(name)?)))
        .map(|(name, recs)| {
            let stats = ALGORITHMS
                .iter()
                .flat_map(|a| SCHEMES.iter().map(move |d| (a, d)))
                .map(|(a, d)| {
                    algorithm_stats(&format!("{}/{}", a.name(), d.name()), &arm(recs, *a, *d))
                })
                .collect();
            (name, stats)
        })
        .collect()
}
