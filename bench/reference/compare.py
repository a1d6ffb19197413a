"""Particle-steps per second of `sysid filter` beside the independent references, on one data set.

In one invocation, for each round: `sysid filter --algorithm mln-rbpf`, `mlnrbpf_numpy.py`,
`sysid filter --algorithm bootstrap`, `bootstrap_particles.py` — one process at a time, in
that order, so each of our runs sits next to its reference in time (this host's speed drifts).
Every run uses the round's filter seed and the same particle count. Prints, per implementation,
the median and range of particle-steps/s over the rounds (wall time of the filter, as each
record reports it), and the ratio ours/theirs (ratio of the medians, and the range of the
per-round ratios); the same per CPU-second (ours: CPU time of the whole `sysid` process;
theirs: CPU time of the filter loop), which other jobs on a shared host do not stretch; the
share of a core each process got (its CPU time / its wall time) and the load average; and the
mean θ_val of the stiffnesses and the log-likelihood per implementation, as a check that both
sides computed the same filter.

Usage: python3 compare.py [--sysid PATH] [--data DIR] [--rounds 3] [--particles 500]
                          [--markdown FILE]
Without --data, a data set is made with `sysid simulate --preset paper-3dof --seed 1`.
"""

import argparse
import datetime
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from importlib.metadata import PackageNotFoundError, version

HERE = os.path.dirname(os.path.abspath(__file__))
DEFAULT_SYSID = "/work/bin/sysid-baseline"

#: (label, algorithm, side): side "ours" runs the sysid binary, "theirs" a script of this folder.
IMPLEMENTATIONS = [
    ("sysid mln-rbpf", "mln-rbpf", "ours"),
    ("numpy MLN-RBPF (mlnrbpf_numpy.py)", "mln-rbpf", "theirs"),
    ("sysid bootstrap", "bootstrap", "ours"),
    ("particles bootstrap (bootstrap_particles.py)", "bootstrap", "theirs"),
]
SCRIPTS = {"mln-rbpf": "mlnrbpf_numpy.py", "bootstrap": "bootstrap_particles.py"}


def run_one(args, algorithm, side, seed, out):
    if side == "ours":
        cmd = [
            args.sysid,
            "filter",
            "--algorithm",
            algorithm,
            "--data",
            args.data,
            "--particles",
            str(args.particles),
            "--seed",
            str(seed),
            "--out",
            out,
        ]
    else:
        cmd = [
            sys.executable,
            os.path.join(HERE, SCRIPTS[algorithm]),
            args.data,
            "--particles",
            str(args.particles),
            "--seed",
            str(seed),
            "--json",
            out,
        ]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    proc = subprocess.run(cmd, check=False, capture_output=True, text=True)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if proc.returncode != 0:
        raise SystemExit(
            f"error: {' '.join(cmd)} exited with {proc.returncode}:\n{proc.stderr.strip()}"
        )
    with open(out) as fh:
        record = json.load(fh)
    try:
        result = {
            "rate": float(record["timing"]["particle_steps_per_s"]),
            "theta": [float(v) for v in record["theta_val"]],
            "loglik": float(record["loglik"]),
            "share": cpu / wall,
        }
        if side == "ours":
            # The whole process's CPU time (start-up, reading, validation and writing included,
            # about 2% of a run): slightly understates our rate per CPU-second.
            steps = float(record["steps_total"]) * float(record["particles"])
            result["cpu_rate"] = steps / cpu
        else:
            steps = float(record["steps"]) * float(record["particles"])
            result["cpu_rate"] = steps / float(record["timing"]["cpu_s"])
    except (KeyError, TypeError, ValueError) as err:
        raise SystemExit(f"error: {out}: missing or bad field ({err})") from None
    return result


