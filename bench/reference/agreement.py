"""Do `sysid filter` and a reference implementation compute the same filter? θ_val over seeds.

Runs one algorithm (mln-rbpf or bootstrap) with filter seeds 1..S on one data set, on our side
(`sysid filter`) and with the reference script of this folder, one process at a time, and
prints per parameter the mean θ_val ± its Monte-Carlo standard error on each side, the run-to-run
s.d., and z = (difference of the means) / (standard error of the difference). Both sides draw
from different generators, so only the distributions can agree; |z| well above 3 for a
parameter points at a difference in the filters. The log-likelihood is heavy-tailed across
seeds (a few runs lose hundreds of nats), so it is compared by medians and a Mann–Whitney
rank test (scipy).

Usage: python3 agreement.py --algorithm mln-rbpf [--seeds 20] [--first-seed 1] [--sysid PATH]
                            [--data DIR] [--keep DIR]
"""

import argparse
import math
import os
import statistics
import subprocess
import sys
import tempfile

from compare import DEFAULT_SYSID, run_one
from dataset import THETA_NAMES


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--algorithm", choices=["mln-rbpf", "bootstrap"], required=True)
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--first-seed", type=int, default=1)
    parser.add_argument("--keep", help="keep the run records in this directory")
    parser.add_argument("--sysid", default=DEFAULT_SYSID)
    parser.add_argument("--data", help="data-set directory (default: simulate paper-3dof, seed 1)")
    parser.add_argument("--particles", type=int, default=500)
    args = parser.parse_args(argv)
    if args.seeds < 2:
        parser.error("--seeds must be at least 2 (a standard error needs two runs)")
    if not (os.path.isfile(args.sysid) and os.access(args.sysid, os.X_OK)):
        parser.error(f"--sysid: {args.sysid} is not an executable file")

    theta = {"ours": [], "theirs": []}
    loglik = {"ours": [], "theirs": []}
    with tempfile.TemporaryDirectory(prefix="sysid-agreement-") as tmp:
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
        keep = args.keep or tmp
        os.makedirs(keep, exist_ok=True)
        seeds = range(args.first_seed, args.first_seed + args.seeds)
        for seed in seeds:
            for side in ("ours", "theirs"):
                out = os.path.join(keep, f"{args.algorithm}_{side}_{seed}.json")
                result = run_one(args, args.algorithm, side, seed, out)
                theta[side].append(result["theta"])
                loglik[side].append(result["loglik"])
            print(
                f"seed {seed}: loglik ours {loglik['ours'][-1]:.1f}, "
                f"theirs {loglik['theirs'][-1]:.1f}",
                flush=True,
            )

    S = args.seeds
    if S < 10:
        print(f"note: with {S} seeds the standard errors, and so z, are rough; use 20 or more")
    print(
        f"\n{args.algorithm}, {args.particles} particles, filter seeds {seeds[0]}..{seeds[-1]}, "
        f"data {os.path.basename(os.path.normpath(args.data))}\n"
    )
    print("| parameter | ours: mean ± s.e. (s.d.) | reference: mean ± s.e. (s.d.) | z |")
    print("|---|---:|---:|---:|")
    for j, name in enumerate(THETA_NAMES):
        cells = []
        means, ses = [], []
        for side in ("ours", "theirs"):
            v = [t[j] for t in theta[side]]
            m, sd = statistics.fmean(v), statistics.stdev(v)
            means.append(m)
            ses.append(sd / math.sqrt(S))
            cells.append(f"{m:.3f} ± {sd / math.sqrt(S):.3f} ({sd:.3f})")
        z = (means[0] - means[1]) / math.hypot(*ses) if math.hypot(*ses) > 0 else float("nan")
        print(f"| {name} | {cells[0]} | {cells[1]} | {z:+.2f} |")
    from scipy.stats import mannwhitneyu

    p = mannwhitneyu(loglik["ours"], loglik["theirs"]).pvalue
    print(
        f"| log-likelihood, median (range) | {statistics.median(loglik['ours']):.1f} "
        f"({min(loglik['ours']):.1f} … {max(loglik['ours']):.1f}) | "
        f"{statistics.median(loglik['theirs']):.1f} "
        f"({min(loglik['theirs']):.1f} … {max(loglik['theirs']):.1f}) | "
        f"Mann–Whitney p = {p:.2f} |"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
