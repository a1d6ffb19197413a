"""The package's identification beside the Python references of bench/reference, in one process.

Round by round, in this Python process: `sysid_mpf.identify` (the paper's settings: resampling
at every step, one filter, forward Euler — what the references compute) against the vectorised
numpy MLN-RBPF (`bench/reference/mlnrbpf_numpy.py`) and against the bootstrap PF of the
`particles` package (`bench/reference/bootstrap_particles.py`), same data, particles and seed.
Speed is particle-steps per CPU-second: for the package the CPU time of the whole `identify`
call (set-up, residuals and validation included), for the references that of their filter loop
(as they report it; numba's compilation excluded).

    pip install -r bench/reference/requirements.txt && pip install ./python
    python python/bench/references.py --data DIR [--rounds 3]
"""

import os

for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(var, "1")

import argparse  # noqa: E402
import contextlib  # noqa: E402
import io  # noqa: E402
import json  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402

import sysid_mpf as sm  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "..", "bench", "reference"))

import bootstrap_particles  # noqa: E402
import mlnrbpf_numpy  # noqa: E402

REFERENCES = {"mln-rbpf": mlnrbpf_numpy, "bootstrap": bootstrap_particles}
LABELS = {
    "mln-rbpf": "numpy MLN-RBPF (bench/reference/mlnrbpf_numpy.py)",
    "bootstrap": "`particles` bootstrap PF (bench/reference/bootstrap_particles.py)",
}


def ours(data, algorithm, particles, seed):
    start = time.process_time()
    r = sm.identify(data, algorithm=algorithm, particles=particles, seed=seed, config={})
    cpu = time.process_time() - start
    return particles * r.steps_total / cpu


def theirs(module, data_dir, particles, seed, out):
    with contextlib.redirect_stdout(io.StringIO()):
        code = module.main([data_dir, "--particles", str(particles), "--seed", str(seed), "--json", out])
    if code:
        raise SystemExit(f"{module.__name__} failed with {code}")
    with open(out) as fh:
        rec = json.load(fh)
    return rec["particles"] * rec["steps"] / rec["timing"]["cpu_s"]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", required=True, help="data-set directory (sysid simulate)")
    ap.add_argument("--particles", type=int, default=500)
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args(argv)
    data = sm.load_dataset(args.data)
    out = os.path.join(tempfile.mkdtemp(), "ref.json")
    print(f"# {args.particles} particles, {args.rounds} rounds, data {args.data}, one process")
    print("| algorithm | sysid_mpf (M particle-steps per CPU-s) | reference | reference (M/CPU-s) | ratio |")
    print("|---|---:|---|---:|---:|")
    for alg, module in REFERENCES.items():
        a, b = [], []
        for r in range(args.rounds):
            seed = r + 1
            a.append(ours(data, alg, args.particles, seed))
            b.append(theirs(module, args.data, args.particles, seed, out))
        ma, mb = statistics.median(a), statistics.median(b)
        print(f"| {alg} | {ma / 1e6:.3f} | {LABELS[alg]} | {mb / 1e6:.3f} | {ma / mb:.1f} |")
        sys.stdout.flush()


if __name__ == "__main__":
    main()
