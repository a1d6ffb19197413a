//! Experiment configs (one TOML per figure or study in `experiments/`) and their expansion into
//! jobs: structure × algorithm × particles × resampling × discretisation × run (the structure
//! axis is optional: without it every job uses the data section's structure). Every job
//! regenerates its data set from
//! `(master_seed, run)`, so all algorithms of one run see the identical data set. A job's
//! fingerprint ([`Study::job_fingerprint`]) is the one its record will carry, so a resumed sweep
//! can tell whether an existing record is this job's result.

use std::collections::BTreeMap;
use std::path::Path;

use crate::error::{bail, invalid, Context, Result};
use core_filters::resampling::Scheme;
use models::dataset::{generate, DatasetConfig, LoadedDataset};
use models::filtering::Discretisation;
use models::structure::ShearChain;
use serde::{Deserialize, Serialize};

use crate::verdict::Declared;
use identify::pipeline::{identify, Algorithm, FilterSettings, RunInput};
use identify::record::{Fingerprint, RunRecord};

/// The data of a study.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DataSection {
    /// Preset name (`paper-3dof`, `paper-3dof-harmonic`, `shear-chain`): every run generates its
    /// own data set from `(master_seed, run)`. Empty when `dir` is given.
    #[serde(default)]
    pub preset: String,
    /// A data-set directory (a user's record, `measured.csv` with or without `dataset.json`;
    /// relative paths are taken from the directory of the study file) instead of a preset: every
    /// run filters the same data with its own filter streams, so the runs measure the
    /// Monte-Carlo spread of one identification on that record.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dir: Option<std::path::PathBuf>,
    pub storeys: Option<usize>,
    /// Amplitude scale (default: the preset's).
    pub scale: Option<f64>,
    /// Duration (s) (default: the whole record).
    pub duration: Option<f64>,
    /// Keep one sample in `decimate` of the generated data (a lower-rate logger; see
    /// [`crate::decimate`]); absent: every sample.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub decimate: Option<usize>,
}

/// The sweep axes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SweepSection {
    pub algorithms: Vec<Algorithm>,
    /// Runs 0..runs (each its own data set and filter streams).
    pub runs: u64,
    pub master_seed: u64,
    #[serde(default = "default_particles")]
    pub particles: Vec<usize>,
    #[serde(default = "default_resampling")]
    pub resampling: Vec<Scheme>,
    /// The structure axis (`[[sweep.structures]]`); empty: the data section's structure only.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub structures: Vec<Structure>,
    /// Discretisations of the filters' equations of motion (`docs/discretisation.md`); absent:
    /// the `[filter]` table's (forward Euler unless set).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub discretisations: Option<Vec<Discretisation>>,
}

/// One structure of the structure axis: a shear chain of the data section's preset with its own
/// storey count, hysteretic storeys, sensors, record length, algorithms and runs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Structure {
    /// Name in record ids and reports (letters, digits and `-`).
    pub label: String,
    pub storeys: usize,
    /// 1-based storeys with a Bouc–Wen element; absent: the preset's (storey 1).
    pub hysteretic: Option<Vec<usize>>,
    /// 1-based measured storeys; absent: every storey.
    pub sensors: Option<Vec<usize>>,
    /// Duration of the data (s); absent: the data section's.
    pub duration: Option<f64>,
    /// Amplitude scale of the excitation; absent: the data section's (or the preset's).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scale: Option<f64>,
    /// A vendored real ground motion by name (`models::ground_motions`, e.g.
    /// `loma-prieta-1989`) instead of the preset's excitation; absent: the preset's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub excitation: Option<String>,
    /// Algorithms run on this structure (a subset of the sweep's); absent: the sweep's.
    pub algorithms: Option<Vec<Algorithm>>,
    /// Runs 0..runs on this structure (at most the sweep's); absent: the sweep's.
    pub runs: Option<u64>,
    /// Keys of `[filter]` this structure's runs take differently (`filter = { … }`), laid over
    /// the study's settings and its algorithm's `filter_for` keys: settings that depend on the
    /// building, such as the MPF-EKF2's per-particle prior from ten storeys on.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub filter: Option<toml::Table>,
}

