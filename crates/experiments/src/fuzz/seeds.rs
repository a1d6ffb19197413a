//! The valid inputs the probes start from, made once per run by `sysid` itself (so they are
//! what the program writes and reads today) and kept in memory: small data sets, run records,
//! a plan, a reference posterior and an information limit, filter and study files, excitation
//! records, channel maps with excerpts of the real recordings, sharded study outputs, a
//! cluster submission and a finished field study. Every workload is small: 0.5 s of record,
//! 20 particles, one or two runs.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use crate::error::{bail, Context, Result};

use super::probe::ROOT;

/// The seed files, by their path in the seed directory (with [`ROOT`] for the directory).
pub(crate) struct Seeds {
    files: BTreeMap<String, Vec<u8>>,
    /// Stand-ins for Slurm's `sbatch`, `squeue` and `scancel`, first on every probe's PATH:
    /// no probe reaches a real batch system.
    pub(crate) bin: PathBuf,
}

impl Seeds {
    /// The seed file `rel` (panics on a name the driver does not make: a bug of the driver).
    pub(crate) fn get(&self, rel: &str) -> Vec<u8> {
        self.files
            .get(rel)
            .unwrap_or_else(|| panic!("no seed file {rel}"))
            .clone()
    }

    /// The files under the seed directory `prefix`, by their path below it.
    pub(crate) fn tree(&self, prefix: &str) -> Vec<(String, Vec<u8>)> {
        let p = format!("{prefix}/");
        let found: Vec<(String, Vec<u8>)> = self
            .files
            .iter()
            .filter_map(|(k, v)| Some((k.strip_prefix(&p)?.to_string(), v.clone())))
            .collect();
        assert!(!found.is_empty(), "no seed directory {prefix}");
        found
    }

    /// A digest of every seed file (names and bytes): equal when the seeds are made again.
    pub(crate) fn digest(&self) -> String {
        use std::hash::{Hash, Hasher};
        let mut h = std::hash::DefaultHasher::new();
        self.files.hash(&mut h);
        format!("{} files, digest {:016x}", self.files.len(), h.finish())
    }

    /// A data set's three files.
    pub(crate) fn dataset(&self, prefix: &str) -> Vec<(String, Vec<u8>)> {
        self.tree(prefix)
    }
}

/// A filter configuration with every kind of key set (and 20 particles).
pub(crate) const FILTER_CONFIG: &str = r#"particles = 20
resampling = "systematic"
ess_threshold = 0.5
pool = 1
noise_fraction = 0.1
process_noise_factor = 1.0
physical_support = true
r_noise_fraction = 0.05
discretisation = "symplectic"
substeps = 1
window = 20
trace_every = 10
validate = true
loop_every = 4
marginal_prior = { kind = "moment_matched" }
rejuvenation = 0.98

[fix]
n = 2.0

[prior]
k = [{ kind = "log_normal", median = 10.0, log_sd = 0.3 }, { kind = "log_normal", median = 10.0, log_sd = 0.3 }, { kind = "log_normal", median = 10.0, log_sd = 0.3 }]
c = [{ kind = "log_normal", median = 0.4, log_sd = 0.5 }, { kind = "log_normal", median = 0.4, log_sd = 0.5 }, { kind = "log_normal", median = 0.4, log_sd = 0.5 }]
elements = [{ storey = 0, beta_gamma = { kind = "triangle", beta_max = 5.0 }, n = { kind = "uniform", lo = 1.0, hi = 5.0 } }]
"#;

/// The same for field data, with the building.
const FIELD_CONFIG_STRUCTURE: &str = r#"
[structure]
storeys = 3
hysteretic = [1]
masses = [1.0]
measurement = "relative"
damping = "storey"
"#;

/// A study of two runs on a small simulated building.
const STUDY: &str = r#"name = "mini"
description = "fuzz seed"

[data]
preset = "shear-chain"
duration = 0.5

[sweep]
algorithms = ["mpf-ekf2"]
runs = 2
master_seed = 3
particles = [20]

