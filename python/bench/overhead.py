"""Python call overhead against `sysid filter`, end to end, side by side.

Alternates, round by round, `sysid filter --algorithm A --data D --particles N --seed S --out F`
and a Python process that does the same through the package
(`sm.identify(sm.load_dataset(D), algorithm=A, particles=N, seed=S, out=F)`, interpreter start-up
and `import sysid_mpf` included), each as a child process; reports the median wall and CPU times
(user + system of the child) and their ratios, and checks that both wrote the same θ_val and
log-likelihood bits. The start-up of a Python process that only imports the package is timed
alongside, so that the call's own overhead (Python CPU − start-up − sysid CPU) is reported too.

    python python/bench/overhead.py --sysid target/release/sysid --data DIR [--rounds 7]
"""

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time

PY_CALL = (
    "import sys, sysid_mpf as sm; "
    "sm.identify(sm.load_dataset(sys.argv[1]), algorithm=sys.argv[2], "
    "particles=int(sys.argv[3]), seed=int(sys.argv[4]), out=sys.argv[5])"
)


def timed(cmd):
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    p = subprocess.run(cmd, capture_output=True, text=True, stdin=subprocess.DEVNULL)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if p.returncode != 0 and "physically impossible" not in p.stderr:
        raise SystemExit(f"{' '.join(cmd)} failed:\n{p.stderr}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sysid", default="target/release/sysid")
    ap.add_argument("--data", required=True, help="data-set directory (sysid simulate)")
    ap.add_argument("--algorithms", default="mln-rbpf,mpf-ekf2,storvik,bootstrap")
    ap.add_argument("--particles", type=int, default=500)
    ap.add_argument("--rounds", type=int, default=7)
    args = ap.parse_args(argv)
    tmp = tempfile.mkdtemp()
    print(f"# {args.particles} particles, {args.rounds} rounds, data {args.data}")
    print(
        "| algorithm | sysid filter CPU (s) | Python CPU (s) | ratio | of which start-up + import (s) "
        "| ratio without start-up | sysid wall (s) | Python wall (s) | same bits |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|---|")
    for alg in args.algorithms.split(","):
        cli, py, start = [], [], []
        same = True
        for r in range(args.rounds):
            seed = str(r + 1)
            a, b = os.path.join(tmp, "cli.json"), os.path.join(tmp, "py.json")
            pair = [
                ("cli", [args.sysid, "filter", "--algorithm", alg, "--data", args.data,
                         "--particles", str(args.particles), "--seed", seed, "--out", a]),
                ("py", [sys.executable, "-c", PY_CALL, args.data, alg, str(args.particles), seed, b]),
            ]
            if r % 2:
                pair.reverse()
            for side, cmd in pair:
                (cli if side == "cli" else py).append(timed(cmd))
            start.append(timed([sys.executable, "-c", "import sysid_mpf"]))
            ra, rb = (json.load(open(p)) for p in (a, b))
            same &= ra["theta_val"] == rb["theta_val"] and ra["loglik"] == rb["loglik"]
        cw, cc = (statistics.median(x[i] for x in cli) for i in (0, 1))
        pw, pc = (statistics.median(x[i] for x in py) for i in (0, 1))
        sc = statistics.median(x[1] for x in start)
        print(
            f"| {alg} | {cc:.3f} | {pc:.3f} | {pc / cc:.3f} | {sc:.3f} | {(pc - sc) / cc:.3f} "
            f"| {cw:.2f} | {pw:.2f} | {'yes' if same else 'NO'} |"
        )
        sys.stdout.flush()


if __name__ == "__main__":
    main()