impl Structure {
    /// Why this build cannot generate the structure's data, if it cannot. Every structure of
    /// the axis is supported (the data configuration takes hysteretic storeys and a sensor
    /// layout); kept so that a future structure field that a build lacks is named, not ignored.
    pub(crate) fn unsupported(&self) -> Option<String> {
        None
    }

    fn check(&self, sweep: &SweepSection) -> Result<()> {
        let ctx = || format!("structure `{}` of `sweep.structures`", self.label);
        if self.label.is_empty()
            || !self
                .label
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '-')
        {
            bail!("{}: the label must be letters, digits and `-`", ctx());
        }
        identify::limits::check_count(self.storeys, 1, models::limits::MAX_STOREYS)
            .with_context(|| format!("{}: field `storeys`", ctx()))?;
        for (field, list) in [("hysteretic", &self.hysteretic), ("sensors", &self.sensors)] {
            if let Some(list) = list {
                if list.is_empty() {
                    bail!("{}: field `{field}` is empty", ctx());
                }
                if let Some(s) = list.iter().find(|&&s| s == 0 || s > self.storeys) {
                    bail!(
                        "{}: field `{field}`: storey {s} is not in 1..={}",
                        ctx(),
                        self.storeys
                    );
                }
                let mut sorted = list.clone();
                sorted.sort_unstable();
                sorted.dedup();
                if sorted.len() != list.len() {
                    bail!("{}: field `{field}` repeats a storey", ctx());
                }
            }
        }
        if let Some(d) = self.duration {
            if !(d.is_finite() && d > 0.0) {
                bail!("{}: field `duration` must be positive, got {d}", ctx());
            }
        }
        if let Some(name) = &self.excitation {
            if models::ground_motions::by_name(name).is_none() {
                bail!(
                    "{}: field `excitation`: no vendored record is named `{name}`; the records \
                     are: {}",
                    ctx(),
                    models::ground_motions::names().join(", ")
                );
            }
        }
        if let Some(a) = self.scale {
            if !(a.is_finite() && a > 0.0 && a <= models::limits::MAX_ABS_SCALE) {
                bail!(
                    "{}: field `scale` must be a positive number, got {a}",
                    ctx()
                );
            }
        }
        if let Some(algs) = &self.algorithms {
            if let Some(a) = algs.iter().find(|a| !sweep.algorithms.contains(a)) {
                bail!(
                    "{}: algorithm `{}` is not one of the sweep's algorithms",
                    ctx(),
                    a.name()
                );
            }
        }
        if let Some(r) = self.runs {
            if r == 0 || r > sweep.runs {
                bail!("{}: field `runs` must be in 1..={}", ctx(), sweep.runs);
            }
        }
        Ok(())
    }
}

/// `settings` with `keys` (a table of `[filter]` keys) laid over them; an unknown key or a value
/// of the wrong type is an error, and so is a key every job sets from the sweep's axes (it would
/// be overwritten without a word).
fn laid_over(settings: &FilterSettings, keys: &toml::Table) -> Result<FilterSettings> {
    for (key, axis) in [
        ("particles", "sweep.particles"),
        ("resampling", "sweep.resampling"),
        ("discretisation", "sweep.discretisations"),
    ] {
        if keys.contains_key(key) {
            bail!("`{key}` is set for every job by `{axis}` (or `[filter]`), not here");
        }
    }
    let mut table = toml::Table::try_from(settings)
        .map_err(|e| invalid!("the filter settings as a table: {e}"))?;
    for (k, v) in keys {
        table.insert(k.clone(), v.clone());
    }
    table.try_into().map_err(|e| invalid!("{e}"))
}

fn default_particles() -> Vec<usize> {
    vec![500]
}
fn default_resampling() -> Vec<Scheme> {
    vec![Scheme::Systematic]
}