[filter]
trace_every = 0
loop_every = 0
validate = false

[quick]
runs = 1
particles = 10
duration = 0.3
"#;

/// A study on a data directory of the user's.
const OWN_STUDY: &str = r#"name = "own"
description = "fuzz seed"

[data]
dir = "d"

[sweep]
algorithms = ["mpf-ekf2", "mln-rbpf"]
runs = 1
master_seed = 1
particles = [20]

[filter]
trace_every = 0
loop_every = 0
"#;

/// The paper's studies, each a few runs of 0.5 s.
fn paper_study(name: &str) -> String {
    let algorithms = match name {
        "fig4" => r#""bootstrap""#,
        "fig5" => r#""mln-rbpf", "storvik""#,
        "fig6" => r#""mln-rbpf", "mpf-ekf2""#,
        "fig8" => r#""mpf-ekf2""#,
        _ => r#""mln-rbpf", "storvik", "mpf-ekf2", "bootstrap""#,
    };
    format!(
        "name = \"{name}\"\ndescription = \"fuzz seed\"\n\n[data]\npreset = \"paper-3dof\"\n\
         duration = 0.5\n\n[sweep]\nalgorithms = [{algorithms}]\nruns = 2\nmaster_seed = 7\n\
         particles = [20]\n\n[filter]\ntrace_every = 10\nloop_every = 4\n\n[quick]\nruns = 1\n\
         particles = 10\nduration = 0.3\n"
    )
}

/// A regression file: a small study and bounds for two algorithms.
fn regression() -> String {
    let mut s = String::from(
        "[study]\nname = \"regression\"\ndescription = \"fuzz seed\"\n[study.data]\n\
         preset = \"paper-3dof\"\nduration = 0.5\n[study.sweep]\n\
         algorithms = [\"mpf-ekf2\", \"bootstrap\"]\nruns = 2\nmaster_seed = 4242\n\
         particles = [20]\n[study.filter]\ntrace_every = 0\nloop_every = 0\nvalidate = false\n",
    );
    let params = ["k1", "k2", "k3", "c1", "c2", "c3", "beta", "gamma", "n"];
    for alg in ["mpf-ekf2", "bootstrap"] {
        s.push_str(&format!("[thresholds.{alg}]\nmax_failed = 1\n"));
        for table in ["rel_error_mean", "ratio_sd"] {
            s.push_str(&format!("[thresholds.{alg}.{table}]\n"));
            for p in params {
                s.push_str(&format!("{p} = 50.0\n"));
            }
        }
    }
    s
}

/// A scaling study of two small buildings.
const SCALING: &str = r#"name = "scaling"
description = "fuzz seed"

[data]
preset = "building-chain"
duration = 0.5

[sweep]
algorithms = ["mpf-ekf2", "bootstrap"]
runs = 1
master_seed = 5
particles = [20]

[filter]
trace_every = 0
loop_every = 0
validate = false
discretisation = "symplectic"

[[sweep.structures]]
label = "n3-base-all"
storeys = 3
scale = 50.0

[[sweep.structures]]
label = "n4-base-sparse"
storeys = 4
scale = 25.0
sensors = [4]
"#;

/// An excitations study of two ground motions.
const EXCITATIONS: &str = r#"name = "excitations"
description = "fuzz seed"

[data]
preset = "paper-3dof"
duration = 0.5

[sweep]
algorithms = ["mpf-ekf2"]
runs = 1
master_seed = 1989
particles = [20]

[filter]
trace_every = 0
loop_every = 0
validate = false

[[verdicts]]
statement = "the stiffness error differs between ground motions"
test = "differs-from-first"
metric = "k-error"
algorithms = ["mpf-ekf2"]
threshold = 0.01

[[sweep.structures]]
label = "el-centro-paper"
storeys = 3

[[sweep.structures]]
label = "northridge-1994"
storeys = 3
excitation = "northridge-1994"
scale = 57.0
"#;

