//! One probe: a command line (of `sysid`, or a Python script and its arguments), the files it
//! runs on, and which paths it may write.
//!
//! A probe lives in a directory of its own: `work/` is the program's working directory and
//! holds its inputs, `outside/` the files that links lead to. Every path here is relative to
//! that directory; arguments name files relative to `work/`.

use std::collections::BTreeMap;
use std::ffi::OsString;
use std::path::{Path, PathBuf};

/// The placeholder in seed files for the absolute path of the probe's `work/` directory
/// (cluster plans name their files absolutely).
pub(crate) const ROOT: &str = "@FUZZ-WORK@";

/// What is at a path before the probe runs.
#[derive(Debug, Clone)]
pub(crate) enum Node {
    /// A regular file; [`ROOT`] in it becomes the absolute `work/` directory.
    File(Vec<u8>),
    Dir,
    /// A symbolic link with this target (absolute, or relative to the link's directory).
    Link(PathBuf),
    Fifo,
    /// A sparse file of this many bytes.
    Sparse(u64),
    /// A character device with this major and minor number (made only as root: 1, 3 is the
    /// null device and 1, 5 the zero device, so nothing escapes through it).
    Device(u32, u32),
}

/// Which program runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Program {
    Sysid,
    Python,
}

/// Where the program is told a path or a value: an argument, a parameter of the Python script,
/// or nowhere (a file named by another file, as the data files of a channel map).
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) enum Ref {
    None,
    Arg(usize),
    Param(String),
}

/// A file or directory the program reads.
#[derive(Debug, Clone)]
pub(crate) struct Slot {
    pub(crate) path: PathBuf,
    pub(crate) refer: Ref,
    /// A directory (a data set); its files are slots of their own.
    pub(crate) dir: bool,
    /// An input that must not change: false for the records a resumed command finds in its
    /// own output directory, which it may replace.
    pub(crate) kept: bool,
}

/// A path the program may write: a file, or a directory and everything under it.
#[derive(Debug, Clone)]
pub(crate) struct Out {
    pub(crate) path: PathBuf,
    pub(crate) refer: Ref,
    pub(crate) dir: bool,
    /// Names the program writes inside the directory (data-set files, figures, reports).
    pub(crate) names: &'static [&'static str],
}

/// One probe.
#[derive(Debug, Clone)]
pub(crate) struct Probe {
    pub(crate) target: &'static str,
    pub(crate) program: Program,
    /// The hostile change made to the valid command (or `valid`).
    pub(crate) what: String,
    pub(crate) args: Vec<OsString>,
    /// The Python script's parameters (JSON, given as its last argument).
    pub(crate) params: serde_json::Map<String, serde_json::Value>,
    pub(crate) nodes: BTreeMap<PathBuf, Node>,
    pub(crate) inputs: Vec<Slot>,
    pub(crate) outputs: Vec<Out>,
    /// Values that may be replaced by hostile ones.
    pub(crate) flags: Vec<Ref>,
    /// Paths under an output that must not change (what was there and is not the program's).
    pub(crate) protected: Vec<PathBuf>,
    /// Data-set directories whose `dataset.json` records digests of their CSV files.
    pub(crate) datasets: Vec<PathBuf>,
}

/// `work/<rel>`.
pub(crate) fn work(rel: impl AsRef<Path>) -> PathBuf {
    Path::new("work").join(rel)
}

impl Probe {
    pub(crate) fn new(target: &'static str, program: Program) -> Self {
        Probe {
            target,
            program,
            what: "valid".into(),
            args: Vec::new(),
            params: serde_json::Map::new(),
            nodes: BTreeMap::new(),
            inputs: Vec::new(),
            outputs: Vec::new(),
            flags: Vec::new(),
            protected: Vec::new(),
            datasets: Vec::new(),
        }
    }

    /// Appends arguments that are not varied.
    pub(crate) fn args(&mut self, args: &[&str]) -> &mut Self {
        self.args.extend(args.iter().map(OsString::from));
        self
    }

    /// Appends `name value`, the value one that may be made hostile.
    pub(crate) fn flag(&mut self, name: &str, value: &str) -> &mut Self {
        self.args.push(name.into());
        self.flags.push(Ref::Arg(self.args.len()));
        self.args.push(value.into());
        self
    }

    /// A Python parameter that may be made hostile.
    pub(crate) fn param(&mut self, key: &str, value: serde_json::Value) -> &mut Self {
        self.params.insert(key.into(), value);
        self.flags.push(Ref::Param(key.into()));
        self
    }

    /// A Python parameter that is not varied.
    pub(crate) fn fixed_param(&mut self, key: &str, value: serde_json::Value) -> &mut Self {
        self.params.insert(key.into(), value);
        self
    }

    /// Puts a file at `work/<rel>`, an input named by nothing else.
    pub(crate) fn file(&mut self, rel: &str, bytes: Vec<u8>) -> PathBuf {
        let path = work(rel);
        self.nodes.insert(path.clone(), Node::File(bytes));
        self.inputs.push(Slot {
            path: path.clone(),
            refer: Ref::None,
            dir: false,
            kept: true,
        });
        path
    }