def cpu_model():
    try:
        text = subprocess.run(["lscpu"], capture_output=True, text=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        return platform.processor() or "unknown"
    for line in text.splitlines():
        if line.startswith("Model name:"):
            return line.split(":", 1)[1].strip()
    return "unknown"


def package_version(name):
    try:
        return version(name)
    except PackageNotFoundError:
        return "not installed"


def ratio_cell(ours, theirs):
    """Ratio of the medians, and the range of the per-round ratios (runs next to each other)."""
    paired = [o / t for o, t in zip(ours, theirs)]
    return (
        f"{statistics.median(ours) / statistics.median(theirs):.1f}× "
        f"({min(paired):.1f}–{max(paired):.1f})"
    )


def fmt_rate(x):
    return f"{x / 1e6:.3f} M"


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument(
        "--sysid", default=DEFAULT_SYSID, help=f"sysid binary (default {DEFAULT_SYSID})"
    )
    parser.add_argument("--data", help="data-set directory (default: simulate paper-3dof, seed 1)")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--particles", type=int, default=500)
    parser.add_argument("--markdown", help="also write the tables as Markdown to this file")
    args = parser.parse_args(argv)
    if args.rounds < 1:
        parser.error("--rounds must be at least 1")
    if not (os.path.isfile(args.sysid) and os.access(args.sysid, os.X_OK)):
        parser.error(f"--sysid: {args.sysid} is not an executable file")

    with tempfile.TemporaryDirectory(prefix="sysid-compare-") as tmp:
        if args.data is None:
            args.data = os.path.join(tmp, "data")
            subprocess.run(
                [
                    args.sysid,
                    "simulate",
                    "--preset",
                    "paper-3dof",
                    "--seed",
                    "1",
                    "--out",
                    args.data,
                ],
                check=True,
                capture_output=True,
            )
        results = {label: [] for label, _, _ in IMPLEMENTATIONS}
        load_before = os.getloadavg()[0]
        for rnd in range(1, args.rounds + 1):
            for i, (label, algorithm, side) in enumerate(IMPLEMENTATIONS):
                out = os.path.join(tmp, f"r{rnd}_{i}.json")
                res = run_one(args, algorithm, side, rnd, out)
                results[label].append(res)
                print(
                    f"round {rnd}: {label:46s} {fmt_rate(res['rate'])} particle-steps/s, "
                    f"{fmt_rate(res['cpu_rate'])} per CPU-second, {100 * res['share']:.0f}% of a core",
                    flush=True,
                )
        load_after = os.getloadavg()[0]

    lines = [
        (
            f"date: {datetime.datetime.now(datetime.UTC):%Y-%m-%d %H:%M} UTC; "
            f"CPU: {cpu_model()} ({os.cpu_count()} logical CPUs); Python {platform.python_version()}, "
            f"numpy {package_version('numpy')}, particles {package_version('particles')}; "
            f"{args.particles} particles, {args.rounds} rounds, data {os.path.basename(os.path.normpath(args.data))}; "
            f"1-minute load average {load_before:.1f} at the start, {load_after:.1f} at the end"
        ),
        "",
        (
            "| implementation | particle-steps/s, median | range | ratio ours/theirs | "
            "per CPU-second, median | ratio ours/theirs | share of a core |"
        ),
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for label, algorithm, side in IMPLEMENTATIONS:
        rate = [r["rate"] for r in results[label]]
        cpu_rate = [r["cpu_rate"] for r in results[label]]
        share = [r["share"] for r in results[label]]
        ratio = cpu_ratio = ""
        if side == "theirs":
            ours = next(lb for lb, alg, sd in IMPLEMENTATIONS if alg == algorithm and sd == "ours")
            ratio = ratio_cell([r["rate"] for r in results[ours]], rate)
            cpu_ratio = ratio_cell([r["cpu_rate"] for r in results[ours]], cpu_rate)
        lines.append(
            f"| {label} | {fmt_rate(statistics.median(rate))} | "
            f"{fmt_rate(min(rate))} – {fmt_rate(max(rate))} | {ratio} | "
            f"{fmt_rate(statistics.median(cpu_rate))} | {cpu_ratio} | "
            f"{100 * min(share):.0f}–{100 * max(share):.0f}% |"
        )
    lines += [
        "",
        "| implementation | mean θ_val k1, k2, k3 over the rounds | log-likelihood per round |",
        "|---|---|---|",
    ]
    for label, _, _ in IMPLEMENTATIONS:
        k = [statistics.fmean(r["theta"][j] for r in results[label]) for j in range(3)]
        lines.append(
            f"| {label} | {', '.join(f'{v:.3f}' for v in k)} | "
            f"{', '.join(format(r['loglik'], '.1f') for r in results[label])} |"
        )
    text = "\n".join(lines)
    print()
    print(text)
    if args.markdown:
        with open(args.markdown, "w") as fh:
            fh.write(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
