"""Reading a data set written by `sysid simulate` and the filter settings of SPEC §3.

Shared by the reference implementations so that both use the same data, noise levels and priors
as `sysid filter`, and nothing else. Every value is derived here from the data set itself:
dt from `dataset.json` (checked against the time column), R and Q from its clean-signal RMS
values (SPEC §3), the prior of SPEC §3 with the moment-matched Gaussian of the marginalised
block.
"""

import csv
import json
import math
import os

import numpy as np

#: Names of θ in the order of SPEC §1 (and of `sysid`'s records).
THETA_NAMES = ["k1", "k2", "k3", "c1", "c2", "c3", "beta", "gamma", "n"]

#: Prior hyper-parameters of SPEC §3.
K_MEDIAN, K_LOG_SD = 10.0, 0.3
C_MEDIAN, C_LOG_SD = 0.4, 0.5
BETA_MAX = 5.0
N_LO, N_HI = 1.0, 5.0

#: Measurement and process noise as fractions of the clean-signal RMS (SPEC §2–3).
NOISE_FRACTION = 0.1
R1_NOISE_FRACTION = 0.05
DISP_SD = 1e-6

#: Steps at the end of the record over which θ_val is averaged (SPEC §7, eq. 26).
WINDOW = 80


class DataSetError(Exception):
    """A data set that cannot be read, with the file, line and field at fault."""


class DataSet:
    """The measured record and the filter settings derived from one data-set directory.

    Attributes: `t`, `ug` (measured excitation), `y` (T × 3 measured relative accelerations),
    `dt`, `theta_true`, `r_diag` (SPEC §3 R), `q_disp_sd`, `q_vel_sd`, `q_r_sd` (SPEC §3 Q).
    """

    def __init__(self, directory):
        self.directory = directory
        meta_path = os.path.join(directory, "dataset.json")
        csv_path = os.path.join(directory, "measured.csv")
        try:
            with open(meta_path) as fh:
                meta = json.load(fh)
        except (OSError, ValueError) as err:
            raise DataSetError(f"{meta_path}: {err}") from err
        self.dt = _number(meta, "dt", meta_path)
        rms = _field(meta, "rms", meta_path)
        acc_rms = np.asarray(_field(rms, "acc", meta_path, "rms.acc"), dtype=float)
        ug_rms = float(_field(rms, "ug", meta_path, "rms.ug"))
        vel_rms = np.asarray(_field(rms, "vel", meta_path, "rms.vel"), dtype=float)
        if acc_rms.shape != (3,) or vel_rms.shape != (3,):
            raise DataSetError(f"{meta_path}: field rms.acc / rms.vel: expected 3 storeys")
        self.theta_true = np.asarray(_field(meta, "theta_true", meta_path), dtype=float)
        if self.theta_true.shape != (9,):
            raise DataSetError(f"{meta_path}: field theta_true: expected 9 values")

        # SPEC §3: R_ii = (0.1 RMS ẍ_i)² + (0.1 RMS ü_g)²; Q of displacements, velocities, r1.
        self.r_diag = (NOISE_FRACTION * acc_rms) ** 2 + (NOISE_FRACTION * ug_rms) ** 2
        self.q_disp_sd = DISP_SD
        self.q_vel_sd = self.dt * NOISE_FRACTION * ug_rms
        self.q_r_sd = self.dt * R1_NOISE_FRACTION * vel_rms[0]

        self.t, self.ug, self.y = _read_measured(csv_path)
        samples = meta.get("samples")
        if samples is not None and samples != len(self.t):
            raise DataSetError(
                f"{meta_path}: field samples: {samples}, but {csv_path} has {len(self.t)} rows"
            )
        if len(self.t) < WINDOW + 2:
            raise DataSetError(f"{csv_path}: {len(self.t)} rows, need at least {WINDOW + 2}")
        steps = np.diff(self.t)
        if not np.allclose(steps, self.dt, rtol=1e-6, atol=1e-9):
            bad = int(np.argmax(np.abs(steps - self.dt))) + 3
            raise DataSetError(
                f"{csv_path}: line {bad}, field t: step {steps[bad - 3]} differs from "
                f"dt = {self.dt} of {meta_path}"
            )

    @property
    def steps(self):
        """Filter steps: the measurement of sample 0 is not used (zero initial state)."""
        return len(self.t) - 1


