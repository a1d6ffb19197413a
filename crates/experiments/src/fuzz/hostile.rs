//! Makes a valid probe hostile with one change: a mutated input file, a special file where an
//! input or an output is expected, a hostile value of a flag, or a damaged command line.

use std::path::{Path, PathBuf};

use rand::seq::IndexedRandom;
use rand::Rng;

use super::mutate::{self, FuzzRng};
use super::probe::{may_make_devices, relative_target, work, Node, Out, Probe, Program, Ref};

/// One hostile change to `p`, recorded in `p.what` (a few probes stay valid).
pub(crate) fn harden(p: &mut Probe, rng: &mut FuzzRng) {
    // What the target itself varied (the arrays of a Python probe), kept in the description.
    let made = std::mem::take(&mut p.what);
    let roll = rng.random_range(0..100);
    let what = match roll {
        0..=3 => None,
        4..=48 => mutate_input(p, rng),
        49..=61 => special_input(p, rng),
        62..=79 => special_output(p, rng),
        80..=94 => hostile_flag(p, rng),
        _ => damaged_command_line(p, rng),
    };
    // A probe without what the roll asked for (no input, no output) gets a hostile flag.
    let what = what
        .or_else(|| hostile_flag(p, rng))
        .or_else(|| special_output(p, rng));
    p.what = match (made.as_str(), what) {
        ("valid" | "", None) => "valid".into(),
        ("valid" | "", Some(w)) => w,
        (m, None) => m.to_string(),
        (m, Some(w)) => format!("{m}; {w}"),
    };
}

fn shown(p: &Path) -> String {
    p.strip_prefix("work").unwrap_or(p).display().to_string()
}

/// Mutates the bytes of one input file.
fn mutate_input(p: &mut Probe, rng: &mut FuzzRng) -> Option<String> {
    let files: Vec<PathBuf> = p
        .inputs
        .iter()
        .filter(|s| !s.dir)
        .map(|s| s.path.clone())
        .collect();
    let path = files.choose(rng)?.clone();
    let Some(Node::File(bytes)) = p.nodes.get_mut(&path) else {
        return None;
    };
    let what = mutate::mutate_some(bytes, rng);
    // The digests in dataset.json would refuse a changed CSV file before it is parsed: mostly
    // they are recomputed, so the parsers meet the mutation.
    let mut note = "";
    if rng.random_bool(0.8) {
        if let Some(dir) = p.datasets.iter().find(|d| path.parent() == Some(d)) {
            if refresh_digest(p, &dir.clone(), &path) {
                note = " (digest recomputed)";
            }
        }
    }
    Some(format!("{}: {what}{note}", shown(&path)))
}

/// Records the size and SHA-256 of the CSV file `file` in the data set `dir`'s `dataset.json`.
fn refresh_digest(p: &mut Probe, dir: &Path, file: &Path) -> bool {
    let name = file.file_name().and_then(|n| n.to_str()).unwrap_or("");
    let Some(Node::File(csv)) = p.nodes.get(file) else {
        return false;
    };
    let digest = models::dataset::FileDigest::of(csv);
    let meta_path = dir.join("dataset.json");
    let Some(Node::File(meta)) = p.nodes.get_mut(&meta_path) else {
        return false;
    };
    let Ok(mut json) = serde_json::from_slice::<serde_json::Value>(meta) else {
        return false;
    };
    let Some(files) = json.get_mut("files").and_then(|f| f.as_object_mut()) else {
        return false;
    };
    let Ok(value) = serde_json::to_value(digest) else {
        return false;
    };
    files.insert(name.into(), value);
    match serde_json::to_vec_pretty(&json) {
        Ok(text) => {
            *meta = text;
            true
        }
        Err(_) => false,
    }
}

/// Removes every node at or under `path`; returns them (paths relative to `path`).
fn take_nodes(p: &mut Probe, path: &Path) -> Vec<(PathBuf, Node)> {
    let keys: Vec<PathBuf> = p
        .nodes
        .keys()
        .filter(|k| k.starts_with(path))
        .cloned()
        .collect();
    keys.into_iter()
        .filter_map(|k| {
            let node = p.nodes.remove(&k)?;
            Some((k.strip_prefix(path).ok()?.to_path_buf(), node))
        })
        .collect()
}

/// Names that are awkward in paths, scripts and formats.
const ODD_NAMES: &[&str] = &[
    "a\nb",
    "x #y",
    "p%a%j",
    "sp ace",
    "q'uo\"te",
    "$(touch pwned)",
    "`id`",
    "-dash",
    "\u{e9}\u{1f600}",
    "back\\slash",
    "semi;colon",
    "\t",
];

