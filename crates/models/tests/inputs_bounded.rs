//! Bounded inputs and data-set integrity: every input that once panicked, aborted or was
//! accepted wrongly is now a clear error naming the file, the line and the field; mismatched
//! data-set files are refused by name; a data set is never destroyed by a rewrite.

use models::dataset::{self, generate, load_dir, DatasetConfig, DatasetError, ExcitationSource};
use models::limits;
use models::readers::{read_at2, read_csv, ReadError, Units};
use std::path::{Path, PathBuf};

/// A fresh directory under the system temp dir, unique per test, and the guard that removes it
/// when dropped (also when the test panics).
fn scratch(name: &str) -> (tempfile::TempDir, PathBuf) {
    let tmp = tempfile::Builder::new()
        .prefix(&format!("models-inputs-{name}-"))
        .tempdir()
        .unwrap();
    let dir = tmp.path().to_path_buf();
    (tmp, dir)
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

/// The message names `file:line` and the field.
fn assert_names(msg: &str, file: &Path, line: usize, field: &str) {
    let f = file.display().to_string();
    assert!(
        msg.contains(&format!("{f}:{line}")),
        "`{msg}` lacks {f}:{line}"
    );
    assert!(
        msg.contains(&format!("`{field}`")),
        "`{msg}` lacks field {field}"
    );
}

const AT2_HEAD: &str = "PEER\nEVENT\nACCELERATION TIME SERIES IN UNITS OF G\n";

#[test]
fn at2_huge_npts_and_dt_are_errors() {
    let (_tmp, d) = scratch("at2");
    // NPTS= 1e30 once overflowed a capacity (panic), NPTS= 1e12 asked for 8 TB (abort).
    for npts in ["1e30", "1e12", "10000001"] {
        let p = write(
            &d,
            "huge.AT2",
            &format!("{AT2_HEAD}NPTS= {npts}, DT= .0050 SEC\n .1 .2\n"),
        );
        let e = read_at2(&p).unwrap_err();
        assert!(matches!(e, ReadError::Limit { line: 4, .. }), "{e}");
        assert_names(&e.to_string(), &p, 4, "NPTS");
    }
    // The old header form too.
    let p = write(
        &d,
        "old.AT2",
        &format!("{AT2_HEAD} 1e30   .0050   NPTS, DT\n .1\n"),
    );
    assert_names(&read_at2(&p).unwrap_err().to_string(), &p, 4, "NPTS");
    for dt in ["1e6", "1e-9", "2"] {
        let p = write(
            &d,
            "dt.AT2",
            &format!("{AT2_HEAD}NPTS= 2, DT= {dt} SEC\n .1 .2\n"),
        );
        let e = read_at2(&p).unwrap_err();
        assert_names(&e.to_string(), &p, 4, "DT");
    }
    // More values than NPTS are counted, not stored.
    let p = write(
        &d,
        "extra.AT2",
        &format!("{AT2_HEAD}NPTS= 2, DT= .01\n .1 .2 .3\n"),
    );
    assert!(matches!(
        read_at2(&p),
        Err(ReadError::NptsMismatch {
            declared: 2,
            found: 3,
            ..
        })
    ));
}

#[test]
fn excitation_csv_times_are_bounded() {
    let (_tmp, d) = scratch("csvtimes");
    // A time of 1e300 or 1e7 once made the resampling allocate without bound.
    for (name, text, line) in [
        ("t1e300.csv", "t,acc\n0,0.1\n1e300,0.2\n", 3),
        ("t1e7.csv", "t,acc\n0,0.1\n1e7,0.2\n", 3),
        ("tiny.csv", "t,acc\n0,0.1\n1e-9,0.2\n", 3),
        ("late.csv", "t,acc\n1e300,0.1\n1e300,0.2\n", 2),
    ] {
        let p = write(&d, name, text);
        let e = read_csv(&p, Units::G).unwrap_err();
        assert_names(&e.to_string(), &p, line, "t");
        // And through data generation, the path `simulate --excitation FILE` takes.
        let mut c = DatasetConfig::from_preset("paper-3dof", 1).unwrap();
        c.excitation = ExcitationSource::Csv {
            path: p.clone(),
            units: Units::G,
        };
        c.duration = None;
        let e = generate(&c).unwrap_err();
        assert!(e.to_string().contains(&p.display().to_string()), "{e}");
    }
    // Huge accelerations: finite, but g × 1e308 would be ∞.
    let p = write(&d, "acc.csv", "t,acc\n0,1e308\n0.01,0.2\n");
    assert_names(
        &read_csv(&p, Units::G).unwrap_err().to_string(),
        &p,
        2,
        "acc",
    );
}

#[test]
fn a_resampled_record_is_bounded_before_allocation() {
    let (_tmp, d) = scratch("resample");
    // 2 samples 1 s apart are valid; resampled at dt = 1e-5 s with a 1e5 s duration... the
    // record spans 1 s, so ask for a record spanning the maximum at the coarsest step.
    let n = 60_000;
    let mut text = String::from("t,acc\n");
    for k in 0..n {
        text.push_str(&format!("{},{}\n", k as f64, 0.1));
    }
    let p = write(&d, "long.csv", &text);
    let mut c = DatasetConfig::from_preset("paper-3dof", 1).unwrap();
    c.excitation = ExcitationSource::Csv {
        path: p,
        units: Units::G,
    };
    c.duration = None;
    c.dt = 0.001; // 6e7 samples > MAX_SAMPLES
    let e = generate(&c).unwrap_err();
    assert!(
        matches!(e, DatasetError::InvalidConfig { field: "dt", .. }),
        "{e}"
    );
}

#[test]
fn generation_settings_are_bounded() {
    let base = DatasetConfig::from_preset("paper-3dof", 1).unwrap();
    type Change = Box<dyn Fn(&mut DatasetConfig)>;
    let cases: [(&str, Change); 8] = [
        ("noise_fraction", Box::new(|c| c.noise_fraction = 1e308)),
        ("noise_fraction", Box::new(|c| c.noise_fraction = -0.1)),
        ("storeys", Box::new(|c| c.storeys = Some(1_000_000_000))),
        ("storeys", Box::new(|c| c.storeys = Some(usize::MAX))),
        ("duration", Box::new(|c| c.duration = Some(1e12))),
        ("duration", Box::new(|c| c.duration = Some(f64::INFINITY))),
        ("scale", Box::new(|c| c.scale = 1e300)),
        ("dt", Box::new(|c| c.dt = 1e6)),
    ];
    for (field, set) in cases {
        let mut c = base.clone();
        set(&mut c);
        match generate(&c) {
            Err(DatasetError::InvalidConfig { field: f, .. }) => assert_eq!(f, field),
            other => panic!("{field}: {other:?}"),
        }
    }
    // Huge synthetic records (Kanai–Tajimi, harmonic) are bounded too.
    let mut c = DatasetConfig::from_preset("paper-3dof-harmonic", 1).unwrap();
    c.duration = Some(limits::max_duration(c.dt) * 2.0);
    assert!(matches!(
        generate(&c),
        Err(DatasetError::InvalidConfig {
            field: "duration",
            ..
        })
    ));
    // A sign flip is a valid scale.
    let mut c = base.clone();
    c.scale = -1.0;
    c.duration = Some(0.5);
    let flipped = generate(&c).unwrap();
    c.scale = 1.0;
    let plain = generate(&c).unwrap();
    assert_eq!(flipped.ug_clean[10], -plain.ug_clean[10]);
    // 200 storeys (the limit) for a short record: allowed.
    let mut c = DatasetConfig::from_preset("shear-chain", 1).unwrap();
    c.storeys = Some(limits::MAX_STOREYS);
    c.duration = Some(0.05);
    assert_eq!(generate(&c).unwrap().channels(), 200);
}

fn short(seed: u64) -> dataset::Dataset {
    let mut c = DatasetConfig::from_preset("paper-3dof", seed).unwrap();
    c.duration = Some(1.0);
    generate(&c).unwrap()
}

#[test]
fn measured_values_beyond_the_limit_name_file_line_and_column() {
    let (_tmp, d) = scratch("huge-values");
    let m = write(&d, "measured.csv", "t,ug,a1\n0,0,0\n0.005,1,1e308\n");
    // Once reported downstream as "rms_v1: inf" with no file.
    let e = load_dir(&d).unwrap_err().to_string();
    assert_names(&e, &m, 3, "a1");
    let m = write(&d, "measured.csv", "t,ug,a1\n0,0,0\n1e300,1,1\n");
    assert_names(&load_dir(&d).unwrap_err().to_string(), &m, 3, "t");
}

#[test]
fn a_byte_order_mark_is_accepted() {
    let (_tmp, d) = scratch("bom");
    short(3).write_dir(&d.join("ds")).unwrap();
    let ds = d.join("ds");
    let want = load_dir(&ds).unwrap();
    // Field data with a BOM (no dataset.json, so no digests to disagree with).
    let text = std::fs::read_to_string(ds.join("measured.csv")).unwrap();
    let field = d.join("field");
    std::fs::create_dir_all(&field).unwrap();
    write(&field, "measured.csv", &format!("\u{feff}{text}"));
    let got = load_dir(&field).unwrap();
    assert_eq!(got.y_meas, want.y_meas);
    let p = write(&d, "bom.csv", "\u{feff}t,acc\n0,0.1\n0.01,0.2\n");
    assert_eq!(read_csv(&p, Units::G).unwrap().acc.len(), 2);
    let p = write(
        &d,
        "bom.AT2",
        &format!("\u{feff}{AT2_HEAD}NPTS= 2, DT= .01\n .1 .2\n"),
    );
    assert_eq!(read_at2(&p).unwrap().acc.len(), 2);
}

/// Replaces `"key": [...]` (the first occurrence) in a JSON text.
fn set_json(text: &str, key: &str, value: &str) -> String {
    let mut v: serde_json::Value = serde_json::from_str(text).unwrap();
    let mut cur = &mut v;
    let parts: Vec<&str> = key.split('.').collect();
    for p in &parts[..parts.len() - 1] {
        cur = cur.get_mut(*p).unwrap();
    }
    cur[parts[parts.len() - 1]] = serde_json::from_str(value).unwrap();
    serde_json::to_string_pretty(&v).unwrap()
}

#[test]
fn malformed_metadata_is_a_clear_error() {
    let (_tmp, d) = scratch("meta");
    let ds = d.join("ds");
    short(4).write_dir(&ds).unwrap();
    let j = ds.join("dataset.json");
    let good = std::fs::read_to_string(&j).unwrap();
    // `"vel": []` once indexed out of bounds in the filter.
    let cases = [
        ("rms.vel", "[]", "rms.vel"),
        ("rms.acc", "[1.0]", "rms.acc"),
        ("noise.acc_sd", "[1, 2, 3, 4]", "noise.acc_sd"),
        ("theta_true", "[1.0]", "theta_true"),
        ("bouc_wen_storeys", "[7]", "bouc_wen_storeys"),
        ("config.storeys", "1000000000", "config.storeys"),
        ("config.preset", "\"tower\"", "preset"),
        ("storeys", "2", "storeys"),
        ("samples", "7", "samples"),
        ("structure.hysteretic", "[1, 4]", "structure.hysteretic"),
        ("structure.sensors", "[1, 1]", "structure.sensors"),
        ("structure.masses", "[1.0, 1.0]", "structure.masses"),
        ("structure.sensors", "[1, 2]", "structure"),
        ("dt", "1e6", "dt"),
        ("rms.ug", "-1.0", "rms.ug"),
        ("noise.fraction", "1e308", "noise.fraction"),
        ("state_names", "[\"x1\"]", "state_names"),
    ];
    for (key, value, field) in cases {
        std::fs::write(&j, set_json(&good, key, value)).unwrap();
        let e = load_dir(&ds).unwrap_err();
        let msg = e.to_string();
        assert!(msg.contains(&j.display().to_string()), "{key}: {msg}");
        assert!(msg.contains(&format!("`{field}`")), "{key}: {msg}");
    }
    // Syntax and type errors name the file, line and column.
    std::fs::write(&j, good.replace("\"samples\": 201", "\"samples\": -5")).unwrap();
    let e = load_dir(&ds).unwrap_err();
    assert!(matches!(e, DatasetError::Json { .. }), "{e}");
    assert!(e.to_string().contains(&j.display().to_string()));
    std::fs::write(&j, &good).unwrap();
    load_dir(&ds).unwrap();
}

#[test]
fn files_of_different_data_sets_are_refused_by_name() {
    let (_tmp, d) = scratch("mixed");
    let (one, two) = (d.join("seed1"), d.join("seed2"));
    short(1).write_dir(&one).unwrap();
    short(2).write_dir(&two).unwrap();
    // seed-2 measured.csv with seed-1 metadata: same size, different content.
    let mixed = d.join("mixed");
    std::fs::create_dir_all(&mixed).unwrap();
    for f in ["truth.csv", "dataset.json"] {
        std::fs::copy(one.join(f), mixed.join(f)).unwrap();
    }
    std::fs::copy(two.join("measured.csv"), mixed.join("measured.csv")).unwrap();
    let e = load_dir(&mixed).unwrap_err();
    assert!(matches!(e, DatasetError::Checksum { .. }), "{e}");
    let msg = e.to_string();
    assert!(
        msg.starts_with(&mixed.join("measured.csv").display().to_string()),
        "{msg}"
    );
    // The truth of another seed: the same truth (it does not depend on the seed), so it
    // belongs; the truth of another duration does not.
    std::fs::copy(one.join("measured.csv"), mixed.join("measured.csv")).unwrap();
    load_dir(&mixed).unwrap();
    let mut c = DatasetConfig::from_preset("paper-3dof", 1).unwrap();
    c.duration = Some(1.5);
    generate(&c).unwrap().write_dir(&d.join("long")).unwrap();
    std::fs::copy(d.join("long/truth.csv"), mixed.join("truth.csv")).unwrap();
    let msg = load_dir(&mixed).unwrap_err().to_string();
    assert!(
        msg.starts_with(&mixed.join("truth.csv").display().to_string()),
        "{msg}"
    );
    // A recorded file that is missing.
    std::fs::remove_file(mixed.join("truth.csv")).unwrap();
    let msg = load_dir(&mixed).unwrap_err().to_string();
    assert!(
        msg.contains("truth.csv") && msg.contains("missing"),
        "{msg}"
    );
}

#[test]
fn data_sets_without_digests_and_field_data_still_load() {
    let (_tmp, d) = scratch("older");
    let ds = d.join("ds");
    short(5).write_dir(&ds).unwrap();
    let j = ds.join("dataset.json");
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&j).unwrap()).unwrap();
    assert!(v.get("files").is_some());
    v.as_object_mut().unwrap().remove("files");
    std::fs::write(&j, serde_json::to_string_pretty(&v).unwrap()).unwrap();
    let older = load_dir(&ds).unwrap();
    assert_eq!(older, short(5).to_loaded());
    std::fs::remove_file(ds.join("truth.csv")).unwrap();
    std::fs::remove_file(&j).unwrap();
    let field = load_dir(&ds).unwrap();
    assert!(field.meta.is_none() && field.truth.is_none());
}

