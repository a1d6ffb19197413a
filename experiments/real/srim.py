"""SRIM (the subspace method of the PyPI package `mdof`) on the three-storey frame: the linear
black-box baseline of the real-frame case study (`results/real/REPORT.md`).

Trained on one imported record (input: the table's acceleration; outputs: the three floors'
absolute accelerations; every `a*` column), then simulated in free run from a zero state, driven by the measured
table motion of every record, and scored with the fit of `sysid validate`:
fit = 100·(1 − ‖y − ŷ‖/‖y − ȳ‖) per floor. Orders 6 … 16 are tried (horizon 300, mdof's default) (a 3-storey shear building
has order 6; SRIM usually needs more to absorb what is not a shear building); the order with the
best mean fit on the training record is "SRIM's best model", the others are reported too.

    python experiments/real/srim.py --train DIR --validate DIR... --out results/real/srim.json

DIR is a data set written by `sysid import` (measured.csv with columns t, ug, a1, …).
"""

import argparse
import importlib.metadata
import json
import platform
import sys
import time

import numpy as np


def read(path):
    data = np.genfromtxt(f"{path}/measured.csv", delimiter=",", names=True)
    ug = np.asarray(data["ug"], dtype=float)
    channels = [n for n in data.dtype.names if n.startswith("a")]
    ys = np.vstack([np.asarray(data[c], dtype=float) for c in channels])
    t = np.asarray(data["t"], dtype=float)
    return float(np.median(np.diff(t))), ug, ys


def fit(y, yhat):
    return 100.0 * (1.0 - np.linalg.norm(y - yhat) / np.linalg.norm(y - y.mean()))


def simulate(a, b, c, d, u):
    x = np.zeros(a.shape[0])
    out = np.empty((c.shape[0], u.size))
    for k, uk in enumerate(u):
        out[:, k] = c @ x + d[:, 0] * uk
        x = a @ x + b[:, 0] * uk
    return out


def modes(a, dt):
    lam = np.log(np.linalg.eigvals(a).astype(complex)) / dt
    keep = lam.imag > 0
    f = np.abs(lam[keep]) / (2 * np.pi)
    z = -lam[keep].real / np.abs(lam[keep])
    order = np.argsort(f)
    return [{"frequency_hz": float(f[i]), "damping_ratio": float(z[i])} for i in order]


def main():
    from mdof.realize import srim

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--train", required=True)
    p.add_argument("--validate", nargs="*", default=[])
    p.add_argument("--orders", default="6,8,10,12,14,16")
    p.add_argument("--horizon", type=int, default=300)
    p.add_argument("--out", required=True)
    args = p.parse_args()
    dt, ug, ys = read(args.train)
    others = {path: read(path) for path in args.validate}
    runs = []
    for order in [int(o) for o in args.orders.split(",")]:
        start = time.perf_counter()
        a, b, c, d = srim(ug[None, :], ys, horizon=args.horizon, order=order, threads=1)
        seconds = time.perf_counter() - start
        rho = float(np.max(np.abs(np.linalg.eigvals(a))))
        fits = {}
        for name, (_, u, y) in [(args.train, (dt, ug, ys))] + list(others.items()):
            if rho >= 1.0:
                fits[name] = None
                continue
            yhat = simulate(a, b, c, d, u)
            fits[name] = [float(fit(y[j], yhat[j])) for j in range(y.shape[0])]
        runs.append({
            "order": order,
            "spectral_radius": rho,
            "modes": modes(a, dt),
            "fits": fits,
            "seconds": seconds,
        })
        print(f"order {order:2d}: fits on the training record "
              f"{fits[args.train]} ({seconds:.1f} s)", file=sys.stderr)
    stable = [r for r in runs if r["fits"][args.train] is not None]
    if not stable:
        sys.exit(f"srim.py: no order gave a stable model on {args.train}")
    best = max(stable, key=lambda r: float(np.mean(r["fits"][args.train])))
    out = {
        "method": "SRIM (mdof.realize.srim), free run from a zero state",
        "mdof_version": importlib.metadata.version("mdof"),
        "numpy_version": np.__version__,
        "python_version": platform.python_version(),
        "command": " ".join(["python"] + sys.argv),
        "train": args.train,
        "horizon": args.horizon,
        "best_order": best["order"],
        "runs": runs,
    }
    with open(args.out, "w") as f:
        json.dump(out, f, indent=1)
        f.write("\n")


if __name__ == "__main__":
    main()