def _field(obj, name, path, shown=None):
    if not isinstance(obj, dict) or name not in obj:
        raise DataSetError(f"{path}: missing field {shown or name}")
    return obj[name]


def _number(obj, name, path):
    value = _field(obj, name, path)
    if not isinstance(value, (int, float)) or not value > 0:
        raise DataSetError(f"{path}: field {name}: expected a positive number, got {value!r}")
    return float(value)


def _read_measured(path):
    expected = ["t", "ug", "a1", "a2", "a3"]
    try:
        with open(path, newline="") as fh:
            reader = csv.reader(fh)
            header = next(reader, None)
            if header is None or [h.strip() for h in header] != expected:
                raise DataSetError(f"{path}: line 1: header must be {','.join(expected)}")
            rows = []
            for line, row in enumerate(reader, start=2):
                if len(row) != 5:
                    raise DataSetError(f"{path}: line {line}: expected 5 fields, got {len(row)}")
                values = []
                for name, text in zip(expected, row):
                    try:
                        v = float(text)
                    except ValueError:
                        raise DataSetError(
                            f"{path}: line {line}, field {name}: not a number: {text!r}"
                        ) from None
                    if not math.isfinite(v):
                        raise DataSetError(f"{path}: line {line}, field {name}: not finite")
                    values.append(v)
                rows.append(values)
    except OSError as err:
        raise DataSetError(f"{path}: {err}") from err
    data = np.asarray(rows, dtype=float)
    return data[:, 0].copy(), data[:, 1].copy(), data[:, 2:5].copy()


def lognormal_moments(median, log_sd):
    """Mean and variance of a lognormal given its median and log-s.d. (SPEC §3)."""
    mean = median * math.exp(log_sd**2 / 2)
    return mean, mean**2 * (math.exp(log_sd**2) - 1)


def marginal_prior():
    """Moment-matched Gaussian of z = [k1 k2 k3 c1 c2 c3 β γ] (SPEC §3): mean and covariance."""
    km, kv = lognormal_moments(K_MEDIAN, K_LOG_SD)
    cm, cv = lognormal_moments(C_MEDIAN, C_LOG_SD)
    # β = 5√U: mean 2/3·5, E β² = 25/2; γ | β ~ U(−β, β): mean 0, var E β²/3; cov(β, γ) = 0.
    beta_mean = 2 * BETA_MAX / 3
    beta_var = BETA_MAX**2 / 2 - beta_mean**2
    gamma_var = BETA_MAX**2 / 6
    mean = np.array([km] * 3 + [cm] * 3 + [beta_mean, 0.0])
    var = np.array([kv] * 3 + [cv] * 3 + [beta_var, gamma_var])
    return mean, np.diag(var)


def sample_theta(rng_normal, rng_uniform, size):
    """Draws of θ from the priors of SPEC §3 (size × 9).

    `rng_normal(shape)` and `rng_uniform(shape)` supply standard normals and U(0, 1) variates,
    so the caller chooses the generator.
    """
    theta = np.empty((size, 9))
    theta[:, 0:3] = K_MEDIAN * np.exp(K_LOG_SD * rng_normal((size, 3)))
    theta[:, 3:6] = C_MEDIAN * np.exp(C_LOG_SD * rng_normal((size, 3)))
    beta = BETA_MAX * np.sqrt(rng_uniform(size))
    theta[:, 6] = beta
    theta[:, 7] = beta * (2 * rng_uniform(size) - 1)
    theta[:, 8] = N_LO + (N_HI - N_LO) * rng_uniform(size)
    return theta


def write_record(path, record):
    """Writes a run record (JSON) with the same key names as `sysid filter` where they exist."""
    with open(path, "w") as fh:
        json.dump(record, fh, indent=1)
        fh.write("\n")
