//! The project's own files — the studies under `experiments/`, the channel maps of the vendored
//! real records, the baseline script — found from any directory: a relative path that does not
//! exist from the working directory is looked up in the checkout this `sysid` was built from,
//! and an error names both places. So `sysid reproduce` or `sysid import --map
//! experiments/real/frame-northridge.toml` work from a scratch directory, where their outputs
//! belong, and a path the user gives that exists is always the one used.

use std::path::{Path, PathBuf};

use crate::error::{bail, Result};

/// The checkout this `sysid` was built from (the workspace root; it may have moved since).
pub fn root() -> PathBuf {
    let crate_dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    // crates/experiments → the workspace root.
    crate_dir
        .parent()
        .and_then(Path::parent)
        .unwrap_or(crate_dir)
        .to_path_buf()
}

/// `path` when it exists; else, for a relative path, the same path in the project's checkout
/// ([`root`]) when it exists there; else an error naming `what` and both places looked in.
pub(crate) fn locate(path: &Path, what: &str) -> Result<PathBuf> {
    if path.exists() {
        return Ok(path.to_path_buf());
    }
    let root = root();
    if path.is_relative() {
        let there = root.join(path);
        if there.exists() {
            return Ok(there);
        }
    }
    let cwd = std::env::current_dir()
        .map(|d| d.display().to_string())
        .unwrap_or_else(|_| "the working directory".into());
    if path.is_relative() {
        bail!(
            "{what} {}: not found in {cwd} nor in the project's checkout {} (where this sysid \
             was built)",
            path.display(),
            root.display()
        );
    }
    bail!("{what} {}: not found", path.display());
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_project_file_is_found_from_anywhere_and_a_missing_one_says_where_it_looked() {
        // The paper's Fig. 4 study, relative to the checkout (the tests run in the crate's
        // directory, where it does not exist).
        let p = locate(Path::new("experiments/fig4.toml"), "study").unwrap();
        assert!(p.ends_with("experiments/fig4.toml") && p.is_file(), "{p:?}");
        let e = locate(Path::new("experiments/no-such.toml"), "study")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("study experiments/no-such.toml: not found in")
                && e.contains("project's checkout"),
            "{e}"
        );
        // A path that exists is used as given.
        let here = Path::new("Cargo.toml");
        assert_eq!(locate(here, "file").unwrap(), here);
    }
}
