//! The scaling study: the structure axis of a study (jobs, ids, checks, quick form), the
//! committed `experiments/scaling.toml`, and a small study run end to end (records, cells,
//! figures, report) and resumed.

use std::path::{Path, PathBuf};

use experiments::engine::RunMode;
use experiments::scaling::{self, Options};
use experiments::study::Study;
use identify::figures::validate_svg;
use identify::pipeline::Algorithm;

/// A fresh directory under the system temp dir, unique per test, and the guard that removes it
/// when dropped (also when the test panics).
fn temp_dir(tag: &str) -> (tempfile::TempDir, PathBuf) {
    let tmp = tempfile::Builder::new()
        .prefix(&format!("sysid-scaling-{tag}-"))
        .tempdir()
        .unwrap();
    let d = tmp.path().to_path_buf();
    (tmp, d)
}

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

const SMALL: &str = r#"
name = "small-scaling"
description = "scaling test"
[data]
preset = "shear-chain"
duration = 1.0
[sweep]
algorithms = ["mln-rbpf", "mpf-ekf2", "bootstrap"]
runs = 2
master_seed = 7
particles = [30]
[filter]
trace_every = 0
loop_every = 0
validate = false
[quick]
runs = 1
particles = 20
duration = 0.5

[[sweep.structures]]
label = "n2"
storeys = 2

[[sweep.structures]]
label = "n4"
storeys = 4
duration = 0.5
algorithms = ["mln-rbpf", "mpf-ekf2"]
runs = 1

[[sweep.structures]]
label = "n4-sparse"
storeys = 4
sensors = [3, 4]
"#;

fn write_study(dir: &Path, text: &str) -> PathBuf {
    let p = dir.join("study.toml");
    std::fs::write(&p, text).unwrap();
    p
}

#[test]
fn structure_axis_jobs_ids_and_configs() {
    let (_tmp, dir) = temp_dir("axis");
    let study = Study::load(&write_study(&dir, SMALL)).unwrap();
    let jobs = study.jobs();
    // Run 0: n2 × 3 algorithms, n4 × 2, n4-sparse × 3; run 1: n2 × 3, n4-sparse × 3.
    assert_eq!(jobs.len(), 3 + 2 + 3 + 3 + 3);
    assert!(jobs[..8].iter().all(|j| j.run == 0));
    assert!(jobs
        .iter()
        .all(|j| !(j.structure == Some(1) && (j.run > 0 || j.algorithm == Algorithm::Bootstrap))));
    assert_eq!(
        study.record_id(&jobs[3]),
        "n4-mln-rbpf-np30-systematic-run000"
    );
    let c = study.structure_config(Some(1), 0).unwrap();
    assert_eq!((c.storeys, c.duration), (Some(4), Some(0.5)));
    assert_eq!(
        study.structure_config(Some(0), 1).unwrap().duration,
        Some(1.0)
    );
    // A sparse layout reaches the data configuration (the filters then see only those sensors).
    let sparse = study.structure_config(Some(2), 0).unwrap();
    assert_eq!(sparse.sensors, Some(vec![3, 4]));
    assert_eq!(sparse.storeys, Some(4));
    // The quick form caps every structure's runs and duration.
    let q = study.quick();
    assert!(q.sweep.structures.iter().all(|s| s.runs == Some(1)));
    assert!(q.sweep.structures.iter().all(|s| s.duration == Some(0.5)));
    assert_eq!(q.jobs().len(), 3 + 2 + 3);
}

