//! Record readers and data-set directories: malformed input is rejected with an error naming
//! the file, the line and the field; a written directory loads back bit for bit (SPEC §2).

use models::dataset::{self, generate, load_dir, DatasetConfig, DatasetError};
use models::excitation::G;
use models::readers::{read_at2, read_csv, ReadError, Units};
use std::path::{Path, PathBuf};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

/// A fresh directory under the system temp dir, unique per test, and the guard that removes it
/// when dropped (also when the test panics).
fn scratch(name: &str) -> (tempfile::TempDir, PathBuf) {
    let tmp = tempfile::Builder::new()
        .prefix(&format!("models-readers-{name}-"))
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

/// The error's message names the file, `:<line>` and the field.
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

#[test]
fn fixtures_parse_to_the_same_record() {
    let a = read_at2(&fixture("nga_west2.AT2")).unwrap();
    let b = read_at2(&fixture("nga_old.AT2")).unwrap();
    let c = read_csv(&fixture("record.csv"), Units::G).unwrap();
    assert_eq!(a, b);
    assert_eq!(a.acc.len(), 7);
    assert_eq!(a.dt, 0.01);
    assert!((c.dt - 0.01).abs() < 1e-15);
    for (x, y) in a.acc.iter().zip(&c.acc) {
        assert!((x - y).abs() < 1e-15, "{x} vs {y}");
    }
    assert!((a.acc[4] + 0.005 * G).abs() < 1e-15);
}

#[test]
fn csv_reader_rejects_malformed_input() {
    let (_tmp, d) = scratch("csv");
    let missing = d.join("absent.csv");
    let e = read_csv(&missing, Units::G).unwrap_err();
    assert!(matches!(e, ReadError::Io { .. }));
    assert!(e.to_string().contains(&missing.display().to_string()));

    let cases: [(&str, &str, usize, &str); 6] = [
        ("columns.csv", "t,acc\n0,1\n0.01,2,3\n", 3, "3 columns"),
        ("text.csv", "t,acc\n0,1\n0.01,abc\n", 3, "acc"),
        ("nan.csv", "t,acc\n0,1\n0.01,NaN\n0.02,1\n", 3, "acc"),
        ("inf.csv", "0,1\ninf,2\n", 2, "t"),
        ("backwards.csv", "t,acc\n0,1\n0.02,2\n0.01,3\n", 4, "t"),
        (
            "gap.csv",
            "t,acc\n0,1\n0.01,2\n0.02,2\n0.05,3\n0.06,1\n",
            5,
            "t",
        ),
    ];
    for (name, text, line, field) in cases {
        let p = write(&d, name, text);
        let e = read_csv(&p, Units::G).unwrap_err();
        let msg = e.to_string();
        println!("{msg}");
        if field == "3 columns" {
            assert!(matches!(
                e,
                ReadError::ColumnCount {
                    line: 3,
                    found: 3,
                    ..
                }
            ));
            assert!(msg.contains(&format!("{}:{line}", p.display())), "{msg}");
        } else {
            assert_names(&msg, &p, line, field);
        }
    }
    let p = write(&d, "empty.csv", "t,acc\n\n");
    assert!(matches!(
        read_csv(&p, Units::G),
        Err(ReadError::Empty { .. })
    ));
    // Printed rounding of the times is tolerated.
    let p = write(&d, "rounded.csv", "0,1\n0.0133,2\n0.0267,3\n0.04,4\n");
    assert!((read_csv(&p, Units::MetersPerSecond2).unwrap().dt - 0.04 / 3.0).abs() < 1e-12);
}

#[test]
fn at2_reader_rejects_malformed_input() {
    let (_tmp, d) = scratch("at2");
    let missing = d.join("absent.AT2");
    assert!(read_at2(&missing)
        .unwrap_err()
        .to_string()
        .contains(&missing.display().to_string()));
    let head = "PEER\nEVENT\nACCELERATION TIME SERIES IN UNITS OF G\n";
    // A lying NPTS: the header promises 8 values, the file holds 7.
    let p = write(
        &d,
        "lying.AT2",
        &format!("{head}NPTS=    8, DT=   .0100 SEC\n 1 2 3 4 5\n 6 7\n"),
    );
    let e = read_at2(&p).unwrap_err();
    assert!(matches!(
        e,
        ReadError::NptsMismatch {
            declared: 8,
            found: 7,
            ..
        }
    ));
    assert_names(&e.to_string(), &p, 4, "NPTS");
    let p = write(
        &d,
        "text.AT2",
        &format!("{head}NPTS= 3, DT= .01 SEC\n 1 x 3\n"),
    );
    assert_names(&read_at2(&p).unwrap_err().to_string(), &p, 5, "value 2");
    let p = write(
        &d,
        "nan.AT2",
        &format!("{head}NPTS= 3, DT= .01 SEC\n 1 2\n NaN\n"),
    );
    assert_names(&read_at2(&p).unwrap_err().to_string(), &p, 6, "value 3");
    let p = write(
        &d,
        "dt.AT2",
        &format!("{head}NPTS= 3, DT= abc SEC\n 1 2 3\n"),
    );
    assert_names(&read_at2(&p).unwrap_err().to_string(), &p, 4, "DT");
    let p = write(&d, "header.AT2", &format!("{head}garbage\n 1 2 3\n"));
    assert_names(&read_at2(&p).unwrap_err().to_string(), &p, 4, "NPTS");
    let p = write(&d, "short.AT2", "PEER\nEVENT\n");
    assert!(matches!(read_at2(&p), Err(ReadError::Header { .. })));
}

fn short_dataset(seed: u64) -> dataset::Dataset {
    let mut c = DatasetConfig::from_preset("paper-3dof", seed).unwrap();
    c.duration = Some(3.0);
    generate(&c).unwrap()
}

#[test]
fn dataset_directory_round_trips_bit_exactly() {
    let ds = short_dataset(11);
    let (_tmp, d) = scratch("roundtrip");
    ds.write_dir(&d).unwrap();
    let header = std::fs::read_to_string(d.join("measured.csv")).unwrap();
    assert!(header.starts_with("t,ug,a1,a2,a3\n"));
    let header = std::fs::read_to_string(d.join("truth.csv")).unwrap();
    assert!(header.starts_with("t,ug,x1,x2,x3,v1,v2,v3,r1\n"));
    let loaded = load_dir(&d).unwrap();
    let want = ds.to_loaded();
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(loaded.dt.to_bits(), want.dt.to_bits());
    assert_eq!(bits(&loaded.t), bits(&want.t));
    assert_eq!(bits(&loaded.ug_meas), bits(&want.ug_meas));
    assert_eq!(bits(&loaded.y_meas), bits(&want.y_meas));
    let (lt, wt) = (loaded.truth.as_ref().unwrap(), want.truth.as_ref().unwrap());
    assert_eq!(bits(&lt.ug_clean), bits(&wt.ug_clean));
    assert_eq!(bits(lt.states.as_flat()), bits(wt.states.as_flat()));
    assert_eq!(lt.state_names, wt.state_names);
    assert_eq!(loaded, want);

    // Field data: only measured.csv.
    std::fs::remove_file(d.join("truth.csv")).unwrap();
    std::fs::remove_file(d.join("dataset.json")).unwrap();
    let field = load_dir(&d).unwrap();
    assert!(field.truth.is_none() && field.meta.is_none());
    assert_eq!(bits(&field.y_meas), bits(&want.y_meas));
    assert!((field.dt - ds.dt).abs() < 1e-12);
}

#[test]
fn dataset_loader_rejects_malformed_directories() {
    let (_tmp, d) = scratch("badload");
    let e = load_dir(&d).unwrap_err();
    assert!(e.to_string().contains("measured.csv"), "{e}");
    let m = write(&d, "measured.csv", "t,ug,a1\n0,0,0\n0.005,1,abc\n");
    assert_names(&load_dir(&d).unwrap_err().to_string(), &m, 3, "a1");
    // The header names the measured storeys: `a<s>`, s ≥ 1, once each, increasing.
    for (header, column) in [
        ("t,ug,a0", "a0"),
        ("t,ug,a3,a3", "a3"),
        ("t,ug,a3,a1", "a1"),
        ("t,ug,a01", "a01"),
        ("t,ug,x1", "x1"),
        ("t,u,a1", "u"),
    ] {
        let cols = header.split(',').count();
        let row = |t: &str| format!("{t}{}", ",0".repeat(cols - 1));
        let text = format!("{header}\n{}\n{}\n", row("0"), row("0.005"));
        let m = write(&d, "measured.csv", &text);
        assert_names(&load_dir(&d).unwrap_err().to_string(), &m, 1, column);
    }
    let m = write(&d, "measured.csv", "t,ug\n0,0\n0.005,1\n");
    assert_names(&load_dir(&d).unwrap_err().to_string(), &m, 1, "header");
    write(&d, "measured.csv", "t,ug,a2,a5\n0,0,0,0\n0.005,1,2,3\n");
    assert_eq!(load_dir(&d).unwrap().sensors, [2, 5]);
    let m = write(&d, "measured.csv", "t,ug,a1\n0,0,0\n0.005,1\n");
    assert!(load_dir(&d)
        .unwrap_err()
        .to_string()
        .contains(&format!("{}:3", m.display())));
    let m = write(&d, "measured.csv", "t,ug,a1\n0,0,0\n0.005,1,NaN\n");
    assert_names(&load_dir(&d).unwrap_err().to_string(), &m, 3, "a1");
    let m = write(&d, "measured.csv", "t,ug,a1\n0,0,0\n0.01,1,1\n0.005,1,1\n");
    assert_names(&load_dir(&d).unwrap_err().to_string(), &m, 4, "t");
    write(&d, "measured.csv", "t,ug,a1\n0,0,0\n0.005,1,1\n");
    let t = write(
        &d,
        "truth.csv",
        "t,ug,x1,v1,r1\n0,0,0,0,0\n0.005,1,zz,0,0\n",
    );
    assert_names(&load_dir(&d).unwrap_err().to_string(), &t, 3, "x1");
    write(&d, "truth.csv", "t,ug,x1,v1,r1\n0,0,0,0,0\n0.005,1,0,0,0\n");
    let j = write(&d, "dataset.json", "{ \"config\": 3 ");
    let e = load_dir(&d).unwrap_err();
    assert!(matches!(e, DatasetError::Json { line: 1, .. }));
    assert!(e.to_string().contains(&j.display().to_string()));
}
