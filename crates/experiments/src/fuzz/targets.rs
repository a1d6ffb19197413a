//! The valid command of each `sysid` subcommand that reads a user's file, built on the seeds
//! with small workloads; [`super::hostile`] then makes it hostile.

use rand::seq::IndexedRandom;
use rand::Rng;

use super::mutate::FuzzRng;
use super::probe::{Probe, Program, Ref};
use super::seeds::Seeds;

/// Makes the valid probe of one target.
pub(crate) type Make = fn(&Seeds, &mut FuzzRng) -> Probe;

/// Every `sysid` target: the subcommands that read a file, a value or an output path of the
/// user's.
pub(crate) const TARGETS: &[(&str, Make)] = &[
    ("simulate", simulate),
    ("import", import),
    ("filter", filter),
    ("validate", validate),
    ("plot", plot),
    ("loglik", loglik),
    ("information", information),
    ("reference", reference),
    ("compare-reference", compare_reference),
    ("study", study),
    ("reproduce", reproduce),
    ("regression", regression),
    ("scaling", scaling),
    ("excitations", excitations),
    ("merge", merge),
    ("cluster submit", cluster_submit),
    ("cluster status", cluster_status),
    ("cluster resubmit", cluster_resubmit),
    ("cluster finish", cluster_finish),
    ("cluster compare", cluster_compare),
    ("field-study", field_study),
    ("table1", table1),
];

const DATASET: &[&str] = &["measured.csv", "truth.csv", "dataset.json"];
const IMPORTED: &[&str] = &["measured.csv", "import.json"];
const RUN_FIGURES: &[&str] = &[
    "convergence.svg",
    "ess.svg",
    "hysteresis.svg",
    "accelerations.svg",
    "innovations.svg",
    "innovation_acf.svg",
    "free_run.svg",
    "transfer.svg",
    "shapes.svg",
];
const VALIDATE_FIGURES: &[&str] = &["free_run.svg", "transfer.svg", "shapes.svg"];
const STUDY_OUT: &[&str] = &[
    "REPORT.md",
    "summary.json",
    "records",
    "theta_val.svg",
    "sd_over_spread.svg",
    "last-run.json",
    ".sysid.lock",
];
const SCALING_OUT: &[&str] = &[
    "REPORT.md",
    "summary.json",
    "records",
    "cells.csv",
    "cost_vs_dimension.svg",
    "accuracy_vs_storeys.svg",
    "errors_by_excitation.svg",
];
const PAPER_OUT: &[&str] = &[
    "REPORT.md",
    "summary.json",
    "records",
    "table1",
    "fig4a_bootstrap_convergence.svg",
    "fig7_theta_val_crosses.svg",
    "fig7_coverage.svg",
    "fig8b_mpfekf2_loop.svg",
];
const FIELD_OUT: &[&str] = &["REPORT.md", "frame"];

fn pick<'a>(rng: &mut FuzzRng, values: &[&'a str]) -> &'a str {
    values.choose(rng).expect("values")
}

fn sysid(target: &'static str) -> Probe {
    Probe::new(target, Program::Sysid)
}

fn simulate(s: &Seeds, rng: &mut FuzzRng) -> Probe {
    let mut p = sysid("simulate");
    p.args(&["simulate"]);
    p.flag("--duration", "0.5");
    p.flag("--seed", "1");
    match rng.random_range(0..5) {
        0 => {
            p.input(Some("--excitation"), "exc.csv", s.get("exc.csv"));
            p.flag("--units", pick(rng, &["g", "m/s2"]));
        }
        1 => {
            p.input(Some("--excitation"), "rec.AT2", s.get("rec.AT2"));
        }
        2 => {
            p.flag("--preset", "shear-chain");
            p.flag("--storeys", "4");
            p.flag("--hysteretic", "1,3");
            p.flag("--sensors", "2,4");
            p.args(&["--absolute"]);
        }
        3 => {
            p.flag("--excitation", "kanai-tajimi");
            p.flag("--scale", "2");
            p.flag("--noise-fraction", "0.2");
            p.flag("--run", "3");
        }
        _ => {}
    }
    if rng.random_bool(0.3) {
        // Over an existing data set, which it replaces.
        p.output_files("o", s.dataset("d"));
    }
    p.output(Some("--out"), "o", true, DATASET);
    p
}

