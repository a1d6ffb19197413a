"""Bootstrap particle filter (SPEC §5.1) for the paper's 3-storey chain with the `particles` package.

An independent reference written with Nicolas Chopin's `particles` (PyPI), the way its
documentation builds a filter: a `StateSpaceModel` subclass stating the laws `PX0`, `PX(t, xp)`
and `PY(t, xp, x)` for all particles at once, `particles.state_space_models.Bootstrap` to turn it
into a Feynman–Kac model, and `particles.SMC` to run it, with the package's `Moments` collector
for the posterior mean at every step.

Model (SPEC §1, §3, §5.1): augmented state X = [x1 x2 x3 ẋ1 ẋ2 ẋ3 r1 | k1 k2 k3 c1 c2 c3 β γ n]
(16); forward Euler for the 7 dynamic states plus Gaussian process noise (Q of SPEC §3); θ copied
without noise; Y_t ~ N(ẍ(X_t, ü_g,meas), R). Priors of SPEC §3; zero initial states.

What the package imposes, and how it is matched to `sysid filter`:
- Time: `particles` weights X_0 by Y_0. The filters of this workspace start from the exact zero
  state at sample 0 and weight samples 1..T−1, so here Y_t is sample t+1 and `PX0` is the law of
  the state at sample 1 (the prior of θ, one Euler step from zero with its process noise).
- Resampling: the package resamples when ESS < ESSrmin · N; `ESSrmin=1.0` makes that every
  step (an ESS of exactly N needs all weights equal), scheme `systematic`.
- `PX0` and `PX` are small `ProbDist` subclasses: the transition is degenerate (no noise on θ),
  which the package's `MvNormal` (Cholesky of the covariance) does not accept, and the
  (β, γ) prior is not a product of univariate laws, which `IndepProd` needs. `PY` is the
  package's `MvNormal` with a per-particle mean.
- Random numbers: the package draws from numpy's global generator (`numpy.random`), so
  `--seed` seeds that generator; the transition draws from it too.
- The package's resampler is compiled by numba on first use: a short warm-up run (not timed)
  precedes the timed run.

Usage: python3 bootstrap_particles.py DATA_DIR [--particles 500] [--seed 1] [--json out.json]
"""

import argparse
import math
import os
import sys
import time
from importlib.metadata import version

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np
import particles
from particles import distributions as dists
from particles import state_space_models as ssm
from particles.collectors import Moments

from dataset import THETA_NAMES, WINDOW, DataSet, DataSetError, sample_theta, write_record


def euler_mean(X, ug, dt):
    """Forward Euler map of SPEC §3 applied to every particle's dynamic states (Np × 16 → Np × 7),
    with the excitation ü_g of the step's start."""
    x1, x2, x3, v1, v2, v3, r1 = (X[:, j] for j in range(7))
    beta, gamma, n = X[:, 13], X[:, 14], X[:, 15]
    abs_r_pow_n = np.abs(r1) ** n
    out = np.empty((X.shape[0], 7))
    out[:, 0] = x1 + dt * v1
    out[:, 1] = x2 + dt * v2
    out[:, 2] = x3 + dt * v3
    a = accelerations(X, ug)
    out[:, 3] = v1 + dt * a[:, 0]
    out[:, 4] = v2 + dt * a[:, 1]
    out[:, 5] = v3 + dt * a[:, 2]
    # Bouc–Wen (SPEC §1): ṙ = ẋ1 − β|ẋ1||r|^(n−1) r − γ ẋ1 |r|^n
    out[:, 6] = r1 + dt * (
        v1 - beta * np.abs(v1) * np.sign(r1) * abs_r_pow_n - gamma * v1 * abs_r_pow_n
    )
    return out


def accelerations(X, ug):
    """Relative accelerations ẍ1..ẍ3 of SPEC §1 for every particle (Np × 3)."""
    x1, x2, x3, v1, v2, v3, r1 = (X[:, j] for j in range(7))
    k1, k2, k3, c1, c2, c3 = (X[:, 7 + j] for j in range(6))
    a = np.empty((X.shape[0], 3))
    a[:, 0] = -ug - k1 * r1 + k2 * (x2 - x1) - c1 * v1 + c2 * (v2 - v1)
    a[:, 1] = -ug + k2 * (x1 - x2) + k3 * (x3 - x2) + c2 * (v1 - v2) + c3 * (v3 - v2)
    a[:, 2] = -ug + k3 * (x2 - x3) + c3 * (v2 - v3)
    return a


class EulerTransition(dists.ProbDist):
    """Law of X_t given X_{t−1}: Euler step plus N(0, diag(q²)) on the dynamic states, θ copied."""

    dim = 16

    def __init__(self, xp, ug, dt, q_sd):
        self.xp, self.ug, self.dt, self.q_sd = xp, ug, dt, q_sd

    def rvs(self, size=None):
        x = np.empty_like(self.xp)
        noise = self.q_sd * np.random.standard_normal((self.xp.shape[0], 7))
        x[:, :7] = euler_mean(self.xp, self.ug, self.dt) + noise
        x[:, 7:] = self.xp[:, 7:]
        return x


