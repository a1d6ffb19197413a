"""A real record sampled more coarsely (docs/real-frame.md, "The frame sampled coarsely"): every
channel of an imported data set (`measured.csv`: t, ug, a1, …) low-passed and kept one sample in
Q (scipy's `decimate`, a zero-phase FIR filter, so that nothing above the new Nyquist frequency
folds back and no channel is delayed against another), written as a data set of its own.

The shake-table frame's modes (3.68 / 11.13 / 16.56 Hz at 120 Hz) then sit where a frame two or
three times stiffer, logged at the same rate, has its own: Q = 2 puts the third mode at
ω·dt = 1.73, Q = 3 at 2.60, past the semi-implicit Euler step's stability limit of 2.

    python experiments/real/decimate.py --data results/real/frame/data/northridge --q 2 --out DIR
    sysid filter --algorithm mpf-ekf2 --data DIR --storeys 3 --hysteretic none --masses 1 \\
        --measurement absolute --out run.json

Needs numpy and scipy (installed with mdof, experiments/real/requirements.txt).
"""

import argparse
import os

import numpy as np
from scipy.signal import decimate


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", required=True, help="data-set directory with measured.csv")
    p.add_argument("--q", type=int, required=True, help="keep one sample in Q (2 or more)")
    p.add_argument("--out", required=True, help="new data-set directory")
    a = p.parse_args()
    if a.q < 2:
        p.error("--q must be 2 or more")
    src = os.path.join(a.data, "measured.csv")
    with open(src) as f:
        header = f.readline().strip().split(",")
    if header[:2] != ["t", "ug"]:
        raise SystemExit(f"{src}: line 1: expected the columns t, ug, a1, … (found {header})")
    table = np.loadtxt(src, delimiter=",", skiprows=1, ndmin=2)
    t = table[:, 0]
    steps = np.diff(t)
    dt = float(np.mean(steps))
    if np.max(np.abs(steps - dt)) > 1e-3 * dt:
        raise SystemExit(f"{src}: the samples are not evenly spaced")
    columns = [decimate(table[:, j], a.q, ftype="fir", zero_phase=True) for j in range(1, len(header))]
    n = len(columns[0])
    os.makedirs(a.out, exist_ok=False)
    with open(os.path.join(a.out, "measured.csv"), "w") as f:
        f.write(",".join(header) + "\n")
        for k in range(n):
            row = [f"{round(k * dt * a.q, 6)!r}"] + [repr(float(c[k])) for c in columns]
            f.write(",".join(row) + "\n")
    print(f"{a.out}: {n} samples at dt = {dt * a.q:.6f} s (from {len(t)} at {dt:.6f} s)")


if __name__ == "__main__":
    main()