fn import(s: &Seeds, rng: &mut FuzzRng) -> Probe {
    let mut p = sysid("import");
    p.args(&["import"]);
    if rng.random_bool(0.7) {
        for (name, bytes) in s.tree("import") {
            if name.ends_with(".csv") {
                p.file(&name, bytes);
            }
        }
        p.input(Some("--map"), "frame.toml", s.get("import/frame.toml"));
    } else {
        for f in ["CHAN003.V2", "CHAN007.V2"] {
            p.file(f, s.get(&format!("v2/{f}")));
        }
        p.input(Some("--map"), "overpass.toml", s.get("v2/overpass.toml"));
    }
    p.output(Some("--out"), "o", true, IMPORTED);
    p
}

/// The data set `d` (simulated, with its truth) or `field` (measured only, the building given
/// by flags or the config).
fn data_arg(p: &mut Probe, s: &Seeds, rng: &mut FuzzRng) -> bool {
    let field = rng.random_bool(0.25);
    let name = if field { "field" } else { "d" };
    p.input_dir_arg(Some("--data"), name, s.dataset(name));
    field
}

fn filter(s: &Seeds, rng: &mut FuzzRng) -> Probe {
    let mut p = sysid("filter");
    p.args(&["filter"]);
    if rng.random_bool(0.1) {
        // Exactly a printed plan.
        p.input_dir_arg(Some("--data"), "d", s.dataset("d"));
        p.input(Some("--plan"), "plan.toml", s.get("plan.toml"));
    } else {
        let field = data_arg(&mut p, s, rng);
        p.flag(
            "--algorithm",
            pick(rng, &["mpf-ekf2", "bootstrap", "mln-rbpf", "storvik"]),
        );
        p.flag("--particles", "20");
        if rng.random_bool(0.4) {
            let cfg = if field { "fieldcfg.toml" } else { "cfg.toml" };
            p.input(Some("--config"), cfg, s.get(cfg));
        } else if field {
            p.flag("--storeys", "3");
            p.flag("--hysteretic", "1");
            p.flag("--masses", "1");
            p.flag("--measurement", "relative");
        }
        filter_options(&mut p, rng);
    }
    p.flag("--seed", "1");
    p.flag("--threads", "1");
    p.output(Some("--out"), "run.json", false, &[]);
    if rng.random_bool(0.3) {
        p.output(Some("--plot"), "figs", true, RUN_FIGURES);
    }
    p
}

/// A few of `filter`'s options, each with a valid value.
fn filter_options(p: &mut Probe, rng: &mut FuzzRng) {
    let options: [(&str, &[&str]); 10] = [
        ("--fix", &["k1=8", "n=2", "k1=8,c1=0.4"]),
        ("--ess-threshold", &["0.5", "1"]),
        ("--substeps", &["2", "auto"]),
        ("--rejuvenation", &["0.98", "1"]),
        ("--noise-fraction", &["0.1", "0.05"]),
        ("--process-noise-factor", &["1", "2"]),
        ("--resampling", &["stratified", "residual"]),
        ("--discretisation", &["symplectic", "euler"]),
        ("--damping", &["storey"]),
        ("--run", &["2"]),
    ];
    for (flag, values) in options {
        if rng.random_bool(0.15) {
            p.flag(flag, pick(rng, values));
        }
    }
}

fn validate(s: &Seeds, rng: &mut FuzzRng) -> Probe {
    let mut p = sysid("validate");
    p.args(&["validate"]);
    p.input(Some("--record"), "run.json", s.get("run.json"));
    p.input_dir_arg(Some("--data"), "d", s.dataset("d"));
    p.flag("--draws", "3");
    if rng.random_bool(0.7) {
        p.output(Some("--out"), "v.json", false, &[]);
    }
    if rng.random_bool(0.4) {
        p.output(Some("--plot"), "figs", true, VALIDATE_FIGURES);
    }
    p
}