#[test]
fn bad_structures_are_named() {
    let (_tmp, dir) = temp_dir("bad");
    for (bad, needle) in [
        ("sensors = [0, 4]", "field `sensors`: storey 0"),
        ("sensors = [4, 4]", "field `sensors` repeats"),
        ("hysteretic = [5]", "field `hysteretic`: storey 5"),
        ("sensors = []", "field `sensors` is empty"),
        ("runs = 3", "field `runs`"),
        ("algorithms = [\"storvik\"]", "algorithm `storvik`"),
        ("duration = -1.0", "field `duration`"),
    ] {
        let text = SMALL.replace("sensors = [3, 4]", bad);
        let err = format!("{:#}", Study::load(&write_study(&dir, &text)).unwrap_err());
        assert!(
            err.contains(needle) && err.contains("n4-sparse") && err.contains("study.toml"),
            "{bad}: {err}"
        );
    }
    let twice = SMALL.replace("label = \"n4\"", "label = \"n2\"");
    let err = format!("{:#}", Study::load(&write_study(&dir, &twice)).unwrap_err());
    assert!(err.contains("`n2` appears twice"), "{err}");
    let label = SMALL.replace("label = \"n4\"", "label = \"n 4\"");
    let err = format!("{:#}", Study::load(&write_study(&dir, &label)).unwrap_err());
    assert!(err.contains("label"), "{err}");
}

/// A structure's `filter` keys reach its runs only, over the study's `[filter]`; a key the
/// settings do not know, or a value out of range, is an error naming the structure.
#[test]
fn a_structure_takes_its_own_filter_keys() {
    let (_tmp, dir) = temp_dir("structure-filter");
    let text = SMALL.replace(
        "label = \"n4\"\n",
        "label = \"n4\"\nfilter = { pool = 2, marginal_prior = { kind = \"per_particle\", rel_sd = 0.2 } }\n",
    );
    let study = Study::load(&write_study(&dir, &text)).unwrap();
    for job in study.jobs() {
        let s = study.settings(&job).unwrap();
        if job.structure == Some(1) {
            assert_eq!(s.pool, 2);
            assert_eq!(
                s.marginal_prior,
                models::filtering::MarginalPrior::PerParticle { rel_sd: 0.2 }
            );
        } else {
            let mut e = study.filter_of(job.algorithm).unwrap();
            e.particles = job.particles;
            e.resampling = job.resampling;
            e.discretisation = job.discretisation;
            assert_eq!(s, e);
        }
        // The trace settings of the study's table stay.
        assert_eq!((s.trace_every, s.validate), (0, false));
    }
    // The fingerprints of the structure's runs see its settings.
    let plain = Study::load(&write_study(&dir, SMALL)).unwrap();
    let j = study.jobs()[3].clone();
    assert_eq!(j.structure, Some(1));
    assert_ne!(
        study.job_fingerprint(&j).unwrap(),
        plain.job_fingerprint(&j).unwrap()
    );
    for (bad, needle) in [
        ("filter = { pools = 2 }", "pools"),
        ("filter = { pool = 0 }", "pool"),
        ("filter = { ess_threshold = 2.0 }", "ess_threshold"),
        // Set for every job by the sweep's axes: refused, not silently overwritten.
        ("filter = { particles = 4000 }", "sweep.particles"),
        (
            "filter = { discretisation = \"euler\" }",
            "sweep.discretisations",
        ),
    ] {
        let text = SMALL.replace("label = \"n4\"\n", &format!("label = \"n4\"\n{bad}\n"));
        let err = format!("{:#}", Study::load(&write_study(&dir, &text)).unwrap_err());
        assert!(
            err.contains(needle) && err.contains("`n4`") && err.contains("field `filter`"),
            "{bad}: {err}"
        );
    }
}

/// `experiments/scaling-defaults.toml` runs, on every building, what `sysid filter` uses there
/// without a config, on the data sets of `experiments/scaling.toml`.
#[test]
fn the_defaults_study_runs_the_settings_of_sysid_filter() {
    use identify::pipeline::FilterSettings;
    let study = Study::load(&workspace().join("experiments/scaling-defaults.toml")).unwrap();
    let scaling = Study::load(&workspace().join("experiments/scaling.toml")).unwrap();
    assert_eq!(study.sweep.algorithms, vec![Algorithm::MpfEkf2]);
    let jobs = study.jobs();
    for n in [3, 5, 10, 20, 40] {
        assert!(
            jobs.iter()
                .any(|j| study.sweep.structures[j.structure.unwrap()].storeys == n),
            "{n} storeys"
        );
    }
    for job in &jobs {
        let st = &study.sweep.structures[job.structure.unwrap()];
        let mut expected = FilterSettings::recommended_for(job.algorithm, st.storeys, &[]);
        expected.trace_every = 0;
        expected.loop_every = 0;
        expected.validate = false;
        assert_eq!(study.settings(job).unwrap(), expected, "{}", st.label);
        // The same data set as the scaling study's run of that building.
        let i = scaling
            .sweep
            .structures
            .iter()
            .position(|s| s.label == st.label)
            .unwrap();
        assert_eq!(
            study.structure_config(job.structure, job.run).unwrap(),
            scaling.structure_config(Some(i), job.run).unwrap(),
            "{}",
            st.label
        );
    }
}