/// A field study of the shake-table frame's excerpt: one record identified, one validated.
const FIELD_STUDY: &str = r#"title = "fuzz seed"

[[part]]
name = "frame"
title = "frame"
about = "the frame's excerpt"
common = ["--storeys", "3", "--hysteretic", "none", "--measurement", "absolute", "--masses", "1", "--particles", "20", "--seed", "1"]

[[part.record]]
name = "bonus"
map = "frame.toml"
role = "identify"

[[part.record]]
name = "again"
map = "frame.toml"
role = "validate"

[[part.variant]]
name = "mpf"
label = "MPF-EKF2"
algorithm = "mpf-ekf2"
group = "g"

[part.selection]
group = "g"
"#;

/// The recordings the import seeds are cut from (paths in the repository).
const FRAME_DIR: &str = "data/real/shake-table/bonus-event";
const FRAME_FILES: [&str; 4] = ["ground.csv", "floor-1.csv", "floor-2.csv", "floor-3.csv"];
/// Header lines of a sensor export, then the rows kept (3 s at 120 Hz).
const FRAME_HEADER: usize = 8;
const FRAME_ROWS: usize = 360;

/// Builds the seeds in `dir` (created empty) with `sysid`; `root` is the repository whose
/// channel maps, recordings and ground motions the import and excitation seeds are cut from.
pub(crate) fn build(sysid: &Path, root: &Path, dir: &Path) -> Result<Seeds> {
    if dir.exists() {
        std::fs::remove_dir_all(dir).with_context(|| format!("removing {}", dir.display()))?;
    }
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let dir = std::path::absolute(dir)?;
    let bin = stub_slurm(&dir.join("bin"))?;
    let s = Builder {
        sysid,
        dir: &dir,
        bin: &bin,
    };
    s.data_sets()?;
    s.files_from_repository(root)?;
    s.studies()?;
    s.cluster()?;
    s.field_study()?;
    let files = load(&dir, &bin)?;
    Ok(Seeds { files, bin })
}

struct Builder<'a> {
    sysid: &'a Path,
    dir: &'a Path,
    bin: &'a Path,
}