/// A reduced form for a fast look (`--quick`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct QuickSection {
    pub runs: u64,
    pub particles: usize,
    /// Duration of the data (s) in quick mode.
    pub duration: Option<f64>,
}

/// Most runs a study may have (a sweep's records are kept in one directory).
pub(crate) const MAX_RUNS: usize = 100_000;

/// One study (`experiments/<name>.toml`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Study {
    pub name: String,
    pub description: String,
    pub data: DataSection,
    pub sweep: SweepSection,
    #[serde(default)]
    pub filter: FilterSettings,
    /// Keys of `filter` that one algorithm takes differently (`[filter_for.mpf-ekf2]`, e.g. the
    /// MPF-EKF2's own defaults), laid over `filter` for that algorithm's runs only.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub filter_for: BTreeMap<String, toml::Table>,
    pub quick: Option<QuickSection>,
    /// The statements the study's report decides (`[[verdicts]]`, see
    /// [`crate::verdict::declared`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub verdicts: Vec<Declared>,
}

/// One run of a study.
#[derive(Debug, Clone, PartialEq)]
pub struct Job {
    /// Index into the sweep's structures (`None`: no structure axis).
    pub structure: Option<usize>,
    pub algorithm: Algorithm,
    pub particles: usize,
    pub resampling: Scheme,
    pub discretisation: Discretisation,
    pub run: u64,
}

impl Study {
    /// Reads and checks a study file; errors name the file.
    pub fn load(path: &Path) -> Result<Self> {
        let text = identify::limits::read_text_file(path, "study")?;
        let mut s: Study = identify::limits::parse_toml(&text, path, "study")?;
        if let Some(dir) = &s.data.dir {
            if dir.is_relative() {
                let base = path.parent().unwrap_or_else(|| Path::new("."));
                s.data.dir = Some(base.join(dir));
            }
        }
        s.check()
            .with_context(|| format!("study {}", path.display()))?;
        Ok(s)
    }

    /// Names of θ of the structure every run of a study on one simulated structure identifies
    /// (run 0's; the generated structures of one study differ only in their data). A study on a
    /// data directory, or with more than one structure on its axis, has no single list.
    pub fn param_names(&self) -> Result<Vec<String>> {
        if self.data.dir.is_some() {
            bail!(
                "a study on a data directory: its parameters are those of the directory's building"
            );
        }
        let structure = match self.sweep.structures.len() {
            0 => None,
            1 => Some(0),
            n => bail!(
                "{n} structures on the axis `sweep.structures`: one list of parameters needs one"
            ),
        };
        Ok(self.structure_config(structure, 0)?.chain()?.theta_names())
    }

    fn check(&self) -> Result<()> {
        self.check_sweep_counts()?;
        self.check_filter_tables()?;
        if self
            .sweep
            .discretisations
            .as_ref()
            .is_some_and(Vec::is_empty)
        {
            bail!("field `sweep.discretisations`: give at least one discretisation");
        }
        if let Some(f) = self.data.decimate {
            crate::decimate::check_factor(f).context("field `data.decimate`")?;
        }
        self.check_data()?;
        self.check_verdicts()?;
        self.check_structures()
    }

    /// The sweep has an algorithm, a run, and counts of particles and runs within the limits.
    fn check_sweep_counts(&self) -> Result<()> {
        if self.sweep.algorithms.is_empty() || self.sweep.runs == 0 {
            bail!("the sweep needs at least one algorithm and one run");
        }
        if self.sweep.particles.contains(&0) {
            bail!("particles must be at least 1");
        }
        for &p in &self.sweep.particles {
            identify::limits::check_count(p, 1, identify::limits::MAX_PARTICLES)
                .context("field `sweep.particles`")?;
        }
        identify::limits::check_count(self.sweep.runs as usize, 1, MAX_RUNS)
            .context("field `sweep.runs`")?;
        Ok(())
    }