#[test]
fn rewriting_replaces_a_data_set_and_never_deletes_other_files() {
    let (_tmp, d) = scratch("rewrite");
    let ds = d.join("ds");
    short(1).write_dir(&ds).unwrap();
    short(2).write_dir(&ds).unwrap();
    assert_eq!(load_dir(&ds).unwrap().meta.unwrap().seed, 2);
    // Nothing is left beside it.
    let names: Vec<String> = std::fs::read_dir(&d)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(names, vec!["ds".to_string()]);
    // A directory with other files is refused and left as it was.
    let other = d.join("other");
    std::fs::create_dir_all(&other).unwrap();
    write(&other, "notes.txt", "keep me");
    let e = short(3).write_dir(&other).unwrap_err();
    assert!(matches!(e, DatasetError::NotADataset { .. }), "{e}");
    assert!(e.to_string().contains("notes.txt"), "{e}");
    assert_eq!(
        std::fs::read_to_string(other.join("notes.txt")).unwrap(),
        "keep me"
    );
    assert!(!other.join("measured.csv").exists());
    // So is a file.
    let f = write(&d, "file", "x");
    assert!(matches!(
        short(3).write_dir(&f),
        Err(DatasetError::NotADataset { .. })
    ));
    // An empty directory is filled.
    let empty = d.join("empty");
    std::fs::create_dir_all(&empty).unwrap();
    short(3).write_dir(&empty).unwrap();
    load_dir(&empty).unwrap();
}

#[test]
fn leftovers_of_killed_writers_are_removed() {
    let (_tmp, d) = scratch("leftovers");
    let ds = d.join("ds");
    short(1).write_dir(&ds).unwrap();
    // A process id above the kernel's maximum (2^22) is never alive.
    let dead_tmp = d.join(".ds.tmp-99999999-1");
    let dead_old = d.join(".ds.old-99999999-1");
    for p in [&dead_tmp, &dead_old] {
        std::fs::create_dir_all(p).unwrap();
        write(p, "measured.csv", "partial");
    }
    short(2).write_dir(&ds).unwrap();
    if cfg!(target_os = "linux") {
        assert!(!dead_tmp.exists() && !dead_old.exists());
    }
    // When the data set itself is gone, a copy left aside is kept and named by the loader.
    std::fs::remove_dir_all(&ds).unwrap();
    std::fs::create_dir_all(&dead_old).unwrap();
    let e = load_dir(&ds).unwrap_err().to_string();
    assert!(e.contains(&dead_old.display().to_string()), "{e}");
}
