"""MLN-RBPF (SPEC §5.2) for the paper's 3-storey chain, vectorised across particles with numpy.

An independent reference: written from SPEC §1–3 and §5.2 only, sharing no code with the Rust
workspace. Partition (SPEC §5.2): sampled u = [x1 x2 x3 ẋ1 ẋ2 ẋ3 r1 n], marginalised
z = [k1 k2 k3 c1 c2 c3 β γ] with a Gaussian N(μ, C) per particle; forward Euler; systematic
resampling at every step. All particles advance together: the per-particle 4 × 8, 3 × 8 and
8 × 8 matrices are stacked into (Np, ·, ·) arrays and combined with batched `matmul`,
`np.linalg.cholesky` and `np.linalg.solve` on the stacks.

Usage: python3 mlnrbpf_numpy.py DATA_DIR [--particles 500] [--seed 1] [--json out.json]
"""

import argparse
import math
import os
import sys
import time

# One thread, like one `sysid filter` run (the stacked small-matrix calls do not thread anyway).
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np

from dataset import (
    THETA_NAMES,
    WINDOW,
    DataSet,
    DataSetError,
    marginal_prior,
    write_record,
)

LOG_2PI = math.log(2 * math.pi)


class FilterFailure(Exception):
    """All weights zero or a covariance that is not positive definite, at a given step."""


def measurement_matrix(u):
    """H(u) of SPEC §5.2 for every particle: (Np, 3, 8); ẍ = H(u) z − ü_g."""
    x1, x2, x3, v1, v2, v3, r1 = (u[:, j] for j in range(7))
    H = np.zeros((u.shape[0], 3, 8))
    H[:, 0, 0] = -r1
    H[:, 0, 1] = x2 - x1
    H[:, 0, 3] = -v1
    H[:, 0, 4] = v2 - v1
    H[:, 1, 1] = x1 - x2
    H[:, 1, 2] = x3 - x2
    H[:, 1, 4] = v1 - v2
    H[:, 1, 5] = v3 - v2
    H[:, 2, 2] = x2 - x3
    H[:, 2, 5] = v2 - v3
    return H