class PriorAtFirstSample(dists.ProbDist):
    """Law of X at sample 1: θ from the priors of SPEC §3, one Euler step from the zero state."""

    dim = 16

    def __init__(self, ug0, dt, q_sd):
        self.ug0, self.dt, self.q_sd = ug0, dt, q_sd

    def rvs(self, size=None):
        x0 = np.zeros((size, 16))
        x0[:, 7:] = sample_theta(np.random.standard_normal, np.random.random_sample, size)
        return EulerTransition(x0, self.ug0, self.dt, self.q_sd).rvs(size)


class BoucWenChain(ssm.StateSpaceModel):
    """The paper's 3-storey chain with hysteresis at the base (SPEC §1), augmented with θ.

    Parameters (keyword arguments): `ug` (measured excitation at every sample), `dt`, `q_sd`
    (7 process-noise s.d.), `r_cov` (3 × 3 measurement covariance). Time t of the package is
    sample t + 1 of the record.
    """

    def PX0(self):
        return PriorAtFirstSample(self.ug[0], self.dt, self.q_sd)

    def PX(self, t, xp):
        return EulerTransition(xp, self.ug[t], self.dt, self.q_sd)

    def PY(self, t, xp, x):
        return dists.MvNormal(loc=accelerations(x, self.ug[t + 1]), cov=self.r_cov)


def build_smc(data, particles_n, steps=None):
    q_sd = np.array([data.q_disp_sd] * 3 + [data.q_vel_sd] * 3 + [data.q_r_sd])
    model = BoucWenChain(ug=data.ug, dt=data.dt, q_sd=q_sd, r_cov=np.diag(data.r_diag))
    y = data.y[1:] if steps is None else data.y[1 : steps + 1]
    fk = ssm.Bootstrap(ssm=model, data=y)
    return particles.SMC(
        fk=fk,
        N=particles_n,
        resampling="systematic",
        ESSrmin=1.0,
        collect=[Moments()],
    )


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("data", help="data-set directory (measured.csv, dataset.json)")
    parser.add_argument("--particles", type=int, default=500)
    parser.add_argument("--seed", type=int, default=1, help="seed of numpy's global generator")
    parser.add_argument("--json", help="write a run record (JSON) to this file")
    args = parser.parse_args(argv)
    if args.particles < 1:
        parser.error("--particles must be at least 1")
    try:
        data = DataSet(args.data)
    except DataSetError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2

    np.random.seed(args.seed + 1_000_003)  # warm-up stream, apart from the run's
    build_smc(data, args.particles, steps=5).run()  # numba compiles the resampler here

    np.random.seed(args.seed)
    pf = build_smc(data, args.particles)
    start, start_cpu = time.perf_counter(), time.process_time()
    pf.run()
    wall, cpu = time.perf_counter() - start, time.process_time() - start_cpu
    steps = data.steps
    if not math.isfinite(pf.logLt):
        print(f"bootstrap (particles) failed: log-likelihood {pf.logLt}", file=sys.stderr)
        return 1
    means = np.array([m["mean"] for m in pf.summaries.moments])
    theta_val = means[-WINDOW:, 7:].mean(axis=0)
    ess = np.asarray(pf.summaries.ESSs)
    resampled = int(np.sum(pf.summaries.rs_flags))
    rate = args.particles * steps / wall
    print(
        f"bootstrap (particles {version('particles')}, numpy {np.__version__}): {steps} steps, "
        f"loglik {pf.logLt:.2f}, {wall:.2f} s ({rate / 1e6:.3f} M particle-steps/s), "
        f"resampled at {resampled} of {steps - 1} steps after the first, mean ESS {ess.mean():.1f}"
    )
    print("θ_val: " + " ".join(f"{n}={v:.4f}" for n, v in zip(THETA_NAMES, theta_val)))
    if args.json:
        write_record(
            args.json,
            {
                "implementation": "bootstrap_particles",
                "algorithm": "bootstrap",
                "particles_package": version("particles"),
                "numpy": np.__version__,
                "data": os.path.abspath(args.data),
                "seed": args.seed,
                "particles": args.particles,
                "steps": steps,
                "resampled_steps": resampled,
                "param_names": THETA_NAMES,
                "theta_true": data.theta_true.tolist(),
                "theta_val": theta_val.tolist(),
                "loglik": float(pf.logLt),
                "ess_mean": float(ess.mean()),
                "ess_min": float(ess.min()),
                "timing": {"wall_s": wall, "cpu_s": cpu, "particle_steps_per_s": rate},
            },
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