#[test]
fn the_committed_study_loads() {
    let study = Study::load(&workspace().join("experiments/scaling.toml")).unwrap();
    let labels: Vec<&str> = study
        .sweep
        .structures
        .iter()
        .map(|s| s.label.as_str())
        .collect();
    for n in [3, 5, 10, 20, 40] {
        assert!(labels.contains(&format!("n{n}-base-all").as_str()));
        assert!(labels.contains(&format!("n{n}-base-sparse").as_str()));
    }
    for s in &study.sweep.structures {
        // ≥ 10 runs per cell, ≥ 5 at 40 storeys; the bootstrap PF up to 10 storeys; a shorter
        // record from 20 storeys on.
        let runs = s.runs.unwrap_or(study.sweep.runs);
        assert!(runs >= if s.storeys >= 40 { 5 } else { 10 }, "{}", s.label);
        let algs = s.algorithms.as_ref().unwrap_or(&study.sweep.algorithms);
        assert_eq!(
            algs.contains(&Algorithm::Bootstrap),
            s.storeys <= 10,
            "{}",
            s.label
        );
        assert_eq!(s.duration.is_some(), s.storeys >= 20, "{}", s.label);
        if s.label.contains("three") {
            assert!(s.storeys >= 10);
            assert_eq!(s.hysteretic.as_deref(), Some(&[1, 2, 3][..]));
        }
        if let Some(sensors) = &s.sensors {
            let mut every_third: Vec<usize> = (3..=s.storeys).step_by(3).collect();
            if every_third.last() != Some(&s.storeys) {
                every_third.push(s.storeys);
            }
            assert_eq!(sensors, &every_third, "{}", s.label);
        }
    }
    assert_eq!(study.sweep.particles, vec![500]);
    // Buildings with realistic periods (docs/scaling.md), identified with the symplectic
    // discretisation (forward Euler is unstable at their stiffness and dt).
    assert_eq!(study.data.preset, "building-chain");
    assert_eq!(
        study.filter.discretisation,
        models::filtering::Discretisation::Symplectic
    );
    // Every structure's excitation is scaled so that its base element yields strongly: about
    // 0.8 of saturation for the base family, at least 0.65 for every element of the others.
    let values = scaling::structures::structure_values(&study).unwrap();
    for (s, v) in study.sweep.structures.iter().zip(&values) {
        assert!(s.scale.is_some(), "{}: no scale", s.label);
        assert!(
            (0.2..=4.0).contains(&v.t1) && (0.1 * s.storeys as f64 - v.t1).abs() < 0.2 * v.t1,
            "{}: T1 = {}",
            s.label,
            v.t1
        );
        assert!((v.zeta1 - 0.02).abs() < 1e-9, "{}", s.label);
        for &(storey, ratio) in &v.yielding {
            let lo = if s.label.contains("base") { 0.75 } else { 0.65 };
            assert!(
                (lo..0.95).contains(&ratio),
                "{}: storey {storey}: max|r|/saturation = {ratio}",
                s.label
            );
        }
    }
}