def mln_rbpf(data, particles, seed):
    """Runs the filter over the whole record; returns θ_k per step, the log-likelihood, the
    ESS per step and the wall time of the time loop."""
    rng = np.random.default_rng(seed)
    Np, dt, T = particles, data.dt, data.steps
    mu0, C0 = marginal_prior()

    # Sampled block u: zero initial states, n ~ U(1, 5) (SPEC §3).
    u = np.zeros((Np, 8))
    u[:, 7] = rng.uniform(1.0, 5.0, size=Np)
    mu = np.tile(mu0, (Np, 1))
    C = np.tile(C0, (Np, 1, 1))

    # Noise of rows 4–7 of u (velocities, r1): the rows that observe z through F (SPEC §5.2 (b)).
    Q4 = np.diag([data.q_vel_sd**2] * 3 + [data.q_r_sd**2])
    R = np.diag(data.r_diag)
    y_all, ug = data.y, data.ug

    theta_mean = np.empty((T, 9))
    ess = np.empty(T)
    loglik = 0.0
    F4 = np.zeros((Np, 4, 8))

    start, start_cpu = time.perf_counter(), time.process_time()
    for k in range(1, T + 1):
        x, v, r1, n = u[:, 0:3], u[:, 3:6], u[:, 6], u[:, 7]
        v1 = v[:, 0]

        # (a) proposal with z marginalised: u_k ~ N(f + F μ, F C Fᵀ + Q_u), rows 4–7 only
        # (rows 1–3 of F are zero, row 8 copies n).
        F4[:, 0:3, :] = dt * measurement_matrix(u)
        abs_r_pow_n = np.abs(r1) ** n
        F4[:, 3, 6] = -dt * np.abs(v1) * np.sign(r1) * abs_r_pow_n
        F4[:, 3, 7] = -dt * v1 * abs_r_pow_n
        f4 = np.empty((Np, 4))
        f4[:, 0:3] = v - dt * ug[k - 1]
        f4[:, 3] = r1 + dt * v1
        pred4 = f4 + np.einsum("nij,nj->ni", F4, mu)
        FC = F4 @ C  # (Np, 4, 8)
        S = FC @ F4.transpose(0, 2, 1) + Q4
        try:
            S_chol = np.linalg.cholesky(S)
        except np.linalg.LinAlgError as err:
            raise FilterFailure(f"step {k}: proposal covariance: {err}") from None
        innov4 = np.einsum("nij,nj->ni", S_chol, rng.standard_normal((Np, 4)))
        u_new = np.empty_like(u)
        u_new[:, 0:3] = x + dt * v + data.q_disp_sd * rng.standard_normal((Np, 3))
        u_new[:, 3:7] = pred4 + innov4
        u_new[:, 7] = n

        # (b) pseudo-measurement update of (μ, C) with u_k rows 4–7: Kᵀ = S⁻¹ F C.
        KT = np.linalg.solve(S, FC)
        mu = mu + np.einsum("nij,ni->nj", KT, innov4)
        C = C - FC.transpose(0, 2, 1) @ KT
        C = 0.5 * (C + C.transpose(0, 2, 1))
        u = u_new

        # (c) weight: N(y_k; H(u_k) μ + h, H C Hᵀ + R).
        H = measurement_matrix(u)
        HC = H @ C  # (Np, 3, 8)
        L = HC @ H.transpose(0, 2, 1) + R
        e = y_all[k] - (np.einsum("nij,nj->ni", H, mu) - ug[k])
        try:
            L_chol = np.linalg.cholesky(L)
        except np.linalg.LinAlgError as err:
            raise FilterFailure(f"step {k}: innovation covariance: {err}") from None
        # One batched solve gives the gain and the whitened innovation: L⁻¹ [H C | e].
        sol = np.linalg.solve(L, np.concatenate([HC, e[:, :, None]], axis=2))
        KT, Linv_e = sol[:, :, :8], sol[:, :, 8]
        log_det = 2.0 * np.log(np.diagonal(L_chol, axis1=1, axis2=2)).sum(axis=1)
        log_w = -0.5 * (np.einsum("ni,ni->n", e, Linv_e) + log_det + 3 * LOG_2PI)
        log_w[~np.isfinite(log_w)] = -np.inf

        # (d) KF update of (μ, C) with y_k.
        mu = mu + np.einsum("nij,ni->nj", KT, e)
        C = C - HC.transpose(0, 2, 1) @ KT
        C = 0.5 * (C + C.transpose(0, 2, 1))

        # (e) normalise (log-sum-exp), estimate, resample (u, μ, C) jointly.
        w_max = log_w.max()
        if not np.isfinite(w_max):
            raise FilterFailure(f"step {k}: all weights zero")
        w = np.exp(log_w - w_max)
        w_sum = w.sum()
        loglik += w_max + math.log(w_sum / Np)
        W = w / w_sum
        ess[k - 1] = 1.0 / np.dot(W, W)
        theta_mean[k - 1, 0:8] = W @ mu
        theta_mean[k - 1, 8] = W @ u[:, 7]
        cdf = np.cumsum(W)
        cdf[-1] = 1.0
        a = np.searchsorted(cdf, (rng.random() + np.arange(Np)) / Np)
        u, mu, C = u[a], mu[a], C[a]
    wall, cpu = time.perf_counter() - start, time.process_time() - start_cpu
    return theta_mean, loglik, ess, wall, cpu


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("data", help="data-set directory (measured.csv, dataset.json)")
    parser.add_argument("--particles", type=int, default=500)
    parser.add_argument("--seed", type=int, default=1, help="seed of numpy's PCG64 generator")
    parser.add_argument("--json", help="write a run record (JSON) to this file")
    args = parser.parse_args(argv)
    if args.particles < 1:
        parser.error("--particles must be at least 1")
    try:
        data = DataSet(args.data)
    except DataSetError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    try:
        theta_mean, loglik, ess, wall, cpu = mln_rbpf(data, args.particles, args.seed)
    except FilterFailure as err:
        print(f"mln-rbpf (numpy) failed: {err}", file=sys.stderr)
        return 1
    theta_val = theta_mean[-WINDOW:].mean(axis=0)
    rate = args.particles * data.steps / wall
    print(
        f"mln-rbpf (numpy {np.__version__}): {data.steps} steps, loglik {loglik:.2f}, "
        f"{wall:.2f} s ({rate / 1e6:.3f} M particle-steps/s), mean ESS {ess.mean():.1f}"
    )
    print("θ_val: " + " ".join(f"{n}={v:.4f}" for n, v in zip(THETA_NAMES, theta_val)))
    if args.json:
        write_record(
            args.json,
            {
                "implementation": "mlnrbpf_numpy",
                "algorithm": "mln-rbpf",
                "numpy": np.__version__,
                "data": os.path.abspath(args.data),
                "seed": args.seed,
                "particles": args.particles,
                "steps": data.steps,
                "param_names": THETA_NAMES,
                "theta_true": data.theta_true.tolist(),
                "theta_val": theta_val.tolist(),
                "loglik": loglik,
                "ess_mean": float(ess.mean()),
                "ess_min": float(ess.min()),
                "timing": {"wall_s": wall, "cpu_s": cpu, "particle_steps_per_s": rate},
            },
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