impl Builder<'_> {
    /// Runs `sysid args` in the seed directory; its standard output.
    fn sysid(&self, args: &[&str]) -> Result<Vec<u8>> {
        let path = std::env::var_os("PATH").unwrap_or_default();
        let mut paths = vec![self.bin.to_path_buf()];
        paths.extend(std::env::split_paths(&path));
        let o = Command::new(self.sysid)
            .args(args)
            .current_dir(self.dir)
            .env("PATH", std::env::join_paths(paths).unwrap_or(path))
            .env("RAYON_NUM_THREADS", "1")
            .output()
            .with_context(|| format!("starting {}", self.sysid.display()))?;
        if !o.status.success() {
            let stderr = String::from_utf8_lossy(&o.stderr);
            let lines: Vec<&str> = stderr.lines().collect();
            bail!(
                "making the fuzz seeds: `sysid {}` failed ({}): {}",
                args.join(" "),
                o.status,
                lines[lines.len().saturating_sub(12)..].join("\n")
            );
        }
        Ok(o.stdout)
    }

    fn write(&self, rel: &str, bytes: impl AsRef<[u8]>) -> Result<()> {
        let p = self.dir.join(rel);
        if let Some(parent) = p.parent() {
            std::fs::create_dir_all(parent)?;
        }
        std::fs::write(&p, bytes).with_context(|| format!("writing {}", p.display()))?;
        Ok(())
    }

    /// Data sets, records, a plan, a reference posterior and an information limit.
    fn data_sets(&self) -> Result<()> {
        self.sysid(&["simulate", "--duration", "0.5", "--seed", "1", "--out", "d"])?;
        // The information limit needs a linear record long enough for Newton's ascent (2 s of
        // this one is not: a trial step leaves the prior's support).
        self.sysid(&[
            "simulate",
            "--duration",
            "3",
            "--seed",
            "1",
            "--hysteretic",
            "none",
            "--out",
            "lin",
        ])?;
        self.write(
            "field/measured.csv",
            std::fs::read(self.dir.join("d/measured.csv"))?,
        )?;
        self.write("cfg.toml", FILTER_CONFIG)?;
        self.write(
            "fieldcfg.toml",
            format!("{FILTER_CONFIG}{FIELD_CONFIG_STRUCTURE}"),
        )?;
        let filter = ["filter", "--algorithm", "mpf-ekf2", "--particles", "20"];
        self.sysid(&[&filter[..], &["--data", "d", "--out", "run.json"]].concat())?;
        self.sysid(&[&filter[..], &["--data", "lin", "--out", "runlin.json"]].concat())?;
        self.sysid(&[
            "filter",
            "--data",
            "d",
            "--config",
            "cfg.toml",
            "--algorithm",
            "bootstrap",
            "--out",
            "runcfg.json",
        ])?;
        let plan = self.sysid(&[&filter[..], &["--data", "d", "--print-plan"]].concat())?;
        self.write("plan.toml", plan)?;
        self.sysid(&[
            "reference",
            "--data",
            "d",
            "--particles",
            "10",
            "--iterations",
            "20",
            "--burn-in",
            "5",
            "--probe",
            "2",
            "--out",
            "ref.json",
        ])?;
        self.sysid(&["information", "--data", "lin", "--out", "lim.json"])?;
        Ok(())
    }

    /// Excerpts of the recordings and ground motions of the repository, and channel maps that
    /// name them beside the map.
    fn files_from_repository(&self, root: &Path) -> Result<()> {
        let read = |rel: &str| -> Result<String> {
            let p = root.join(rel);
            std::fs::read_to_string(&p).with_context(|| format!("reading {}", p.display()))
        };
        for f in FRAME_FILES {
            let text = read(&format!("{FRAME_DIR}/{f}"))?;
            let cut: Vec<&str> = text.lines().take(FRAME_HEADER + FRAME_ROWS).collect();
            self.write(&format!("import/{f}"), cut.join("\n") + "\n")?;
        }
        let map = read("experiments/real/frame-bonus-event.toml")?
            .replace(&format!("../../{FRAME_DIR}/"), "");
        self.write("import/frame.toml", map)?;
        for f in ["CHAN003.V2", "CHAN007.V2"] {
            self.write(&format!("v2/{f}"), read(&format!("data/real/csmip/{f}"))?)?;
        }
        let v2 = read("experiments/real/overpass-bent.toml")?.replace("../../data/real/csmip/", "");
        self.write("v2/overpass.toml", v2)?;
        let elcentro = read("data/ground_motions/elcentro_1940_ns.csv")?;
        let cut: Vec<&str> = elcentro.lines().take(120).collect();
        self.write("exc.csv", cut.join("\n") + "\n")?;
        self.write(
            "rec.AT2",
            at2_excerpt(&read(
                "data/ground_motions/peer/RSN1690_NORTH151_SYL090-hor1.AT2",
            )?)?,
        )?;
        Ok(())
    }

    /// Study files and the outputs of small runs of them (a whole one and two shards).
    fn studies(&self) -> Result<()> {
        self.write("mini.toml", STUDY)?;
        self.write("own.toml", OWN_STUDY)?;
        for f in ["fig4", "fig5", "fig6", "fig8", "fig7"] {
            self.write(&format!("exps/{f}.toml"), paper_study(f))?;
        }
        self.write("reg.toml", regression())?;
        self.write("sc.toml", SCALING)?;
        self.write("ex.toml", EXCITATIONS)?;
        let study = ["study", "--config", "mini.toml", "--threads", "1", "--out"];
        self.sysid(&[&study[..], &["st"]].concat())?;
        self.sysid(&[&study[..], &["part0", "--shard", "0/2"]].concat())?;
        self.sysid(&[&study[..], &["part1", "--shard", "1/2"]].concat())?;
        self.sysid(&[
            "scaling",
            "--config",
            "sc.toml",
            "--out",
            "sco",
            "--threads",
            "1",
        ])?;
        Ok(())
    }

    /// A submitted study (with the stand-in `sbatch`) whose two shards have run.
    fn cluster(&self) -> Result<()> {
        let out = ["--out", "cl"];
        self.sysid(
            &[
                &[
                    "cluster",
                    "submit",
                    "study",
                    "--config",
                    "mini.toml",
                    "--tasks",
                    "2",
                ][..],
                &out,
            ]
            .concat(),
        )?;
        for i in 0..2 {
            let part = format!("cl/cluster/parts/shard-{i}");
            let shard = format!("{i}/2");
            self.sysid(&[
                "study",
                "--config",
                "mini.toml",
                "--out",
                &part,
                "--shard",
                &shard,
                "--resume",
                "--threads",
                "1",
            ])?;
        }
        Ok(())
    }

    fn field_study(&self) -> Result<()> {
        self.write("import/fs.toml", FIELD_STUDY)?;
        self.sysid(&["field-study", "--config", "import/fs.toml", "--out", "fso"])?;
        Ok(())
    }
}