/// An odd file name; for an output (which need not exist) sometimes one longer than a file
/// name may be.
fn odd_name(rng: &mut FuzzRng, output: bool) -> String {
    if output && rng.random_bool(0.1) {
        return "n".repeat(300);
    }
    ODD_NAMES.choose(rng).expect("names").to_string()
}

/// Puts a special file where an input is expected.
fn special_input(p: &mut Probe, rng: &mut FuzzRng) -> Option<String> {
    let slot = p.inputs.choose(rng)?.clone();
    let path = slot.path.clone();
    let taken = take_nodes(p, &path);
    let what = match rng.random_range(0..10) {
        0 => {
            p.nodes.insert(path.clone(), Node::Fifo);
            "a named pipe"
        }
        1 if may_make_devices() && rng.random_bool(0.5) => {
            p.nodes.insert(path.clone(), Node::Device(1, 5));
            "the zero device (a device node)"
        }
        1 => {
            p.nodes.insert(path.clone(), Node::Link("/dev/zero".into()));
            "a link to /dev/zero"
        }
        2 if !slot.dir => {
            p.nodes.insert(path.clone(), Node::Dir);
            p.nodes
                .insert(path.join("inner.txt"), Node::File(b"inner\n".to_vec()));
            p.protected.push(path.join("inner.txt"));
            "a directory"
        }
        2 => {
            p.nodes
                .insert(path.clone(), Node::File(b"not a directory\n".to_vec()));
            "a file"
        }
        3 => "missing",
        4 => {
            p.nodes.insert(path.clone(), Node::Sparse(3 << 30));
            "a sparse file of 3 GiB"
        }
        5 | 6 => {
            // The same content, reached through a link to outside the working directory.
            let away = PathBuf::from("outside").join(format!("away-{}", p.nodes.len()));
            for (rel, node) in taken {
                p.nodes.insert(joined(&away, &rel), node);
            }
            p.nodes
                .insert(path.clone(), Node::Link(relative_target(&path, &away)));
            "a link to a copy outside"
        }
        7 => {
            p.nodes
                .insert(path.clone(), Node::Link(path.file_name()?.into()));
            "a link to itself"
        }
        8 if slot.refer != Ref::None => {
            // Renamed: the same content under an odd name.
            let name = odd_name(rng, false);
            let renamed = path.with_file_name(&name);
            for (rel, node) in taken {
                p.nodes.insert(joined(&renamed, &rel), node);
            }
            let shown_path = renamed.strip_prefix("work").ok()?.to_str()?.to_string();
            p.set(&slot.refer, &shown_path);
            // The renamed input stays an input.
            for s in p.inputs.iter_mut() {
                if let Ok(rest) = s.path.strip_prefix(&path) {
                    s.path = joined(&renamed, rest);
                }
            }
            for d in p.datasets.iter_mut() {
                if let Ok(rest) = d.strip_prefix(&path) {
                    *d = joined(&renamed, rest);
                }
            }
            return Some(format!("{} renamed {name:?}", shown(&path)));
        }
        _ => {
            p.nodes
                .insert(path.clone(), Node::Link("no/such/target".into()));
            "a dangling link"
        }
    };
    Some(format!("{} is {what}", shown(&path)))
}

/// `base/rel`, or `base` itself when `rel` is empty (`join` would add a trailing slash).
fn joined(base: &Path, rel: &Path) -> PathBuf {
    if rel.as_os_str().is_empty() {
        base.to_path_buf()
    } else {
        base.join(rel)
    }
}