    /// An input file named by `flag` (or positionally without one).
    pub(crate) fn input(&mut self, flag: Option<&str>, rel: &str, bytes: Vec<u8>) -> &mut Self {
        self.file(rel, bytes);
        let refer = self.path_arg(flag, rel);
        self.inputs.last_mut().expect("just added").refer = refer;
        self
    }

    /// An input file given to the Python script as parameter `key`.
    pub(crate) fn py_input(&mut self, key: &str, rel: &str, bytes: Vec<u8>) -> &mut Self {
        self.file(rel, bytes);
        self.params.insert(key.into(), rel.into());
        self.inputs.last_mut().expect("just added").refer = Ref::Param(key.into());
        self
    }

    fn path_arg(&mut self, flag: Option<&str>, rel: &str) -> Ref {
        if let Some(f) = flag {
            self.args.push(f.into());
        }
        self.args.push(rel.into());
        Ref::Arg(self.args.len() - 1)
    }

    /// A directory of input files (`files` by their names in it), named by `refer`.
    pub(crate) fn input_dir(&mut self, rel: &str, files: Vec<(String, Vec<u8>)>, refer: Ref) {
        let dir = work(rel);
        self.nodes.insert(dir.clone(), Node::Dir);
        let has_meta = files.iter().any(|(n, _)| n == "dataset.json");
        for (name, bytes) in files {
            self.file(&format!("{rel}/{name}"), bytes);
        }
        if has_meta {
            self.datasets.push(dir.clone());
        }
        self.inputs.push(Slot {
            path: dir,
            refer,
            dir: true,
            kept: true,
        });
    }

    /// A data-set (or other input) directory named by `flag`.
    pub(crate) fn input_dir_arg(
        &mut self,
        flag: Option<&str>,
        rel: &str,
        files: Vec<(String, Vec<u8>)>,
    ) {
        let refer = self.path_arg(flag, rel);
        self.input_dir(rel, files, refer);
    }

    /// Files already in an output directory (a resumed study's records): mutated like inputs,
    /// but the program may replace them.
    pub(crate) fn output_files(&mut self, rel_dir: &str, files: Vec<(String, Vec<u8>)>) {
        for (name, bytes) in files {
            let path = work(format!("{rel_dir}/{name}"));
            self.nodes.insert(path.clone(), Node::File(bytes));
            self.inputs.push(Slot {
                path,
                refer: Ref::None,
                dir: false,
                kept: false,
            });
        }
    }

    /// An output named by `flag`.
    pub(crate) fn output(
        &mut self,
        flag: Option<&str>,
        rel: &str,
        dir: bool,
        names: &'static [&'static str],
    ) -> &mut Self {
        let refer = self.path_arg(flag, rel);
        self.outputs.push(Out {
            path: work(rel),
            refer,
            dir,
            names,
        });
        self
    }

    /// An output given to the Python script as parameter `key`.
    pub(crate) fn py_output(
        &mut self,
        key: &str,
        rel: &str,
        dir: bool,
        names: &'static [&'static str],
    ) -> &mut Self {
        self.params.insert(key.into(), rel.into());
        self.outputs.push(Out {
            path: work(rel),
            refer: Ref::Param(key.into()),
            dir,
            names,
        });
        self
    }

    /// Sets the value at `refer` (an argument or a parameter) to `value`.
    pub(crate) fn set(&mut self, refer: &Ref, value: &str) {
        match refer {
            Ref::None => {}
            Ref::Arg(i) => self.args[*i] = value.into(),
            Ref::Param(k) => {
                self.params.insert(k.clone(), value.into());
            }
        }
    }

    /// Is `path` (relative to the probe's directory) one the program may write?
    pub(crate) fn may_write(&self, path: &Path) -> bool {
        let under = |p: &PathBuf| path.starts_with(p);
        self.outputs.iter().any(|o| under(&o.path))
            && !self.protected.iter().any(under)
            && !self
                .inputs
                .iter()
                .any(|s| s.kept && !s.dir && under(&s.path))
    }

    /// Creates the probe's files under `root` (which must not exist yet).
    pub(crate) fn materialise(&self, root: &Path) -> std::io::Result<()> {
        let work_dir = root.join("work");
        std::fs::create_dir_all(&work_dir)?;
        std::fs::create_dir_all(root.join("outside"))?;
        let absolute = std::path::absolute(&work_dir)?;
        for (rel, node) in &self.nodes {
            let p = root.join(rel);
            if let Some(parent) = p.parent() {
                std::fs::create_dir_all(parent)?;
            }
            match node {
                Node::File(bytes) => {
                    std::fs::write(&p, with_root(bytes, &absolute))?;
                }
                Node::Dir => std::fs::create_dir_all(&p)?,
                Node::Link(target) => std::os::unix::fs::symlink(target, &p)?,
                Node::Fifo => mkfifo(&p)?,
                Node::Sparse(len) => std::fs::File::create(&p)?.set_len(*len)?,
                Node::Device(major, minor) => mknod(&p, *major, *minor)?,
            }
        }
        Ok(())
    }

    /// The arguments the program is run with (a Python probe's parameters last, as JSON).
    pub(crate) fn argv(&self) -> Vec<OsString> {
        let mut argv = self.args.clone();
        if self.program == Program::Python {
            argv.push(
                serde_json::Value::Object(self.params.clone())
                    .to_string()
                    .into(),
            );
        }
        argv
    }
}