/// The first 100 samples of a PEER record, with its header saying so.
fn at2_excerpt(text: &str) -> Result<String> {
    let lines: Vec<&str> = text.lines().collect();
    if lines.len() < 25 {
        bail!("the PEER record for the fuzz seeds is shorter than expected");
    }
    let mut out: Vec<String> = lines[..3].iter().map(|l| l.to_string()).collect();
    out.push("NPTS=   100, DT=   .0200 SEC".into());
    out.extend(lines[4..24].iter().map(|l| l.to_string()));
    Ok(out.join("\n") + "\n")
}

/// Shell scripts standing in for Slurm: `sbatch` answers a job id, the others nothing.
fn stub_slurm(bin: &Path) -> Result<PathBuf> {
    use std::os::unix::fs::PermissionsExt;
    std::fs::create_dir_all(bin)?;
    for (name, body) in [("sbatch", "echo 101\n"), ("squeue", ""), ("scancel", "")] {
        let p = bin.join(name);
        std::fs::write(&p, format!("#!/bin/sh\n{body}"))?;
        std::fs::set_permissions(&p, std::fs::Permissions::from_mode(0o755))?;
    }
    Ok(bin.to_path_buf())
}

/// Every file under `dir` but the stand-ins, with `dir` written as [`ROOT`] in them.
fn load(dir: &Path, bin: &Path) -> Result<BTreeMap<String, Vec<u8>>> {
    let needle = dir.to_string_lossy().into_owned();
    let mut files = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d)? {
            let p = e?.path();
            if p == bin {
                continue;
            }
            if p.is_dir() {
                stack.push(p);
                continue;
            }
            let rel = p
                .strip_prefix(dir)
                .map_err(|_| crate::error::Error::invalid("a seed outside its directory"))?
                .to_string_lossy()
                .into_owned();
            if unsteady(&rel) {
                continue;
            }
            let bytes = std::fs::read(&p)?;
            let bytes = match String::from_utf8(bytes) {
                // The thread CPU time of a scaling run, beside its record.
                Ok(text) if rel.ends_with(".cpu") && text.trim().parse::<f64>().is_ok() => {
                    b"0.25".to_vec()
                }
                Ok(text) => steady(&text.replace(&needle, ROOT)).into_bytes(),
                Err(e) => e.into_bytes(),
            };
            files.insert(rel, bytes);
        }
    }
    Ok(files)
}

/// Files made from timings through and through, which no probe starts from: the scaling
/// study's report, table, summary and cost figure (its records are kept) and the field study's
/// logs and the digests of its steps' inputs beside them (of records that hold their timings; a
/// resumed probe therefore computes every step again, as after any change of its inputs).
fn unsteady(rel: &str) -> bool {
    (rel.starts_with("sco/") && !rel.starts_with("sco/records/"))
        || (rel.contains("/logs/") && (rel.ends_with(".txt") || rel.ends_with(".inputs")))
}

