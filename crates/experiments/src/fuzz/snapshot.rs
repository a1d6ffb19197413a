//! What a directory tree holds, to compare before and after a probe: every entry's kind, and
//! for a file its size, modification time, inode and (below a size) a hash of its content.
//! Symbolic links are recorded as links (with their target), never followed; nothing but
//! regular files is opened, so a named pipe or a link to `/dev/zero` in the tree is safe.

use std::collections::BTreeMap;
use std::hash::Hasher;
use std::io::Read;
use std::path::{Path, PathBuf};

/// Files larger than this are compared by size, time and inode only (a 3 GiB sparse input is
/// not read).
const HASHED_BYTES: u64 = 64 << 20;

/// The kind of an entry.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Kind {
    File,
    Dir,
    Link,
    Fifo,
    Other,
}

/// One entry of a tree.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Entry {
    pub(crate) kind: Kind,
    len: u64,
    mtime_ns: i128,
    inode: u64,
    hash: u64,
    link: Option<PathBuf>,
}

/// Entries by path (absolute).
pub(crate) type Snapshot = BTreeMap<PathBuf, Entry>;

/// How to take a snapshot.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Depth {
    /// Hash file contents (the probe's own directory); without, size, time and inode only (a
    /// repository checkout of thousands of files).
    pub(crate) hash: bool,
}

/// The entries under `root` (not `root` itself), skipping the paths in `exclude` and their
/// contents. A tree that is missing gives an empty snapshot.
pub(crate) fn take(root: &Path, depth: Depth, exclude: &[PathBuf]) -> Snapshot {
    let mut out = Snapshot::new();
    let mut stack = vec![root.to_path_buf()];
    while let Some(dir) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        for e in entries.flatten() {
            let path = e.path();
            if exclude.iter().any(|x| x == &path) {
                continue;
            }
            let entry = entry(&path, depth);
            if entry.kind == Kind::Dir {
                stack.push(path.clone());
            }
            out.insert(path, entry);
        }
    }
    out
}

fn entry(path: &Path, depth: Depth) -> Entry {
    use std::os::unix::fs::{FileTypeExt, MetadataExt};
    let Ok(meta) = std::fs::symlink_metadata(path) else {
        // Gone between listing and looking: recorded as such, compared like any entry.
        return Entry {
            kind: Kind::Other,
            len: 0,
            mtime_ns: 0,
            inode: 0,
            hash: 0,
            link: None,
        };
    };
    let t = meta.file_type();
    let kind = if t.is_symlink() {
        Kind::Link
    } else if t.is_dir() {
        Kind::Dir
    } else if t.is_file() {
        Kind::File
    } else if t.is_fifo() {
        Kind::Fifo
    } else {
        Kind::Other
    };
    // A directory changes its time whenever a file is made and removed in it (the temporary
    // file of an atomic write beside its output): only its kind is compared.
    if kind == Kind::Dir {
        return Entry {
            kind,
            len: 0,
            mtime_ns: 0,
            inode: 0,
            hash: 0,
            link: None,
        };
    }
    let hash = if kind == Kind::File && depth.hash && meta.len() <= HASHED_BYTES {
        content_hash(path)
    } else {
        0
    };
    Entry {
        kind,
        len: meta.len(),
        mtime_ns: i128::from(meta.mtime()) * 1_000_000_000 + i128::from(meta.mtime_nsec()),
        inode: meta.ino(),
        hash,
        link: std::fs::read_link(path).ok(),
    }
}

fn content_hash(path: &Path) -> u64 {
    let mut h = std::hash::DefaultHasher::new();
    let Ok(mut f) = std::fs::File::open(path) else {
        return 1;
    };
    let mut buf = vec![0u8; 1 << 16];
    loop {
        match f.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => h.write(&buf[..n]),
            Err(_) => return 2,
        }
    }
    h.finish()
}

/// The paths that were created, changed or deleted between two snapshots, each with a word
/// saying which.
pub(crate) fn changes(before: &Snapshot, after: &Snapshot) -> Vec<(PathBuf, &'static str)> {
    let mut out = Vec::new();
    for (path, was) in before {
        match after.get(path) {
            None => out.push((path.clone(), "deleted")),
            Some(now) if now.kind != was.kind => out.push((path.clone(), "replaced")),
            Some(now) if now != was => out.push((path.clone(), "changed")),
            Some(_) => {}
        }
    }
    for path in after.keys() {
        if !before.contains_key(path) {
            out.push((path.clone(), "created"));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn created_changed_replaced_and_deleted_entries_are_found() {
        let tmp = tempfile::tempdir().unwrap();
        let d = tmp.path();
        std::fs::write(d.join("same"), "a").unwrap();
        std::fs::write(d.join("edit"), "a").unwrap();
        std::fs::write(d.join("gone"), "a").unwrap();
        std::fs::write(d.join("link"), "a").unwrap();
        std::fs::create_dir(d.join("dir")).unwrap();
        let deep = Depth { hash: true };
        let before = take(d, deep, &[]);
        std::fs::write(d.join("edit"), "b").unwrap();
        std::fs::remove_file(d.join("gone")).unwrap();
        std::fs::remove_file(d.join("link")).unwrap();
        std::os::unix::fs::symlink("same", d.join("link")).unwrap();
        std::fs::write(d.join("dir/new"), "c").unwrap();
        let after = take(d, deep, &[]);
        let mut found = changes(&before, &after);
        found.sort();
        let want: Vec<(PathBuf, &str)> = vec![
            (d.join("dir/new"), "created"),
            (d.join("edit"), "changed"),
            (d.join("gone"), "deleted"),
            (d.join("link"), "replaced"),
        ];
        assert_eq!(found, want);
        // An excluded directory is not looked into.
        let after = take(d, deep, &[d.join("dir")]);
        assert!(!after.contains_key(&d.join("dir/new")));
    }
}