    /// Every filter setting a run can take is valid: the `[filter]` table, each algorithm's
    /// `[filter_for.*]` table, and each structure's own `filter` keys for each of its algorithms.
    fn check_filter_tables(&self) -> Result<()> {
        identify::limits::check_filter_settings(&self.filter).context("table `filter`")?;
        for name in self.filter_for.keys() {
            let algorithm: Algorithm = name
                .parse()
                .map_err(|e: String| invalid!("table `filter_for.{name}`: {e}"))?;
            let settings = self
                .filter_of(algorithm)
                .with_context(|| format!("table `filter_for.{name}`"))?;
            identify::limits::check_filter_settings(&settings)
                .with_context(|| format!("table `filter_for.{name}`"))?;
        }
        for (i, st) in self.sweep.structures.iter().enumerate() {
            if st.filter.is_none() {
                continue;
            }
            let algorithms = st.algorithms.as_ref().unwrap_or(&self.sweep.algorithms);
            for &algorithm in algorithms {
                let ctx = || {
                    format!(
                        "structure `{}` of `sweep.structures`: field `filter` ({})",
                        st.label,
                        algorithm.name()
                    )
                };
                let settings = self
                    .filter_for_structure(Some(i), algorithm)
                    .with_context(ctx)?;
                identify::limits::check_filter_settings(&settings).with_context(ctx)?;
            }
        }
        Ok(())
    }

    /// The `[data]` table names one source: a preset whose generated data set is valid, or a
    /// data directory that loads (without the keys of generated data or a structure axis).
    fn check_data(&self) -> Result<()> {
        match (&self.data.dir, self.data.preset.is_empty()) {
            (Some(_), false) => {
                bail!("table `data`: give either `preset` or `dir`, not both")
            }
            (None, true) => bail!(
                "table `data`: give `preset` (a simulated structure) or `dir` (a data-set directory)"
            ),
            (Some(dir), true) => {
                if self.data.storeys.is_some()
                    || self.data.scale.is_some()
                    || self.data.duration.is_some()
                {
                    bail!(
                        "table `data`: `storeys`, `scale` and `duration` describe generated data; \
                         with `dir` the data set is {} as it is",
                        dir.display()
                    );
                }
                if !self.sweep.structures.is_empty() {
                    bail!("a study on a data directory has no structure axis (`sweep.structures`)");
                }
                models::dataset::load_dir(dir)
                    .with_context(|| format!("table `data`: field `dir` ({})", dir.display()))?;
            }
            (None, false) => {
                models::dataset::check_config(&self.dataset_config(0)?)
                    .context("table `data`")?;
            }
        }
        Ok(())
    }

    /// The declared verdicts can be decided: one particle count and one resampling scheme (runs
    /// are compared run by run), and each statement names what the sweep runs.
    fn check_verdicts(&self) -> Result<()> {
        if !self.verdicts.is_empty()
            && (self.sweep.particles.len() > 1 || self.sweep.resampling.len() > 1)
        {
            bail!(
                "table `verdicts`: a verdict compares the algorithms run by run, so the sweep may \
                 have one particle count and one resampling scheme; it has {} and {}",
                self.sweep.particles.len(),
                self.sweep.resampling.len()
            );
        }
        let algorithms: Vec<&str> = self.sweep.algorithms.iter().map(|a| a.name()).collect();
        for v in &self.verdicts {
            v.check(&algorithms, &self.discretisations())?;
        }
        Ok(())
    }

    /// Each structure of the axis is valid, its label is unique, and the data set it
    /// generates (when the toolkit can run it) is valid.
    fn check_structures(&self) -> Result<()> {
        let mut labels = std::collections::BTreeSet::new();
        for (i, st) in self.sweep.structures.iter().enumerate() {
            st.check(&self.sweep)?;
            if !labels.insert(st.label.as_str()) {
                bail!(
                    "structure label `{}` appears twice in `sweep.structures`",
                    st.label
                );
            }
            if st.unsupported().is_none() {
                models::dataset::check_config(&self.structure_config(Some(i), 0)?)
                    .with_context(|| format!("structure `{}`", st.label))?;
            }
        }
        Ok(())
    }

