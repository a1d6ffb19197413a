//! `pip install ./python` after `cargo build --release` compiles only the binding, PyO3 and
//! numpy's crates: every crate the two builds share is selected with the same features (a
//! crate built with other features is a second compilation of it and of everything above it:
//! num-complex's `default` alone recompiled faer, nalgebra, gemm and the workspace's crates).
//! The root Cargo.toml turns those features on for the release build; this test fails when a
//! dependency's update or a new dependency brings a difference back. `.ci/run` checks the
//! outcome itself (what pip compiled).

use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;

/// Package → its selected features, as `cargo tree` resolves them for `selection`.
fn features(selection: &[&str]) -> BTreeMap<String, String> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let out = Command::new(env!("CARGO"))
        .current_dir(&root)
        .args(["tree", "-q", "-e", "normal,build", "--prefix", "none"])
        .args(["-f", "{p} | {f}"])
        .args(selection)
        .output()
        .expect("running cargo tree");
    assert!(
        out.status.success(),
        "cargo tree {selection:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout)
        .expect("cargo tree prints UTF-8")
        .lines()
        .filter_map(|line| {
            let (package, features) = line.split_once(" | ")?;
            // "name vX.Y.Z (path)" → "name vX.Y.Z"; a repeated subtree ends in " (*)".
            let mut words = package.split_whitespace();
            let id = format!("{} {}", words.next()?, words.next()?);
            Some((id, features.trim_end_matches(" (*)").trim().to_string()))
        })
        .collect()
}

#[test]
fn the_python_binding_selects_the_release_builds_features() {
    // What `cargo build --release` (default members) and the main job (`-p experiments`)
    // select, and what maturin selects for the binding.
    let python = features(&["-p", "sysid-mpf-py", "--features", "pyo3/extension-module"]);
    for selection in [
        &["--workspace", "--exclude", "sysid-mpf-py"][..],
        &["-p", "experiments"],
    ] {
        let release = features(selection);
        let shared: Vec<_> = release.keys().filter(|k| python.contains_key(*k)).collect();
        assert!(
            shared.iter().any(|k| k.starts_with("faer ")) && shared.len() > 50,
            "the two builds share faer and the workspace's dependencies: {shared:?}"
        );
        let differ: Vec<String> = shared
            .into_iter()
            .filter(|k| release[k.as_str()] != python[k.as_str()])
            .map(|k| {
                format!(
                    "{k}: [{}] against the binding's [{}]",
                    release[k.as_str()],
                    python[k.as_str()]
                )
            })
            .collect();
        assert!(
            differ.is_empty(),
            "{selection:?} selects other features than the Python binding's build, so pip \
             would compile these (and everything above them) again; turn the binding's \
             features on in the root Cargo.toml:\n{}",
            differ.join("\n")
        );
    }
}
