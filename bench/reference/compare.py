#!/usr/bin/env python3
"""Particle-steps per second of `sysid filter` beside the independent references, on one data set.

In one invocation, for each round: `sysid filter --algorithm mln-rbpf`, `mlnrbpf_numpy.py`,
`sysid filter --algorithm bootstrap`, `bootstrap_particles.py` — one process at a time, in
that order, so each of our runs sits next to its reference in time (this host's speed drifts).
Every run uses the round's filter seed and the same particle count. Prints, per implementation,
the median and range of particle-steps/s over the rounds, and the ratio ours/theirs (ratio of
the medians, and the range of the per-round ratios); plus the mean θ_val of the stiffnesses and
the log-likelihood per implementation, as a check that both sides computed the same filter;
and the share of a core each process got (its CPU time / its wall time) with the load average,
because on a shared host other jobs stretch every wall-clock figure.

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
        rate = float(record["timing"]["particle_steps_per_s"])
        theta = [float(v) for v in record["theta_val"]]
        loglik = float(record["loglik"])
    except (KeyError, TypeError, ValueError) as err:
        raise SystemExit(f"error: {out}: missing or bad field ({err})") from None
    return rate, theta, loglik, cpu / wall


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
        rates = {label: [] for label, _, _ in IMPLEMENTATIONS}
        thetas = {label: [] for label, _, _ in IMPLEMENTATIONS}
        logliks = {label: [] for label, _, _ in IMPLEMENTATIONS}
        shares = {label: [] for label, _, _ in IMPLEMENTATIONS}
        load_before = os.getloadavg()[0]
        for rnd in range(1, args.rounds + 1):
            for i, (label, algorithm, side) in enumerate(IMPLEMENTATIONS):
                out = os.path.join(tmp, f"r{rnd}_{i}.json")
                rate, theta, loglik, share = run_one(args, algorithm, side, rnd, out)
                rates[label].append(rate)
                shares[label].append(share)
                thetas[label].append(theta)
                logliks[label].append(loglik)
                print(
                    f"round {rnd}: {label:46s} {fmt_rate(rate)} particle-steps/s, "
                    f"{100 * share:.0f}% of a core",
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
        "| implementation | particle-steps/s, median | range | ratio ours/theirs (median; per-round range) | share of a core (CPU / wall of the process) |",
        "|---|---:|---:|---:|---:|",
    ]
    for label, algorithm, side in IMPLEMENTATIONS:
        r = rates[label]
        ratio = ""
        if side == "theirs":
            ours = next(lb for lb, alg, sd in IMPLEMENTATIONS if alg == algorithm and sd == "ours")
            paired = [o / t for o, t in zip(rates[ours], r)]
            ratio = (
                f"{statistics.median(rates[ours]) / statistics.median(r):.1f}× "
                f"({min(paired):.1f}–{max(paired):.1f})"
            )
        lines.append(
            f"| {label} | {fmt_rate(statistics.median(r))} | "
            f"{fmt_rate(min(r))} – {fmt_rate(max(r))} | {ratio} | "
            f"{100 * min(shares[label]):.0f}–{100 * max(shares[label]):.0f}% |"
        )
    lines += [
        "",
        "| implementation | mean θ_val k1, k2, k3 over the rounds | log-likelihood per round |",
        "|---|---|---|",
    ]
    for label, _, _ in IMPLEMENTATIONS:
        k = [statistics.fmean(t[j] for t in thetas[label]) for j in range(3)]
        lines.append(
            f"| {label} | {', '.join(f'{v:.3f}' for v in k)} | "
            f"{', '.join(f'{v:.1f}' for v in logliks[label])} |"
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
