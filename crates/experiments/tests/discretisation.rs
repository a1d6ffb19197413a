//! The discretisation study's machinery: the sweep's discretisation axis, the decimated data,
//! the take-over of records only for the same job (same fingerprint) and the statements the
//! study files declare.

use experiments::engine::Reuse;
use experiments::study::Study;
use experiments::verdict::scheme;
use models::filtering::Discretisation;

fn study(extra_data: &str, schemes: &str) -> Study {
    let text = format!(
        r#"
name = "t"
description = "test"
[data]
preset = "paper-3dof"
duration = 1.0
{extra_data}
[sweep]
algorithms = ["mln-rbpf", "mpf-ekf2"]
{schemes}
runs = 2
master_seed = 9
particles = [20]
[filter]
trace_every = 0
loop_every = 0
validate = false
"#
    );
    // The study names no file beside it: its directory can go once it is loaded.
    let dir = tempfile::Builder::new()
        .prefix("sysid-disc-")
        .tempdir()
        .unwrap();
    let path = dir.path().join("t.toml");
    std::fs::write(&path, text).unwrap();
    Study::load(&path).unwrap()
}

#[test]
fn the_axis_multiplies_the_jobs_and_reaches_the_settings() {
    let s = study("", r#"discretisations = ["euler", "symplectic"]"#);
    let jobs = s.jobs();
    assert_eq!(jobs.len(), 2 * 2 * 2);
    let ids: Vec<String> = jobs.iter().map(Study::job_id).collect();
    assert!(ids.contains(&"mln-rbpf-np20-systematic-run000".to_string()));
    assert!(ids.contains(&"mpf-ekf2-np20-systematic-symplectic-run001".to_string()));
    for j in &jobs {
        assert_eq!(s.settings(j).unwrap().discretisation, j.discretisation);
    }
    // Without the axis: the [filter] table's scheme, and the fingerprint of an Euler job is the
    // one of the same job in a study that names the axis.
    let plain = study("", "");
    assert!(plain
        .jobs()
        .iter()
        .all(|j| j.discretisation == Discretisation::Euler));
    assert_eq!(
        plain.job_fingerprint(&plain.jobs()[0]).unwrap(),
        s.job_fingerprint(&s.jobs()[0]).unwrap()
    );
}

#[test]
fn decimated_data_have_twice_the_step_and_their_own_fingerprint() {
    let full = study("", "");
    let half = study("decimate = 2", "");
    let (a, _) = full.data(None, 0).unwrap();
    let (b, _) = half.data(None, 0).unwrap();
    assert_eq!(b.dt, 2.0 * a.dt);
    assert_eq!(b.len(), a.len().div_ceil(2));
    assert_eq!(b.y(3), a.y(6));
    let job = &full.jobs()[0];
    assert_ne!(
        full.job_fingerprint(job).unwrap(),
        half.job_fingerprint(job).unwrap()
    );
    let r = half.run_job(job).unwrap();
    assert_eq!(r.steps_total, b.len() - 1);
}

#[test]
fn a_record_is_taken_over_only_for_the_same_job() {
    let s = study("", r#"discretisations = ["euler", "symplectic"]"#);
    let jobs = s.jobs();
    let euler = jobs
        .iter()
        .find(|j| j.discretisation == Discretisation::Euler)
        .unwrap();
    let symplectic = jobs
        .iter()
        .find(|j| j.discretisation == Discretisation::Symplectic && j.run == euler.run)
        .unwrap();
    let mut source = s.run_job(euler).unwrap();
    source.experiment = "fig7".into();
    let reuse = Reuse::new([&source]);
    let taken = reuse.run(&s, euler).unwrap();
    assert_eq!(reuse.taken(), 1);
    assert_eq!(taken.experiment, "t");
    assert_eq!(taken.theta_val, source.theta_val);
    let computed = reuse.run(&s, symplectic).unwrap();
    assert_eq!(reuse.taken(), 1, "a symplectic job is not the Euler record");
    assert_eq!(scheme(&computed), Some(Discretisation::Symplectic));
    assert_eq!(scheme(&taken), Some(Discretisation::Euler));
    // A different data set (decimated) with the same job is not taken over either.
    let half = study(
        "decimate = 2",
        r#"discretisations = ["euler", "symplectic"]"#,
    );
    reuse.run(&half, euler).unwrap();
    assert_eq!(reuse.taken(), 1);
}

#[test]
fn the_symplectic_regression_file_checks_the_symplectic_scheme() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../experiments/regression-symplectic.toml");
    let file = experiments::regression::RegressionFile::load(&path).unwrap();
    assert_eq!(file.study.filter.discretisation, Discretisation::Symplectic);
    assert!(file
        .study
        .jobs()
        .iter()
        .all(|j| file.study.settings(j).unwrap().discretisation == Discretisation::Symplectic));
    assert_eq!(file.thresholds.len(), 3);
}

#[test]
fn the_study_files_declare_the_section_statements() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../experiments");
    let at_200 = Study::load(&dir.join("discretisation.toml")).unwrap();
    let at_100 = Study::load(&dir.join("discretisation-100hz.toml")).unwrap();
    // Five per algorithm and the two goals; at 100 Hz two more per algorithm against 200 Hz.
    assert_eq!(at_200.verdicts.len(), 17);
    assert_eq!(at_100.verdicts.len(), 23);
    let against: Vec<_> = at_100
        .verdicts
        .iter()
        .filter_map(|v| v.against.as_deref())
        .collect();
    assert_eq!(against, ["discretisation"; 6]);
    assert!(at_200.verdicts.iter().all(|v| v.against.is_none()));
    // The dt·k/c band: half to 1.5 times dt·32 at each rate.
    let band = |s: &Study| s.verdicts[1].band.unwrap();
    assert_eq!(band(&at_200), [0.08, 0.24]);
    assert_eq!(band(&at_100), [0.16, 0.48]);
}