fn plot(s: &Seeds, rng: &mut FuzzRng) -> Probe {
    let mut p = sysid("plot");
    p.args(&["plot"]);
    let record = pick(rng, &["run.json", "runcfg.json"]);
    p.input(None, record, s.get(record));
    p.output(Some("--out"), "figs", true, RUN_FIGURES);
    p
}

fn loglik(s: &Seeds, rng: &mut FuzzRng) -> Probe {
    let mut p = sysid("loglik");
    p.args(&["loglik"]);
    p.input_dir_arg(Some("--data"), "d", s.dataset("d"));
    p.input(None, "run.json", s.get("run.json"));
    if rng.random_bool(0.3) {
        p.input(None, "runcfg.json", s.get("runcfg.json"));
    }
    p.flag("--particles", "20");
    p.flag("--seeds", "2");
    if rng.random_bool(0.4) {
        p.args(&["--truth"]);
    }
    if rng.random_bool(0.3) {
        p.input(Some("--config"), "cfg.toml", s.get("cfg.toml"));
    }
    if rng.random_bool(0.6) {
        p.output(Some("--out"), "ll.txt", false, &[]);
    }
    p
}

fn information(s: &Seeds, rng: &mut FuzzRng) -> Probe {
    let mut p = sysid("information");
    p.args(&["information"]);
    if rng.random_bool(0.5) {
        p.input(Some("--limit"), "lim.json", s.get("lim.json"));
        p.input(None, "runlin.json", s.get("runlin.json"));
    } else {
        p.input_dir_arg(Some("--data"), "lin", s.dataset("lin"));
        p.input(None, "runlin.json", s.get("runlin.json"));
        p.flag("--step", "0.001");
        if rng.random_bool(0.3) {
            p.input(Some("--start"), "start.json", s.get("runlin.json"));
        }
        p.output(Some("--out"), "lim.json", false, &[]);
    }
    if rng.random_bool(0.5) {
        p.output(Some("--table"), "t.md", false, &[]);
    }
    p
}

fn reference(s: &Seeds, rng: &mut FuzzRng) -> Probe {
    let mut p = sysid("reference");
    p.args(&["reference"]);
    p.input_dir_arg(Some("--data"), "d", s.dataset("d"));
    p.flag("--particles", "10");
    p.flag("--iterations", "20");
    p.flag("--burn-in", "5");
    p.flag("--probe", "2");
    p.flag("--seed", "1");
    p.flag("--estimator", pick(rng, &["mpf-ekf2", "bootstrap"]));
    match rng.random_range(0..4) {
        0 => {
            p.input(Some("--start-from"), "run.json", s.get("run.json"));
        }
        1 => {
            p.args(&["--start-at-truth"]);
        }
        2 => {
            p.input(Some("--config"), "cfg.toml", s.get("cfg.toml"));
        }
        _ => {}
    }
    p.output(Some("--out"), "ref.json", false, &[]);
    p
}

fn compare_reference(s: &Seeds, rng: &mut FuzzRng) -> Probe {
    let mut p = sysid("compare-reference");
    p.args(&["compare-reference"]);
    p.input(Some("--reference"), "ref.json", s.get("ref.json"));
    p.input(None, "run.json", s.get("run.json"));
    if rng.random_bool(0.3) {
        p.input(None, "runcfg.json", s.get("runcfg.json"));
    }
    if rng.random_bool(0.5) {
        p.output(Some("--out"), "c.md", false, &[]);
    }
    p
}

/// Sweep options of the study commands.
fn sweep_options(p: &mut Probe, rng: &mut FuzzRng) {
    p.flag("--threads", "1");
    if rng.random_bool(0.2) {
        p.args(&["--quick"]);
    }
    if rng.random_bool(0.15) {
        p.flag("--shard", pick(rng, &["0/2", "1/2"]));
    }
}