    /// The study in `--quick` form (fewer runs and particles, shorter data if configured).
    pub fn quick(&self) -> Self {
        let mut s = self.clone();
        if let Some(q) = self.quick {
            s.sweep.runs = s.sweep.runs.min(q.runs);
            s.sweep.particles = vec![q.particles];
            if q.duration.is_some() {
                s.data.duration = q.duration;
            }
            for st in &mut s.sweep.structures {
                st.runs = Some(st.runs.unwrap_or(q.runs).min(q.runs));
                if let Some(d) = q.duration {
                    st.duration = Some(st.duration.map_or(d, |own| own.min(d)));
                }
            }
        }
        s
    }

    /// The jobs, in a fixed order (algorithm-major within each run, so that a partial sweep
    /// has complete runs first).
    /// With a structure axis, every structure's run `r` comes before any run `r + 1`.
    pub fn jobs(&self) -> Vec<Job> {
        let structures: Vec<Option<usize>> = if self.sweep.structures.is_empty() {
            vec![None]
        } else {
            (0..self.sweep.structures.len()).map(Some).collect()
        };
        let mut out = Vec::new();
        for run in 0..self.sweep.runs {
            for &structure in &structures {
                let st = structure.map(|i| &self.sweep.structures[i]);
                if st.and_then(|s| s.runs).is_some_and(|r| run >= r) {
                    continue;
                }
                let algorithms = st
                    .and_then(|s| s.algorithms.as_ref())
                    .unwrap_or(&self.sweep.algorithms);
                for &particles in &self.sweep.particles {
                    for &resampling in &self.sweep.resampling {
                        for &discretisation in &self.discretisations() {
                            for &algorithm in algorithms {
                                out.push(Job {
                                    structure,
                                    algorithm,
                                    particles,
                                    resampling,
                                    discretisation,
                                    run,
                                });
                            }
                        }
                    }
                }
            }
        }
        out
    }

    /// The discretisations of the sweep (the `[filter]` table's when the sweep names none).
    pub fn discretisations(&self) -> Vec<Discretisation> {
        self.sweep
            .discretisations
            .clone()
            .unwrap_or_else(|| vec![self.filter.discretisation])
    }

    /// File stem of a job's record (forward Euler, the paper's, carries no suffix).
    pub fn job_id(job: &Job) -> String {
        let scheme = match job.discretisation {
            Discretisation::Euler => String::new(),
            d => format!("-{}", d.name()),
        };
        format!(
            "{}-np{}-{}{scheme}-run{:03}",
            job.algorithm.name(),
            job.particles,
            job.resampling.name(),
            job.run
        )
    }

    /// File stem of a job's record, prefixed by its structure's label when the study has a
    /// structure axis.
    pub fn record_id(&self, job: &Job) -> String {
        match job.structure {
            Some(i) => format!("{}-{}", self.sweep.structures[i].label, Self::job_id(job)),
            None => Self::job_id(job),
        }
    }

    /// The data-set configuration of run `run` on structure `structure` (an index into the
    /// sweep's structures; `None`: the data section's).
    pub fn structure_config(&self, structure: Option<usize>, run: u64) -> Result<DatasetConfig> {
        let mut c = self.dataset_config(run)?;
        if let Some(i) = structure {
            let st = &self.sweep.structures[i];
            if let Some(why) = st.unsupported() {
                bail!("{why}");
            }
            c.storeys = Some(st.storeys);
            c.hysteretic = st.hysteretic.clone();
            c.sensors = st.sensors.clone();
            if st.duration.is_some() {
                c.duration = st.duration;
            }
            if let Some(a) = st.scale {
                c.scale = a;
            }
            if let Some(name) = &st.excitation {
                c.excitation = models::dataset::ExcitationSource::Named { name: name.clone() };
            }
        }
        Ok(c)
    }