/// `text` with what differs from one making of the seeds to the next written as fixed values —
/// timings (JSON keys ending in `_s`, `seconds`, `realtime_factor`; the last column of a
/// Markdown table headed `wall s`, a field study's) and UTC times — so that a seed makes the
/// same probes byte for byte (`.cpu` files, the thread CPU times of the scaling runs, are made
/// 0.25 too). No reader checks these values.
fn steady(text: &str) -> String {
    let mut wall_table = false;
    text.split_inclusive('\n')
        .map(|line| {
            let row = line.trim_end();
            if !row.starts_with('|') {
                wall_table = false;
            } else if row.ends_with("| wall s |") {
                wall_table = true;
                return line.to_string();
            }
            let line = if wall_table {
                steady_last_cell(line)
            } else {
                line.to_string()
            };
            steady_times(&steady_timing(&line))
        })
        .collect()
}

/// A Markdown table row `| … | <number> |` with its last cell made 0.25 (other rows as they are).
fn steady_last_cell(line: &str) -> String {
    let row = line.trim_end();
    let Some(head) = row.strip_suffix('|') else {
        return line.to_string();
    };
    let Some((before, last)) = head.rsplit_once('|') else {
        return line.to_string();
    };
    if last.trim().parse::<f64>().is_err() {
        return line.to_string();
    }
    format!("{before}| 0.25 |{}", &line[row.len()..])
}

/// A line `"<timing key>": <number>,` with the number made 0.25.
fn steady_timing(line: &str) -> String {
    let body = line.trim_start();
    let indent = &line[..line.len() - body.len()];
    let Some((key, value)) = body
        .strip_prefix('"')
        .and_then(|rest| rest.split_once("\": "))
    else {
        return line.to_string();
    };
    if !(key.ends_with("_s") || key == "realtime_factor" || key == "seconds") {
        return line.to_string();
    }
    let end = value.find([',', '\n', '\r']).unwrap_or(value.len());
    if value[..end].trim().parse::<f64>().is_err() {
        return line.to_string();
    }
    format!("{indent}\"{key}\": 0.25{}", &value[end..])
}

/// Every UTC time `YYYY-MM-DDTHH:MM:SS` in `line` made 2026-01-01T00:00:00.
fn steady_times(line: &str) -> String {
    const SHAPE: &[u8] = b"dddd-dd-ddTdd:dd:dd";
    let bytes = line.as_bytes();
    let mut out = String::with_capacity(line.len());
    let mut i = 0;
    while i < bytes.len() {
        let fits = bytes.len() - i >= SHAPE.len()
            && SHAPE.iter().zip(&bytes[i..]).all(|(s, b)| match s {
                b'd' => b.is_ascii_digit(),
                s => s == b,
            });
        if fits {
            out.push_str("2026-01-01T00:00:00");
            i += SHAPE.len();
        } else {
            let c = line[i..].chars().next().expect("a character");
            out.push(c);
            i += c.len_utf8();
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn timings_and_times_are_made_steady() {
        let text = "{\n  \"wall_s\": 0.0065,\n  \"realtime_factor\": 76.4\n  \"runs\": 3,\n  \
                    \"submitted\": \"2026-11-29T08:45:18Z\", \"é\": 1\n}\n";
        assert_eq!(
            steady(text),
            "{\n  \"wall_s\": 0.25,\n  \"realtime_factor\": 0.25\n  \"runs\": 3,\n  \
             \"submitted\": \"2026-01-01T00:00:00Z\", \"é\": 1\n}\n"
        );
        // A field study's table: its wall-time column only.
        let report =
            "| variant | fit % | wall s |\n|---|---|---|\n| a | 62.1 | 0.1 |\n\n| x | 3 |\n";
        assert_eq!(
            steady(report),
            "| variant | fit % | wall s |\n|---|---|---|\n| a | 62.1 | 0.25 |\n\n| x | 3 |\n"
        );
    }
}
