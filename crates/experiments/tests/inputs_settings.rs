//! Filter and study settings that were never checked (θ_val = 0 from `window = 0`, negative
//! stiffnesses from a filter noise fraction of 1e-9, aborts from huge sizes) are errors naming
//! the file and the field.

use experiments::study::Study;
use identify::limits::{check_particle_cloud, load_filter_settings, MAX_PARTICLES};
use std::path::{Path, PathBuf};

/// A fresh directory under the system temp dir, unique per test, and the guard that removes it
/// when dropped (also when the test panics).
fn temp_dir(tag: &str) -> (tempfile::TempDir, PathBuf) {
    let tmp = tempfile::Builder::new()
        .prefix(&format!("sysid-settings-{tag}-"))
        .tempdir()
        .unwrap();
    let d = tmp.path().to_path_buf();
    (tmp, d)
}

fn load_err(dir: &Path, text: &str) -> (PathBuf, String) {
    let p = dir.join("filter.toml");
    std::fs::write(&p, text).unwrap();
    let e = load_filter_settings(&p).unwrap_err();
    (p, format!("{e:#}"))
}

#[test]
fn filter_settings_out_of_range_are_named() {
    let (_tmp, dir) = temp_dir("filter");
    for (text, field) in [
        ("window = 0\n", "`window`"),
        ("noise_fraction = 1e-9\n", "`noise_fraction`"),
        ("noise_fraction = 1e308\n", "`noise_fraction`"),
        ("particles = 0\n", "`particles`"),
        ("particles = 100000000000\n", "`particles`"),
        ("ess_threshold = 2.0\n", "`ess_threshold`"),
        ("substeps = 0\n", "`substeps`"),
        ("substeps = 1000\n", "`substeps`"),
        ("substeps = \"many\"\n", "substeps `many`"),
        ("masses = [1.0, 0.0, 1.0]\n", "`masses`"),
    ] {
        let (p, msg) = load_err(&dir, text);
        assert!(msg.contains(&p.display().to_string()), "{text}: {msg}");
        assert!(msg.contains(field), "{text}: {msg}");
    }
    // Syntax errors name the file too; a BOM and CRLF line ends are accepted.
    let (p, msg) = load_err(&dir, "window = \n");
    assert!(msg.contains(&p.display().to_string()), "{msg}");
    let p = dir.join("ok.toml");
    std::fs::write(&p, "\u{feff}particles = 300\r\nwindow = 40\r\n").unwrap();
    let s = load_filter_settings(&p).unwrap();
    assert_eq!((s.particles, s.window), (300, 40));
    std::fs::write(&p, "substeps = \"auto\"\n").unwrap();
    let s = load_filter_settings(&p).unwrap();
    assert_eq!(s.substeps, identify::settings::Substeps::Auto);
    // The cloud's size once the dimension is known.
    assert!(check_particle_cloud(MAX_PARTICLES, 100).is_err());
    check_particle_cloud(500, 100).unwrap();
}

#[test]
fn huge_study_data_sizes_are_refused_when_the_study_is_read() {
    let (_tmp, dir) = temp_dir("study");
    let fig4 = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../experiments/fig4.toml"),
    )
    .unwrap();
    for (extra, field) in [
        ("storeys = 1000000000\n", "storeys"),
        ("duration = 1e12\n", "duration"),
        ("scale = 1e300\n", "scale"),
    ] {
        let text = fig4.replace(
            "preset = \"paper-3dof\"\n",
            &format!("preset = \"paper-3dof\"\n{extra}"),
        );
        let p = dir.join("study.toml");
        std::fs::write(&p, text).unwrap();
        // Refused when the study is read, naming the file and the field, before any run.
        let e = format!("{:#}", Study::load(&p).unwrap_err());
        assert!(e.contains("study.toml"), "{extra}: {e}");
        assert!(e.contains(&format!("`{field}`")), "{extra}: {e}");
    }
}