#[test]
fn small_study_end_to_end_and_resumed() {
    let (_tmp, dir) = temp_dir("e2e");
    let config = write_study(&dir, SMALL);
    let out = dir.join("out");
    let opts = Options {
        config,
        out: out.clone(),
        mode: RunMode::quiet(2),
        report_only: false,
    };
    let cells = scaling::run(&opts).unwrap();
    // n2: 3 algorithms, n4: 2, n4-sparse: 3.
    assert_eq!(cells.len(), 8);
    let n2: Vec<_> = cells.iter().filter(|c| c.structure == "n2").collect();
    assert!(n2
        .iter()
        .all(|c| c.runs == 2 && c.runs_planned == 2 && c.steps == 200));
    let mpf = n2.iter().find(|c| c.algorithm == "mpf-ekf2").unwrap();
    assert_eq!((mpf.sampled_dim, mpf.marginalised_dim), (3, 9));
    assert!(mpf.us_per_particle_step > 0.0 && mpf.k_error_mean.is_finite());
    // Coverage of the 95 % intervals of k and c: two runs × 4 storey parameters.
    assert_eq!(mpf.coverage_pairs, 8);
    assert!((0.0..=1.0).contains(&mpf.coverage95_kc));
    // The sparse layout runs (two sensors, so the filters see two channels).
    assert!(cells
        .iter()
        .filter(|c| c.structure == "n4-sparse")
        .all(|c| c.runs > 0 && c.runs == c.runs_planned && c.k_error_mean.is_finite()));
    for f in ["cost_vs_dimension.svg", "accuracy_vs_storeys.svg"] {
        validate_svg(&out.join(f)).unwrap();
    }
    let csv = std::fs::read_to_string(out.join("cells.csv")).unwrap();
    assert_eq!(csv.lines().count(), 1 + 8);
    assert!(csv.starts_with(scaling::CSV_HEADER));
    let report = std::fs::read_to_string(out.join("REPORT.md")).unwrap();
    assert!(report.contains("## Beyond the paper: larger structures"));
    assert!(report.contains("does no longer scale with the dimension of the problem"));
    assert!(!report.contains("**Incomplete"), "complete study");
    // Every structure of the axis is generated: nothing is listed as not run.
    assert!(
        !report.contains("which this build does not have"),
        "{report}"
    );
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["cells"].as_array().unwrap().len(), 8);
    // Resumed: every record is reused, the cells are the same but for the timings.
    let again = scaling::run(&Options {
        mode: RunMode {
            resume: true,
            ..opts.mode
        },
        ..opts.clone()
    })
    .unwrap();
    for (a, b) in cells.iter().zip(&again) {
        assert_eq!(
            (a.runs, a.failed, a.k_error_mean.to_bits()),
            (b.runs, b.failed, b.k_error_mean.to_bits())
        );
    }
    // Report only: a removed record is a run not run, nothing is computed.
    let gone = out.join("records/n2-mln-rbpf-np30-systematic-run001.json");
    std::fs::remove_file(&gone).unwrap();
    let partial = scaling::run(&Options {
        report_only: true,
        ..opts.clone()
    })
    .unwrap();
    assert!(!gone.exists());
    let mln = partial
        .iter()
        .find(|c| c.structure == "n2" && c.algorithm == "mln-rbpf")
        .unwrap();
    assert_eq!((mln.runs, mln.runs_planned), (1, 2));
    let report = std::fs::read_to_string(out.join("REPORT.md")).unwrap();
    assert!(
        report.contains("`n2` MLN-RBPF: 1 of 2 planned runs"),
        "{report}"
    );
    // n2: 3 × 2, n4: 2 × 1, n4-sparse: 3 × 2 planned; one record removed.
    assert!(
        report.contains("**Incomplete: 13 of the 14 planned runs have a record.**"),
        "{report}"
    );
    // Report only on records of other inputs (here: another seed): none is used, and the error
    // says why instead of failing on a figure with no cell.
    let other = dir.join("other-seed.toml");
    let text = std::fs::read_to_string(&opts.config).unwrap();
    assert!(text.contains("master_seed = 7"));
    std::fs::write(
        &other,
        text.replacen("master_seed = 7", "master_seed = 8", 1),
    )
    .unwrap();
    let e = scaling::run(&Options {
        config: other,
        report_only: true,
        ..opts.clone()
    })
    .unwrap_err();
    let msg = format!("{e:#}");
    assert!(
        msg.contains("none of the 14 runs") && msg.contains("without --report-only"),
        "{msg}"
    );
}
