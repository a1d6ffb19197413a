//! The plan of a `sysid filter` run (`identify::plan`): settled once, printed
//! (`--plan-only`), written as TOML (`--print-plan`) and run again from that file (`--plan`) to
//! the same record; refused on other data.

use crate::common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use identify::plan::RunPlan;
use identify::record::RunRecord;

fn sysid() -> Command {
    Command::new(env!("CARGO_BIN_EXE_sysid"))
}

fn temp_dir(tag: &str) -> (tempfile::TempDir, PathBuf) {
    common::temp_dir(&format!("sysid-plan-{tag}-"))
}

fn ok(out: Output, what: &str) -> Output {
    assert!(
        out.status.success(),
        "{what} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// A filter run that finished: exit 0, or 1 for an answer `sysid filter` rejects (a 3 s record
/// of field data can give one), its record written either way.
fn ran(out: Output, what: &str) {
    assert!(
        matches!(out.status.code(), Some(0 | 1))
            && String::from_utf8_lossy(&out.stderr).contains("; record "),
        "{what} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// A 3-storey paper data set of `seconds` s; as field data (only `measured.csv`) when `field`.
fn simulate(dir: &Path, seed: &str, field: bool) {
    ok(
        sysid()
            .args([
                "simulate",
                "--preset",
                "paper-3dof",
                "--duration",
                "3",
                "--seed",
                seed,
            ])
            .arg("--out")
            .arg(dir)
            .output()
            .unwrap(),
        "simulate",
    );
    if field {
        for f in ["dataset.json", "truth.csv"] {
            std::fs::remove_file(dir.join(f)).unwrap();
        }
    }
}

const FIELD_FLAGS: [&str; 8] = [
    "--storeys",
    "3",
    "--hysteretic",
    "1",
    "--masses",
    "1",
    "--measurement",
    "relative",
];

fn without_timing(path: &Path) -> serde_json::Value {
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    v.as_object_mut().unwrap().remove("timing");
    v
}

/// For simulated and for field data (where the prior is scaled from the data and the default
/// rules choose rejuvenation and sub-steps): the record of a run, and the record of the plan
/// `--print-plan` wrote for the same flags, run with `--plan`, are equal in every field but the
/// timing; the record carries that plan, and the TOML reads back to it.
#[test]
fn a_printed_plan_runs_to_the_same_record() {
    let (_tmp, dir) = temp_dir("same");
    for field in [false, true] {
        let data = dir.join(format!("data-{field}"));
        simulate(&data, "1", field);
        let mut flags: Vec<&str> = vec!["filter", "--algorithm", "mpf-ekf2", "--particles", "100"];
        if field {
            flags.extend(FIELD_FLAGS);
        }
        let direct = dir.join(format!("direct-{field}.json"));
        ran(
            sysid()
                .args(&flags)
                .arg("--data")
                .arg(&data)
                .arg("--out")
                .arg(&direct)
                .output()
                .unwrap(),
            "filter",
        );
        let printed = ok(
            sysid()
                .args(&flags)
                .arg("--data")
                .arg(&data)
                .arg("--print-plan")
                .output()
                .unwrap(),
            "--print-plan",
        );
        let plan_file = dir.join(format!("plan-{field}.toml"));
        std::fs::write(&plan_file, &printed.stdout).unwrap();
        let replayed = dir.join(format!("replayed-{field}.json"));
        ran(
            sysid()
                .args(["filter", "--plan"])
                .arg(&plan_file)
                .arg("--data")
                .arg(&data)
                .arg("--out")
                .arg(&replayed)
                .output()
                .unwrap(),
            "--plan",
        );
        assert_eq!(
            without_timing(&direct),
            without_timing(&replayed),
            "field data: {field}"
        );
        let text = String::from_utf8(printed.stdout).unwrap();
        let plan = RunPlan::from_toml(&text, "plan.toml").unwrap();
        let record: RunRecord =
            serde_json::from_str(&std::fs::read_to_string(&direct).unwrap()).unwrap();
        assert_eq!(RunPlan::of_record(&record).unwrap().as_ref(), Some(&plan));
        assert_eq!(
            RunPlan::from_toml(&plan.to_toml().unwrap(), "again").unwrap(),
            plan
        );
        // What the rules chose is in the plan, with its rule.
        let rules: Vec<&str> = plan.decisions.iter().map(|d| d.rule.as_str()).collect();
        assert!(rules.contains(&"rules::MPF_REJUVENATION"), "{rules:?}");
        assert_eq!(
            rules.contains(&"scaled_prior::scaled_prior"),
            field,
            "{rules:?}"
        );
        assert_eq!(plan.evidence.prior_from_data.is_some(), field);
    }
}

/// A plan settled on one data set is refused on another, naming the file and the field; an
/// edited plan of another version, or with a setting out of range, is refused by name.
#[test]
fn a_plan_is_refused_on_other_data_or_when_broken() {
    let (_tmp, dir) = temp_dir("refused");
    let (one, two) = (dir.join("one"), dir.join("two"));
    simulate(&one, "1", false);
    simulate(&two, "2", false);
    let printed = ok(
        sysid()
            .args([
                "filter",
                "--algorithm",
                "mln-rbpf",
                "--print-plan",
                "--data",
            ])
            .arg(&one)
            .output()
            .unwrap(),
        "--print-plan",
    );
    let text = String::from_utf8(printed.stdout).unwrap();
    let run = |plan: &str, data: &Path| -> String {
        let file = dir.join("plan.toml");
        std::fs::write(&file, plan).unwrap();
        let out = sysid()
            .args(["filter", "--plan"])
            .arg(&file)
            .arg("--data")
            .arg(data)
            .arg("--out")
            .arg(dir.join("r.json"))
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(1), "{plan}");
        String::from_utf8(out.stderr).unwrap()
    };
    let e = run(&text, &two);
    assert!(
        e.contains("plan.toml") && e.contains("`data_sha256`"),
        "{e}"
    );
    let e = run(&text.replace("plan_version = 1", "plan_version = 7"), &one);
    assert!(e.contains("`plan_version`"), "{e}");
    let e = run(&text.replace("window = 80", "window = 0"), &one);
    assert!(e.contains("`window`"), "{e}");
    assert!(!dir.join("r.json").exists());
    // Flags that settle a plan are refused beside one.
    let out = sysid()
        .args([
            "filter",
            "--plan",
            "p.toml",
            "--particles",
            "5",
            "--data",
            "d",
            "--out",
            "r",
        ])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--particles"));
}

/// `--plan-only` prints the plan — algorithm, building, particles, sub-steps, prior, noise
/// levels and every decision with its rule — and runs nothing.
#[test]
fn plan_only_prints_the_plan_and_runs_nothing() {
    let (_tmp, dir) = temp_dir("only");
    let data = dir.join("d");
    simulate(&data, "1", true);
    let out = ok(
        sysid()
            .args(["filter", "--algorithm", "mpf-ekf2", "--plan-only"])
            .args(FIELD_FLAGS)
            .arg("--data")
            .arg(&data)
            .output()
            .unwrap(),
        "--plan-only",
    );
    let text = String::from_utf8(out.stdout).unwrap();
    for needle in [
        "plan: MPF-EKF2 on 3 storeys",
        "particles 4000 as 8 filter(s)",
        "[rules::HYSTERETIC_PARTICLES] note:",
        "rejuvenation δ = 0.98",
        "θ: k1, k2, k3, c1, c2, c3, beta, gamma, n (9 parameters)",
        "[field::resolve] field data: 3 storeys",
        "[scaled_prior::scaled_prior]",
        "[rules::MPF_REJUVENATION] note:",
    ] {
        assert!(text.contains(needle), "`{needle}` missing from:\n{text}");
    }
    assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1, "only the data");
}

/// `sysid filter --help` states the defaults the rules choose, from the rules' own constants:
/// the rejuvenation's δ, the counts of particles and pooled filters, the sub-step caps; and a run
/// without a config on a hysteretic building takes that δ.
#[test]
fn the_help_states_the_rules_defaults() {
    use identify::rules::{
        HYSTERETIC_PARTICLES, LAG_SUBSTEPS, MPF_REJUVENATION, SUBSTEP_CHECK_TOLERANCE,
    };
    let out = ok(
        sysid().args(["filter", "--help"]).output().unwrap(),
        "--help",
    );
    let help = String::from_utf8(out.stdout).unwrap();
    for needle in [
        format!("Default without --config: δ = {MPF_REJUVENATION} for the MPF-EKF2"),
        format!("{HYSTERETIC_PARTICLES} as 8 × 500"),
        format!("velocity lag exceeds 3 %, {LAG_SUBSTEPS}"),
        format!(
            "the count is doubled (at most {}) until a doubling moves every stiffness by at most {SUBSTEP_CHECK_TOLERANCE} of its posterior s.d.",
            models::filtering::MAX_SUBSTEPS
        ),
        "runs as one Gaussian filter (1 particle)".to_string(),
    ] {
        assert!(help.contains(&needle), "`{needle}` missing from the help");
    }
    assert!(!help.contains("Default: no move"));
    let (_tmp, dir) = temp_dir("help");
    let data = dir.join("d");
    simulate(&data, "1", false);
    let printed = ok(
        sysid()
            .args([
                "filter",
                "--algorithm",
                "mpf-ekf2",
                "--print-plan",
                "--data",
            ])
            .arg(&data)
            .output()
            .unwrap(),
        "--print-plan",
    );
    let plan = RunPlan::from_toml(&String::from_utf8(printed.stdout).unwrap(), "plan").unwrap();
    assert_eq!(plan.settings.rejuvenation, Some(MPF_REJUVENATION));
}

/// The MPF-EKF2 on a building without hysteretic element samples nothing: asked for 1000
/// particles as 8 filters it runs one Gaussian filter, says so in the plan, the record and the
/// summary, warns about no effective sample size, and gives the answer the 1000 identical
/// particles give (θ_val equal to round-off: the same EKF2, its mean over 8 copies).
#[test]
fn a_linear_building_runs_one_gaussian_filter() {
    let (_tmp, dir) = temp_dir("linear");
    let data = dir.join("d");
    ok(
        sysid()
            .args([
                "simulate",
                "--storeys",
                "3",
                "--hysteretic",
                "none",
                "--duration",
                "4",
            ])
            .args(["--seed", "5", "--out"])
            .arg(&data)
            .output()
            .unwrap(),
        "simulate",
    );
    let run = |extra: &[&str], out: &Path| -> Output {
        let o = sysid()
            .args(["filter", "--algorithm", "mpf-ekf2", "--data"])
            .arg(&data)
            .args(extra)
            .arg("--out")
            .arg(out)
            .output()
            .unwrap();
        ran(o.clone(), "filter");
        o
    };
    let one = dir.join("one.json");
    let o = run(&[], &one);
    let stderr = String::from_utf8_lossy(&o.stderr);
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stderr.contains("[rules::samples_nothing]") || stderr.contains("one Gaussian filter"));
    assert!(stdout.contains("One Gaussian filter (EKF2)"), "{stdout}");
    assert!(!stdout.contains("ESS over the run"), "{stdout}");
    assert!(!stderr.contains("effective sample size"), "{stderr}");
    let r: RunRecord = serde_json::from_str(&std::fs::read_to_string(&one).unwrap()).unwrap();
    assert!(r.one_gaussian_filter);
    assert_eq!(r.particles, 1);
    // A study's job keeps its settings (1000 particles as 8 filters, every one the same EKF2):
    // the same answer to round-off.
    let many = identify::pipeline::identify(
        &identify::pipeline::RunInput {
            data: &models::dataset::load_dir(&data).unwrap(),
            chain: None,
            experiment: "cli",
            seed: 1,
            run: 0,
            progress: None,
            residuals: false,
        },
        identify::pipeline::Algorithm::MpfEkf2,
        &identify::pipeline::FilterSettings::recommended(),
    )
    .unwrap();
    assert_eq!((many.particles, many.one_gaussian_filter), (1000, false));
    for (j, (a, b)) in r.theta_val.iter().zip(&many.theta_val).enumerate() {
        assert!(
            (a - b).abs() <= 1e-9 * b.abs(),
            "{}: {a} against {b}",
            r.param_names[j]
        );
    }
    assert!((r.loglik - many.loglik).abs() <= 1e-9 * many.loglik.abs());
}

/// `sysid filter` with `flags` on `data` with `--threads` 1, 2 and 7: the three records, timing
/// left out.
fn on_threads(dir: &Path, data: &Path, tag: &str, flags: &[&str]) -> Vec<serde_json::Value> {
    ["1", "2", "7"]
        .iter()
        .map(|threads| {
            let out = dir.join(format!("{tag}-{threads}.json"));
            ran(
                sysid()
                    .arg("filter")
                    .args(flags)
                    .args(["--threads", threads, "--data"])
                    .arg(data)
                    .arg("--out")
                    .arg(&out)
                    .output()
                    .unwrap(),
                "filter",
            );
            without_timing(&out)
        })
        .collect()
}

/// The pooled filters of one run run side by side; the record is the same, byte for byte but
/// for the timing, on 1, 2 and 7 threads (`--threads`), for a marginalised and a sampled filter.
#[test]
fn a_pooled_run_is_the_same_on_any_number_of_threads() {
    let (_tmp, dir) = temp_dir("threads");
    let data = dir.join("d");
    simulate(&data, "2", false);
    for alg in ["mpf-ekf2", "storvik"] {
        let records = on_threads(
            &dir,
            &data,
            alg,
            &["--algorithm", alg, "--particles", "500"],
        );
        assert_eq!(records[0]["config"]["filter"]["pool"], 4, "{alg}");
        assert_eq!(records[0], records[1], "{alg}: 1 and 2 threads");
        assert_eq!(records[0], records[2], "{alg}: 1 and 7 threads");
    }
}

/// One filter of a tall building advances its particles in blocks on the run's threads
/// (`core_filters::smc::batch::PARALLEL_MIN_DIM`, 32): at 20 storeys (n = 81 for the MPF-EKF2,
/// 41 for the MLN-RBPF) one filter of 125 particles gives the same record, byte for byte but for
/// the timing, on 1, 2 and 7 threads.
#[test]
fn one_tall_filter_is_the_same_on_any_number_of_threads() {
    let (_tmp, dir) = temp_dir("blocks");
    let data = dir.join("d");
    ok(
        sysid()
            .args(["simulate", "--preset", "building-chain", "--storeys", "20"])
            .args([
                "--hysteretic",
                "1",
                "--duration",
                "0.6",
                "--seed",
                "2",
                "--out",
            ])
            .arg(&data)
            .output()
            .unwrap(),
        "simulate",
    );
    for alg in ["mpf-ekf2", "mln-rbpf"] {
        let records = on_threads(
            &dir,
            &data,
            alg,
            &["--algorithm", alg, "--particles", "125"],
        );
        assert!(
            records[0]["config"]["filter"]["pool"].is_null(),
            "{alg}: one filter"
        );
        assert!(
            records[0]["steps_completed"].as_u64().unwrap() > 100,
            "{alg}"
        );
        assert_eq!(records[0], records[1], "{alg}: 1 and 2 threads");
        assert_eq!(records[0], records[2], "{alg}: 1 and 7 threads");
    }
}

/// The held-out choice scores its candidates side by side: on field data of a linear building
/// the record (the choice's evidence with it) is the same, byte for byte but for the timing, on
/// 1, 2 and 7 threads, and `--threads 1` holds the choice to one thread too.
#[test]
fn the_held_out_choice_is_the_same_on_any_number_of_threads() {
    let (_tmp, dir) = temp_dir("choice-threads");
    let data = dir.join("d");
    ok(
        sysid()
            .args(["simulate", "--storeys", "3", "--hysteretic", "none"])
            .args(["--duration", "6", "--seed", "3", "--out"])
            .arg(&data)
            .output()
            .unwrap(),
        "simulate",
    );
    for f in ["dataset.json", "truth.csv"] {
        std::fs::remove_file(data.join(f)).unwrap();
    }
    let flags =
        "--algorithm mpf-ekf2 --storeys 3 --hysteretic none --masses 1 --measurement relative";
    let flags: Vec<&str> = flags.split(' ').collect();
    let records = on_threads(&dir, &data, "run", &flags);
    let held_out = &records[0]["plan"]["evidence"]["held_out"];
    assert!(
        held_out["candidates"]
            .as_array()
            .is_some_and(|c| c.len() >= 12),
        "the held-out choice ran: {held_out}"
    );
    assert_eq!(records[0], records[1], "1 and 2 threads");
    assert_eq!(records[0], records[2], "1 and 7 threads");
}