fn study(s: &Seeds, rng: &mut FuzzRng) -> Probe {
    let mut p = sysid("study");
    p.args(&["study"]);
    if rng.random_bool(0.3) {
        p.input_dir("d", s.dataset("d"), Ref::None);
        p.input(Some("--config"), "own.toml", s.get("own.toml"));
    } else {
        p.input(Some("--config"), "mini.toml", s.get("mini.toml"));
        if rng.random_bool(0.3) {
            // A resumed study, with the records of an earlier one in its output.
            p.output_files("st", s.tree("st"));
            p.args(&["--resume"]);
        }
    }
    sweep_options(&mut p, rng);
    p.output(Some("--out"), "st", true, STUDY_OUT);
    p
}

fn reproduce(s: &Seeds, rng: &mut FuzzRng) -> Probe {
    let mut p = sysid("reproduce");
    p.args(&["reproduce"]);
    p.args(&["--experiments", "exps"]);
    for (name, bytes) in s.tree("exps") {
        p.file(&format!("exps/{name}"), bytes);
    }
    sweep_options(&mut p, rng);
    if rng.random_bool(0.2) {
        p.args(&["--resume"]);
    }
    p.output(Some("--out"), "paper", true, PAPER_OUT);
    p
}

fn regression(s: &Seeds, rng: &mut FuzzRng) -> Probe {
    let mut p = sysid("regression");
    p.args(&["regression"]);
    p.input(Some("--config"), "reg.toml", s.get("reg.toml"));
    p.flag("--threads", "1");
    if rng.random_bool(0.2) {
        p.args(&[pick(rng, &["--resume", "--fresh"])]);
    }
    p.output(
        Some("--out"),
        "reg",
        true,
        &["records", "regression.json", "last-run.json"],
    );
    p
}

fn scaling(s: &Seeds, rng: &mut FuzzRng) -> Probe {
    let mut p = sysid("scaling");
    p.args(&["scaling"]);
    p.input(Some("--config"), "sc.toml", s.get("sc.toml"));
    sweep_options(&mut p, rng);
    if rng.random_bool(0.3) {
        // An earlier run's records, with their CPU times (the seeds keep no more of it: its
        // report, table and figures hold timings, which differ from one making to the next).
        p.output_files("sco", s.tree("sco"));
        p.args(&[pick(rng, &["--resume", "--report-only"])]);
    }
    p.output(Some("--out"), "sco", true, SCALING_OUT);
    p
}

fn excitations(s: &Seeds, rng: &mut FuzzRng) -> Probe {
    let mut p = sysid("excitations");
    p.args(&["excitations"]);
    p.input(Some("--config"), "ex.toml", s.get("ex.toml"));
    sweep_options(&mut p, rng);
    p.output(Some("--out"), "exo", true, SCALING_OUT);
    p
}

fn merge(s: &Seeds, rng: &mut FuzzRng) -> Probe {
    let mut p = sysid("merge");
    p.args(&["merge"]);
    if rng.random_bool(0.3) {
        // Into a directory that already holds records.
        p.output_files("m", s.tree("part0"));
    }
    p.output(Some("--into"), "m", true, &["records", ".sysid.lock"]);
    for part in ["part0", "part1"] {
        p.input_dir_arg(None, part, s.tree(part));
    }
    p
}

/// The study of a cluster submission: its kind and its `--config`.
fn cluster_kind(p: &mut Probe, s: &Seeds, rng: &mut FuzzRng) {
    match rng.random_range(0..5) {
        0 => {
            p.args(&["paper"]);
            p.args(&["--config", "exps"]);
            for (name, bytes) in s.tree("exps") {
                p.file(&format!("exps/{name}"), bytes);
            }
        }
        1 => {
            p.args(&["scaling"]);
            p.input(Some("--config"), "sc.toml", s.get("sc.toml"));
        }
        2 => {
            p.args(&["excitations"]);
            p.input(Some("--config"), "ex.toml", s.get("ex.toml"));
        }
        _ => {
            p.args(&["study"]);
            p.input(Some("--config"), "mini.toml", s.get("mini.toml"));
        }
    }
}