/// `bytes` with [`ROOT`] replaced by `work`.
fn with_root(bytes: &[u8], work: &Path) -> Vec<u8> {
    let needle = ROOT.as_bytes();
    let with = work.as_os_str().as_encoded_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i..].starts_with(needle) {
            out.extend_from_slice(with);
            i += needle.len();
        } else {
            out.push(bytes[i]);
            i += 1;
        }
    }
    out
}

fn mkfifo(path: &Path) -> std::io::Result<()> {
    use std::os::unix::ffi::OsStrExt;
    let c = std::ffi::CString::new(path.as_os_str().as_bytes())
        .map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidInput, e))?;
    // SAFETY: `c` is a NUL-terminated path that outlives the call.
    if unsafe { libc::mkfifo(c.as_ptr(), 0o644) } != 0 {
        return Err(std::io::Error::last_os_error());
    }
    Ok(())
}

/// Whether this process may make device nodes (it runs as root).
pub(crate) fn may_make_devices() -> bool {
    // SAFETY: `geteuid` takes no argument and cannot fail.
    unsafe { libc::geteuid() == 0 }
}

fn mknod(path: &Path, major: u32, minor: u32) -> std::io::Result<()> {
    use std::os::unix::ffi::OsStrExt;
    let c = std::ffi::CString::new(path.as_os_str().as_bytes())
        .map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidInput, e))?;
    let dev = libc::makedev(major, minor);
    // SAFETY: `c` is a NUL-terminated path that outlives the call.
    if unsafe { libc::mknod(c.as_ptr(), libc::S_IFCHR | 0o666, dev) } != 0 {
        return Err(std::io::Error::last_os_error());
    }
    Ok(())
}

/// The target of a link at `link` (relative to the probe's directory) that leads to `target`
/// (also relative to it).
pub(crate) fn relative_target(link: &Path, target: &Path) -> PathBuf {
    let depth = link.parent().map_or(0, |p| p.components().count());
    let mut t = PathBuf::new();
    for _ in 0..depth {
        t.push("..");
    }
    t.join(target)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_outputs_that_are_neither_inputs_nor_protected_may_be_written() {
        let mut p = Probe::new("t", Program::Sysid);
        p.input(Some("--record"), "run.json", b"{}".to_vec());
        p.output(Some("--out"), "figs", true, &[]);
        p.protected.push(work("figs/keep.txt"));
        assert!(p.may_write(&work("figs/a.svg")));
        assert!(!p.may_write(&work("figs/keep.txt")));
        assert!(!p.may_write(&work("run.json")));
        assert!(!p.may_write(&work("other")));
        // An output made to be the input is not writable.
        p.outputs.push(Out {
            path: work("run.json"),
            refer: Ref::None,
            dir: false,
            names: &[],
        });
        assert!(!p.may_write(&work("run.json")));
    }

    #[test]
    fn links_and_pipes_are_made_and_the_root_is_filled_in() {
        let tmp = tempfile::tempdir().unwrap();
        let mut p = Probe::new("t", Program::Sysid);
        p.file(
            "plan.json",
            format!("{{\"out\": \"{ROOT}/cl\"}}").into_bytes(),
        );
        p.nodes.insert(work("fifo"), Node::Fifo);
        let link = work("d/x");
        let target = relative_target(&link, Path::new("outside/v"));
        p.nodes.insert(link, Node::Link(target));
        p.nodes
            .insert(PathBuf::from("outside/v"), Node::File(b"v".to_vec()));
        let root = tmp.path().join("p");
        p.materialise(&root).unwrap();
        assert_eq!(std::fs::read(root.join("work/d/x")).unwrap(), b"v");
        let plan = std::fs::read_to_string(root.join("work/plan.json")).unwrap();
        let abs = std::path::absolute(root.join("work")).unwrap();
        assert_eq!(plan, format!("{{\"out\": \"{}/cl\"}}", abs.display()));
        use std::os::unix::fs::FileTypeExt;
        let t = std::fs::symlink_metadata(root.join("work/fifo"))
            .unwrap()
            .file_type();
        assert!(t.is_fifo());
        if may_make_devices() {
            let mut q = Probe::new("t", Program::Sysid);
            q.nodes.insert(work("null"), Node::Device(1, 3));
            q.materialise(&tmp.path().join("q")).unwrap();
            let null = tmp.path().join("q/work/null");
            assert!(std::fs::symlink_metadata(&null)
                .unwrap()
                .file_type()
                .is_char_device());
            std::fs::write(&null, "discarded").unwrap();
            assert_eq!(std::fs::read(&null).unwrap(), b"");
        }
    }
}