/// Puts something where an output is to be written, or names it oddly.
fn special_output(p: &mut Probe, rng: &mut FuzzRng) -> Option<String> {
    let out = p.outputs.choose(rng)?.clone();
    let path = out.path.clone();
    take_nodes(p, &path);
    let victim = PathBuf::from("outside/victim.txt");
    let what: String = match rng.random_range(0..12) {
        0 if may_make_devices() && rng.random_bool(0.5) => {
            p.nodes.insert(path.clone(), Node::Device(1, 3));
            p.protected.push(path.clone());
            "the null device (a device node)".into()
        }
        0 => {
            p.nodes.insert(path.clone(), Node::Link("/dev/null".into()));
            p.protected.push(path.clone());
            "a link to /dev/null".into()
        }
        1 => {
            p.nodes.insert(path.clone(), Node::Fifo);
            p.protected.push(path.clone());
            "a named pipe".into()
        }
        2 if !out.dir => {
            p.nodes.insert(path.clone(), Node::Dir);
            p.nodes
                .insert(path.join("keep.txt"), Node::File(b"keep\n".to_vec()));
            p.protected.push(path.clone());
            "a directory".into()
        }
        2 => {
            p.nodes.insert(
                path.clone(),
                Node::File(b"a file, not a directory\n".to_vec()),
            );
            p.protected.push(path.clone());
            "a regular file".into()
        }
        3 => {
            p.nodes
                .insert(victim.clone(), Node::File(b"victim\n".to_vec()));
            p.nodes
                .insert(path.clone(), Node::Link(relative_target(&path, &victim)));
            p.protected.push(path.clone());
            p.protected.push(victim);
            "a link to a file outside".into()
        }
        4 => return same_as_input(p, &out, rng),
        5 if out.dir => return occupied_dir(p, &out, rng),
        5 => {
            p.nodes
                .insert(path.clone(), Node::File(b"an older file\n".to_vec()));
            "an existing regular file (to be replaced)".into()
        }
        6 if out.dir => {
            let away = PathBuf::from("outside/dir");
            p.nodes.insert(away.clone(), Node::Dir);
            p.nodes
                .insert(path.clone(), Node::Link(relative_target(&path, &away)));
            p.protected.push(path.clone());
            // Writing through a link to a directory is what a link is for.
            p.outputs.push(Out {
                path: away,
                refer: Ref::None,
                dir: true,
                names: &[],
            });
            "a link to a directory outside".into()
        }
        6 | 7 => {
            let deeper = format!("nowhere/deeper/{}", file_name(&path));
            let rel = shown(&path);
            let parent = Path::new(&rel).parent().unwrap_or(Path::new(""));
            let new = parent.join(&deeper);
            p.set(&out.refer, new.to_str()?);
            // The missing directories are the output (created or not).
            retarget(p, &path, work(parent.join("nowhere")));
            format!("in a missing directory: {}", new.display())
        }
        8 if out.dir && !out.names.is_empty() => return special_inside(p, &out, rng),
        _ => {
            let name = odd_name(rng, true);
            let new = path.with_file_name(&name);
            p.set(&out.refer, new.strip_prefix("work").ok()?.to_str()?);
            retarget(p, &path, new);
            format!("named {name:?}")
        }
    };
    Some(format!("output {} is {what}", shown(&path)))
}

fn file_name(path: &Path) -> String {
    path.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "out".into())
}

/// The output at `from` is at `to` now.
fn retarget(p: &mut Probe, from: &Path, to: PathBuf) {
    for o in p.outputs.iter_mut() {
        if o.path == from {
            o.path = to.clone();
        }
    }
}

/// The output named the same as one of the inputs (a file for a file, the directory of an
/// input for a directory).
fn same_as_input(p: &mut Probe, out: &Out, rng: &mut FuzzRng) -> Option<String> {
    let candidates: Vec<PathBuf> = p
        .inputs
        .iter()
        .filter(|s| s.kept && !s.dir)
        .map(|s| match out.dir {
            true => s.path.parent().map(Path::to_path_buf).unwrap_or_default(),
            false => s.path.clone(),
        })
        .collect();
    let target = candidates.choose(rng)?.clone();
    let rel = target.strip_prefix("work").ok()?;
    let rel = if rel.as_os_str().is_empty() {
        PathBuf::from(".")
    } else {
        rel.to_path_buf()
    };
    p.set(&out.refer, rel.to_str()?);
    retarget(p, &out.path, target.clone());
    Some(format!(
        "output {} is the input {}",
        shown(&out.path),
        rel.display()
    ))
}

/// An existing output directory with a file of someone else's in it.
fn occupied_dir(p: &mut Probe, out: &Out, rng: &mut FuzzRng) -> Option<String> {
    let keep = out.path.join(match rng.random_bool(0.5) {
        true => "notes.txt",
        false => ".hidden",
    });
    p.nodes.insert(out.path.clone(), Node::Dir);
    p.nodes.insert(keep.clone(), Node::File(b"mine\n".to_vec()));
    p.protected.push(keep.clone());
    Some(format!(
        "output {} holds {}",
        shown(&out.path),
        file_name(&keep)
    ))
}

