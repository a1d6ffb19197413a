//! The figures of the studies — the paper's (`sysid reproduce`, `cargo xtask reproduce-paper`),
//! the scaling and excitations studies' and a study file's (`sysid study`) — are drawn aside and
//! put in place whole (`identify::plot::figures_in_place`, the helper of `sysid plot` and the
//! field study): a figure cut short or missing is drawn again by a resumed run, a reproduction
//! killed at any moment leaves every figure complete, and a figure name that is a named pipe
//! or a link is refused by name instead of waited on or written through.
#![cfg(unix)]

use crate::common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

fn sysid() -> Command {
    Command::new(env!("CARGO_BIN_EXE_sysid"))
}

fn run(args: &[&str], cwd: &Path) -> Output {
    let o = sysid()
        .args(args)
        .current_dir(cwd)
        .env("RAYON_NUM_THREADS", "1")
        .stdin(Stdio::null())
        .output()
        .unwrap();
    assert!(
        o.status.code().is_some(),
        "`sysid {}` ended by a signal: {:?}",
        args.join(" "),
        o.status
    );
    o
}

fn ok(o: &Output) {
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

/// A small paper: the five studies of the reproduction, two runs of 0.5 s each.
fn small_paper(dir: &Path) -> PathBuf {
    let exps = dir.join("exps");
    std::fs::create_dir_all(&exps).unwrap();
    for (name, algorithms) in [
        ("fig4", r#""bootstrap""#),
        ("fig5", r#""mln-rbpf", "storvik""#),
        ("fig6", r#""mln-rbpf", "mpf-ekf2""#),
        ("fig8", r#""mpf-ekf2""#),
        ("fig7", r#""mln-rbpf", "storvik", "mpf-ekf2", "bootstrap""#),
    ] {
        std::fs::write(
            exps.join(format!("{name}.toml")),
            format!(
                "name = \"{name}\"\ndescription = \"figures test\"\n[data]\n\
                 preset = \"paper-3dof\"\nduration = 0.5\n[sweep]\nalgorithms = [{algorithms}]\n\
                 runs = 2\nmaster_seed = 7\nparticles = [20]\n[filter]\ntrace_every = 10\n\
                 loop_every = 4\n"
            ),
        )
        .unwrap();
    }
    exps
}

/// The SVG figures directly in `dir` and their bytes.
fn figures(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    std::fs::read_dir(dir)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "svg"))
        .map(|p| {
            let bytes = std::fs::read(&p).unwrap();
            (p, bytes)
        })
        .collect()
}

/// No hidden staging directory is left in `dir`.
fn no_staging(dir: &Path) {
    let hidden: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with(".figures.tmp"))
        .collect();
    assert!(hidden.is_empty(), "{hidden:?} left in {}", dir.display());
}

fn cut_in_half(p: &Path) {
    let b = std::fs::read(p).unwrap();
    std::fs::write(p, &b[..b.len() / 2]).unwrap();
}

fn mkfifo(p: &Path) {
    let o = Command::new("mkfifo").arg(p).output().unwrap();
    assert!(o.status.success());
}

/// A figure name that is a named pipe is refused at once, naming it (it was waited on
/// forever: the fuzz driver's `sysid study` hang), and left as it is.
fn pipe_is_refused(args: &[&str], cwd: &Path, figure: &Path) {
    std::fs::remove_file(figure).unwrap();
    mkfifo(figure);
    let started = Instant::now();
    let o = run(args, cwd);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    let name = figure.file_name().unwrap().to_str().unwrap();
    assert!(err.contains(name) && err.contains("named pipe"), "{err}");
    assert!(started.elapsed() < Duration::from_secs(20));
    use std::os::unix::fs::FileTypeExt;
    assert!(std::fs::symlink_metadata(figure)
        .unwrap()
        .file_type()
        .is_fifo());
    std::fs::remove_file(figure).unwrap();
}

#[test]
fn a_resumed_reproduction_redraws_every_figure_whole() {
    let (_tmp, dir) = common::temp_dir("sysid-figures-paper-");
    small_paper(&dir);
    let args = [
        "reproduce",
        "--experiments",
        "exps",
        "--out",
        "paper",
        "--threads",
        "1",
    ];
    ok(&run(&args, &dir));
    let out = dir.join("paper");
    let whole = figures(&out);
    assert_eq!(whole.len(), 9, "{:?}", whole.keys());
    for f in whole.keys() {
        identify::figures::validate_svg(f).unwrap();
    }
    // Cut short, missing, and an SVG header without its end: all drawn again, the same.
    let names: Vec<&PathBuf> = whole.keys().collect();
    cut_in_half(names[0]);
    std::fs::remove_file(names[1]).unwrap();
    std::fs::write(names[2], "<svg xmlns=\"http://www.w3.org/2000/svg\">").unwrap();
    let resume = [&args[..], &["--resume"]].concat();
    ok(&run(&resume, &dir));
    assert_eq!(figures(&out), whole);
    no_staging(&out);
    pipe_is_refused(&resume, &dir, names[3]);
    // A figure name that is a link to a file elsewhere: refused, the file untouched.
    let victim = dir.join("victim.txt");
    std::fs::write(&victim, "mine").unwrap();
    std::os::unix::fs::symlink(&victim, names[3]).unwrap();
    let o = run(&resume, &dir);
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("symbolic link"));
    assert_eq!(std::fs::read_to_string(&victim).unwrap(), "mine");
    std::fs::remove_file(names[3]).unwrap();
    ok(&run(&resume, &dir));
    assert_eq!(figures(&out), whole);
}

/// `sysid reproduce --resume` killed (SIGKILL) at seeded moments of its run, again and again:
/// after every kill each figure of the output is absent, as it was, or complete — never cut
/// short — and an uninterrupted run then leaves the figures of an uninterrupted reproduction
/// and no staging directory (the killed runs' are removed).
#[test]
fn a_killed_reproduction_never_leaves_a_figure_cut_short() {
    use rand::{Rng, SeedableRng};
    let (_tmp, dir) = common::temp_dir("sysid-figures-kill-");
    small_paper(&dir);
    let args = [
        "reproduce",
        "--experiments",
        "exps",
        "--out",
        "paper",
        "--threads",
        "1",
        "--resume",
    ];
    ok(&run(&args, &dir));
    let out = dir.join("paper");
    let whole = figures(&out);
    // How long a resumed run takes here: the kills are spread over it.
    let started = Instant::now();
    ok(&run(&args, &dir));
    let span = started.elapsed().as_micros().max(1_000) as u64;
    let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(50);
    let mut mid_drawing = 0;
    for round in 0..30 {
        // Some figures start cut short or missing, so a kill can land while they are redrawn.
        if round % 3 == 0 {
            let (name, bytes) = whole.iter().nth(round % whole.len()).unwrap();
            std::fs::write(name, &bytes[..bytes.len() / 2]).unwrap();
        }
        let mut child = sysid()
            .args(args)
            .current_dir(&dir)
            .env("RAYON_NUM_THREADS", "1")
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        std::thread::sleep(Duration::from_micros(rng.random_range(0..span)));
        let _ = child.kill();
        child.wait().unwrap();
        let staged = std::fs::read_dir(&out)
            .unwrap()
            .flatten()
            .any(|e| e.file_name().to_string_lossy().starts_with(".figures.tmp"));
        mid_drawing += usize::from(staged);
        for (f, bytes) in figures(&out) {
            // A figure the test cut and the run did not reach yet is as the test left it;
            // every other one is complete.
            let cut_by_test = whole.get(&f).is_some_and(|w| bytes[..] == w[..w.len() / 2]);
            if !cut_by_test {
                identify::figures::validate_svg(&f).unwrap_or_else(|e| {
                    panic!("round {round}: {e}");
                });
            }
        }
    }
    ok(&run(&args, &dir));
    assert_eq!(figures(&out), whole);
    no_staging(&out);
    eprintln!("{mid_drawing} of 30 kills landed while figures were being drawn");
}

#[test]
fn study_and_scaling_figures_are_put_in_place_whole() {
    let (_tmp, dir) = common::temp_dir("sysid-figures-studies-");
    std::fs::write(
        dir.join("mini.toml"),
        "name = \"mini\"\ndescription = \"figures test\"\n[data]\npreset = \"shear-chain\"\n\
         duration = 0.5\n[sweep]\nalgorithms = [\"mpf-ekf2\", \"mln-rbpf\"]\nruns = 2\n\
         master_seed = 3\nparticles = [20]\n[filter]\ntrace_every = 0\nloop_every = 0\n",
    )
    .unwrap();
    std::fs::write(
        dir.join("sc.toml"),
        "name = \"scaling\"\ndescription = \"figures test\"\n[data]\n\
         preset = \"building-chain\"\nduration = 0.5\n[sweep]\n\
         algorithms = [\"mpf-ekf2\", \"bootstrap\"]\nruns = 1\nmaster_seed = 5\n\
         particles = [20]\n[filter]\ntrace_every = 0\nloop_every = 0\nvalidate = false\n\
         [[sweep.structures]]\nlabel = \"n3\"\nstoreys = 3\nscale = 50.0\n\
         [[sweep.structures]]\nlabel = \"n4\"\nstoreys = 4\nscale = 25.0\n",
    )
    .unwrap();
    for (args, out) in [
        (
            vec![
                "study",
                "--config",
                "mini.toml",
                "--out",
                "st",
                "--threads",
                "1",
            ],
            "st",
        ),
        (
            vec![
                "scaling",
                "--config",
                "sc.toml",
                "--out",
                "sc",
                "--threads",
                "1",
            ],
            "sc",
        ),
        (
            vec![
                "excitations",
                "--config",
                "sc.toml",
                "--out",
                "ex",
                "--threads",
                "1",
            ],
            "ex",
        ),
    ] {
        ok(&run(&args, &dir));
        let out = dir.join(out);
        let whole = figures(&out);
        assert!(!whole.is_empty(), "{}: no figure", out.display());
        let first = whole.keys().next().unwrap().clone();
        cut_in_half(&first);
        let resume = [&args[..], &["--resume"]].concat();
        ok(&run(&resume, &dir));
        assert_eq!(figures(&out), whole, "{}", out.display());
        no_staging(&out);
        pipe_is_refused(&resume, &dir, &first);
    }
}