    /// The data-set configuration of run `run`.
    pub fn dataset_config(&self, run: u64) -> Result<DatasetConfig> {
        let mut c = DatasetConfig::from_preset(&self.data.preset, self.sweep.master_seed)?;
        c.storeys = self.data.storeys;
        if let Some(s) = self.data.scale {
            c.scale = s;
        }
        if self.data.duration.is_some() {
            c.duration = self.data.duration;
        }
        c.run = run;
        Ok(c)
    }

    /// The filter settings of a job: the study's (with its algorithm's `filter_for` keys and its
    /// structure's `filter` keys), with
    /// the job's particles, resampling and discretisation. An error only for a `filter_for` or
    /// structure `filter` table that does not apply (refused already by [`Study::load`]).
    pub fn settings(&self, job: &Job) -> Result<FilterSettings> {
        let mut settings = self.filter_for_structure(job.structure, job.algorithm)?;
        settings.particles = job.particles;
        settings.resampling = job.resampling;
        settings.discretisation = job.discretisation;
        Ok(settings)
    }

    /// The filter settings of `algorithm`'s runs on structure `structure` (an index into the
    /// sweep's structures; `None`: no structure axis): [`Study::filter_of`] with the structure's
    /// `filter` keys laid over it.
    pub(crate) fn filter_for_structure(
        &self,
        structure: Option<usize>,
        algorithm: Algorithm,
    ) -> Result<FilterSettings> {
        let settings = self.filter_of(algorithm)?;
        match structure.and_then(|i| self.sweep.structures[i].filter.as_ref()) {
            Some(keys) => laid_over(&settings, keys),
            None => Ok(settings),
        }
    }

    /// The study's filter settings for `algorithm`: `filter` with the keys of
    /// `filter_for.<algorithm>` laid over it.
    pub fn filter_of(&self, algorithm: Algorithm) -> Result<FilterSettings> {
        match self.filter_for.get(algorithm.name()) {
            Some(keys) => laid_over(&self.filter, keys)
                .with_context(|| format!("table `filter_for.{}`", algorithm.name())),
            None => Ok(self.filter.clone()),
        }
    }

    /// The data set of run `run` as the filters see it (decimated when the study says so), with
    /// its true structure.
    pub fn data(
        &self,
        structure: Option<usize>,
        run: u64,
    ) -> Result<(LoadedDataset, Option<ShearChain>)> {
        let factor = self.data.decimate.unwrap_or(1);
        if let Some(dir) = &self.data.dir {
            let loaded = models::dataset::load_dir(dir)
                .with_context(|| format!("loading data set {}", dir.display()))?;
            let chain = loaded
                .true_chain()
                .with_context(|| format!("the structure of {}", dir.display()))?;
            let loaded =
                crate::decimate::decimate(&loaded, factor).context("field `data.decimate`")?;
            return Ok((loaded, chain));
        }
        let data = generate(&self.structure_config(structure, run)?)?;
        let loaded = crate::decimate::decimate(&data.to_loaded(), factor)
            .context("field `data.decimate`")?;
        Ok((loaded, Some(data.chain)))
    }

    /// The fingerprint (SHA-256, hex) the record of `job` carries when computed by this build:
    /// the job's data set is generated (a few milliseconds) and hashed with the settings, seed,
    /// run, algorithm and numerics version.
    pub fn job_fingerprint(&self, job: &Job) -> Result<String> {
        let (data, _) = self.data(job.structure, job.run)?;
        Ok(Fingerprint::of_run(
            job.algorithm.name(),
            self.sweep.master_seed,
            job.run,
            &self.settings(job)?,
            &data,
        )
        .sha256)
    }

    /// Runs one job: generate the run's data set, identify, return the record. Errors are
    /// configuration errors; numerical failures are inside the record.
    pub fn run_job(&self, job: &Job) -> Result<RunRecord> {
        let (loaded, chain) = self.data(job.structure, job.run)?;
        let input = RunInput {
            data: &loaded,
            chain: chain.as_ref(),
            experiment: &self.name,
            seed: self.sweep.master_seed,
            run: job.run,
            progress: None,
            residuals: false,
        };
        identify(&input, job.algorithm, &self.settings(job)?)
    }
}