fn cluster_submit(s: &Seeds, rng: &mut FuzzRng) -> Probe {
    let mut p = sysid("cluster submit");
    p.args(&["cluster", "submit"]);
    cluster_kind(&mut p, s, rng);
    p.flag("--tasks", "2");
    let options: [(&str, &str); 6] = [
        ("--cpus-per-task", "1"),
        ("--partition", "short"),
        ("--time", "01:00:00"),
        ("--mem", "1G"),
        ("--account", "proj"),
        ("--max-running", "1"),
    ];
    for (flag, value) in options {
        if rng.random_bool(0.3) {
            p.flag(flag, value);
        }
    }
    if rng.random_bool(0.1) {
        p.args(&["--quick"]);
    }
    if rng.random_bool(0.8) {
        // A dry run writes nothing: no output is declared.
        p.args(&["--dry-run", "--out", "cl"]);
        p.flags.push(Ref::Arg(p.args.len() - 1));
    } else {
        p.output(Some("--out"), "cl", true, &["cluster"]);
    }
    p
}

/// A submitted study whose shards have run: the plan, scripts, submissions and the shards'
/// records, all inputs that may be mutated, in `cl`.
fn submitted(p: &mut Probe, s: &Seeds) {
    p.file("mini.toml", s.get("mini.toml"));
    for (name, bytes) in s.tree("cl") {
        p.file(&format!("cl/{name}"), bytes);
    }
}

fn cluster_status(s: &Seeds, _rng: &mut FuzzRng) -> Probe {
    let mut p = sysid("cluster status");
    p.args(&["cluster", "status"]);
    submitted(&mut p, s);
    p.args(&["--out", "cl"]);
    p
}

fn cluster_resubmit(s: &Seeds, _rng: &mut FuzzRng) -> Probe {
    let mut p = sysid("cluster resubmit");
    p.args(&["cluster", "resubmit", "--dry-run"]);
    submitted(&mut p, s);
    p.args(&["--out", "cl"]);
    p
}

fn cluster_finish(s: &Seeds, _rng: &mut FuzzRng) -> Probe {
    let mut p = sysid("cluster finish");
    p.args(&["cluster", "finish"]);
    submitted(&mut p, s);
    // The finish writes the merged records and the report into the study's output, beside
    // the submission it reads.
    for s in p.inputs.iter_mut() {
        s.kept = false;
    }
    p.output(Some("--out"), "cl", true, STUDY_OUT);
    p
}

fn cluster_compare(s: &Seeds, rng: &mut FuzzRng) -> Probe {
    let mut p = sysid("cluster compare");
    p.args(&["cluster", "compare"]);
    let b = pick(rng, &["st", "part0"]);
    p.input_dir_arg(None, "a", s.tree("st"));
    p.input_dir_arg(None, "b", s.tree(b));
    p
}

fn field_study(s: &Seeds, rng: &mut FuzzRng) -> Probe {
    let mut p = sysid("field-study");
    p.args(&["field-study"]);
    for (name, bytes) in s.tree("import") {
        if name != "fs.toml" {
            p.file(&format!("import/{name}"), bytes);
        }
    }
    p.input(Some("--config"), "import/fs.toml", s.get("import/fs.toml"));
    if rng.random_bool(0.5) {
        // Resumed or reported from an earlier study's output.
        p.output_files("fso", s.tree("fso"));
        p.args(&[pick(rng, &["--resume", "--report-only"])]);
    }
    p.output(Some("--out"), "fso", true, FIELD_OUT);
    p
}

fn table1(_s: &Seeds, _rng: &mut FuzzRng) -> Probe {
    let mut p = sysid("table1");
    p.args(&["table1"]);
    p.output(Some("--out"), "t1", true, &["table1.json", "table1.md"]);
    p
}
