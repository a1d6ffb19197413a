//! The generated documentation agrees with its sources: `docs/cli.md` with `sysid`'s own help,
//! the README's headline table with the committed Fig. 7 records. `cargo xtask docs` rewrites
//! both.

use std::path::PathBuf;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

#[test]
fn the_command_reference_is_the_tools_own_help() {
    let expected =
        experiments::cli_reference::render(std::path::Path::new(env!("CARGO_BIN_EXE_sysid")))
            .unwrap();
    let found = std::fs::read_to_string(root().join("docs/cli.md")).unwrap_or_default();
    assert!(
        found == expected,
        "docs/cli.md differs from `sysid --help` and its subcommands' help: run `cargo xtask docs`"
    );
}

#[test]
fn the_readme_headline_table_is_computed_from_the_records() {
    let table =
        experiments::headline::from_dir(&root().join("results/paper/records/fig7")).unwrap();
    let readme = std::fs::read_to_string(root().join("README.md")).unwrap();
    let expected = experiments::headline::splice(&readme, &table).unwrap();
    assert!(
        readme == expected,
        "the README's headline table differs from the records: run `cargo xtask docs`"
    );
    // The table is there and has a row per algorithm.
    for label in ["MLN-RBPF", "Storvik", "MPF-EKF2", "bootstrap PF"] {
        assert!(table.contains(label), "{label} missing from\n{table}");
    }
}