/// One of the names the program writes inside its output directory is already something that
/// is not a regular file.
fn special_inside(p: &mut Probe, out: &Out, rng: &mut FuzzRng) -> Option<String> {
    let name = *out.names.choose(rng)?;
    let path = out.path.join(name);
    p.nodes.insert(out.path.clone(), Node::Dir);
    let victim = PathBuf::from("outside/victim.txt");
    let what = match rng.random_range(0..4) {
        0 => {
            p.nodes.insert(path.clone(), Node::Dir);
            p.nodes.insert(
                path.join("precious.txt"),
                Node::File(b"precious\n".to_vec()),
            );
            p.protected.push(path.join("precious.txt"));
            "a directory holding precious.txt"
        }
        1 => {
            p.nodes
                .insert(victim.clone(), Node::File(b"victim\n".to_vec()));
            p.nodes
                .insert(path.clone(), Node::Link(relative_target(&path, &victim)));
            p.protected.push(victim);
            p.protected.push(path.clone());
            "a link to a file outside"
        }
        2 => {
            p.nodes.insert(path.clone(), Node::Fifo);
            p.protected.push(path.clone());
            "a named pipe"
        }
        _ => {
            p.nodes.insert(path.clone(), Node::Link("/dev/null".into()));
            p.protected.push(path.clone());
            "a link to /dev/null"
        }
    };
    Some(format!("{} is {what}", shown(&path)))
}

/// Replaces the value of one flag (or Python parameter) by a hostile one.
fn hostile_flag(p: &mut Probe, rng: &mut FuzzRng) -> Option<String> {
    let refer = p.flags.choose(rng)?.clone();
    match &refer {
        Ref::Arg(i) => {
            let value = mutate::flag_value(rng);
            let name = p.args[*i - 1].to_string_lossy().into_owned();
            p.args[*i] = value.clone().into();
            Some(format!("{name} {value:?}"))
        }
        Ref::Param(key) => {
            let value = mutate::python_value(rng);
            p.params.insert(key.clone(), value.clone());
            Some(format!("{key}={value}"))
        }
        Ref::None => None,
    }
}

/// Drops, repeats or adds an argument.
fn damaged_command_line(p: &mut Probe, rng: &mut FuzzRng) -> Option<String> {
    if p.program == Program::Python || p.args.is_empty() {
        return None;
    }
    // The subcommand's own words come first; damage what follows them.
    let first = p
        .args
        .iter()
        .position(|a| a.to_string_lossy().starts_with("--"))
        .unwrap_or(p.args.len());
    let what = match rng.random_range(0..5) {
        0 => {
            // A whole option (with its value): a lone value or positional argument dropped
            // would give the command another meaning rather than a damaged one (`merge --into
            // part0 part1` merges into an input, as asked).
            // A switch, or an option whose value is one the probes vary: not one naming a path
            // (without `--out` a command writes to its default, `results/...`; without
            // `--config` a study runs the project's own, a big valid workload) and not
            // `--dry-run` (without it a submission writes, and its output is declared only
            // for a real one).
            let varied: Vec<usize> = p
                .flags
                .iter()
                .filter_map(|f| match f {
                    Ref::Arg(i) => Some(*i - 1),
                    _ => None,
                })
                .collect();
            let options: Vec<usize> = (first..p.args.len())
                .filter(|&i| {
                    let a = p.args[i].to_string_lossy();
                    let switch = p
                        .args
                        .get(i + 1)
                        .is_none_or(|v| v.to_string_lossy().starts_with("--"));
                    a.starts_with("--") && a != "--dry-run" && (switch || varied.contains(&i))
                })
                .collect();
            let &i = options.choose(rng)?;
            let with_value = varied.contains(&i);
            let gone: Vec<_> = p.args.drain(i..i + 1 + usize::from(with_value)).collect();
            // The values after it moved: none of them is varied any more.
            p.flags.clear();
            format!("option {gone:?} dropped")
        }
        1 if first < p.args.len() => {
            let i = rng.random_range(first..p.args.len());
            let again = p.args[i..(i + 2).min(p.args.len())].to_vec();
            p.args.extend(again.iter().cloned());
            format!("{again:?} repeated at the end")
        }
        2 => {
            p.args.push("--no-such-option".into());
            "an unknown option".into()
        }
        3 => {
            p.args.push("stray positional".into());
            "a stray positional argument".into()
        }
        _ => {
            p.args.push("--".into());
            p.args.push("--help".into());
            "`-- --help` at the end".into()
        }
    };
    Some(what)
}
