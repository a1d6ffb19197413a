"""Online Bayesian identification of hysteretic structures from Python and numpy.

The filters (bootstrap PF, MLN-RBPF, Storvik's algorithm, MPF-EKF2), the simulator, the data-set
readers and the run records of the ``sysid`` toolkit, bound from its Rust library: every number
is computed by the same code as ``sysid simulate`` and ``sysid filter`` and is bit-identical to
theirs for the same data, settings and seed.

>>> import sysid_mpf as sm
>>> data = sm.simulate(sm.Building(storeys=5, hysteretic=[1]), duration=10.0, seed=1)
>>> result = sm.identify(data, algorithm="mpf-ekf2", particles=200, seed=1)
>>> result.theta_val, result.theta_sd, result.trace_mean   # numpy arrays

Bad input raises :class:`SysidError` (a ``ValueError``) with the message ``sysid`` prints; a run
releases the GIL and stops on Ctrl-C with ``KeyboardInterrupt``.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from typing import Any, Mapping, Optional, Sequence, Union

# numpy is imported where arrays are taken in (`field_data`, masses given as an array), not
# here: the compiled module loads it when it first hands out an array, so a script that only
# identifies and writes a record does not pay numpy's start-up (about 0.1 s, docs/python.md).
from . import _core
from ._core import (
    Dataset,
    Record,
    SysidError,
    default_config,
    load_dataset,
    parse_record,
    read_record,
    table1,
)

__version__ = _core.__version__

__all__ = [
    "ALGORITHMS",
    "Building",
    "Dataset",
    "Record",
    "SysidError",
    "default_config",
    "field_data",
    "identify",
    "load_dataset",
    "loglik",
    "parse_record",
    "read_record",
    "simulate",
    "table1",
]

#: The identification algorithms (SPEC §5), as ``identify(..., algorithm=...)`` names them.
ALGORITHMS = ("bootstrap", "mln-rbpf", "storvik", "mpf-ekf2")

PathLike = Union[str, "os.PathLike[str]"]


@dataclass(frozen=True)
class Building:
    """A shear building as the toolkit describes it (docs/structures.md).

    Every field may be left ``None`` (not stated): :func:`simulate` then takes the preset's
    value, and :func:`identify` of field data refuses the run naming what is missing (nothing is
    guessed), as ``sysid filter`` does.

    storeys: number of storeys N.
    hysteretic: 1-based storeys with a Bouc–Wen element (``[]``: a linear building).
    masses: storey masses m1..mN, or one value for every storey.
    sensors: 1-based measured storeys, increasing (default: every storey).
    measurement: ``"absolute"`` (ẍ + ü_g, real accelerometers) or ``"relative"`` (ẍ).
    damping: the damping form identified by :func:`identify`: ``"storey"`` (per-storey
        dashpots, the default) or ``"storey+mass"`` (also mass-proportional damping αM; θ gains
        ``alpha``), as ``sysid filter --damping``.
    """

    storeys: Optional[int] = None
    hysteretic: Optional[Sequence[int]] = None
    masses: Optional[Union[float, Sequence[float]]] = None
    sensors: Optional[Sequence[int]] = None
    measurement: Optional[str] = None
    damping: Optional[str] = None

    def _masses(self) -> Optional[list]:
        if self.masses is None:
            return None
        import numpy as np

        if np.ndim(self.masses) == 0:
            return [float(self.masses)]
        return [float(m) for m in self.masses]

    def _flags(self) -> dict:
        """The building as the keyword arguments of ``sysid filter``'s structure flags."""
        return dict(
            storeys=None if self.storeys is None else int(self.storeys),
            hysteretic=None if self.hysteretic is None else [int(h) for h in self.hysteretic],
            masses=self._masses(),
            measurement=self.measurement,
            damping=self.damping,
        )

    def _sensors(self) -> list:
        if self.sensors is not None:
            return [int(s) for s in self.sensors]
        if self.storeys is None:
            raise SysidError(
                "sensors: the building states neither its sensors nor its storeys "
                "(Building(storeys=N) measures every storey)"
            )
        return list(range(1, int(self.storeys) + 1))


def _config_args(config: Union[None, PathLike, Mapping[str, Any]]) -> tuple:
    """``config`` as the binding takes it: (file path, None), (None, JSON text) or (None, None)."""
    if isinstance(config, Mapping):
        return None, json.dumps(dict(config), allow_nan=False)
    if config is not None:
        return os.fspath(config), None
    return None, None


def _storey_list(values: Optional[Sequence[int]]) -> Optional[str]:
    """A storey list as the command line spells it (``1,4``; ``none`` for an empty list)."""
    if values is None:
        return None
    values = [int(v) for v in values]
    return ",".join(str(v) for v in values) if values else "none"


def simulate(
    building: Optional[Building] = None,
    *,
    preset: str = "paper-3dof",
    excitation: Optional[str] = None,
    units: str = "g",
    scale: Optional[float] = None,
    duration: Optional[float] = None,
    noise_fraction: float = 0.1,
    seed: int = 0,
    run: int = 0,
) -> Dataset:
    """Simulates a building under an excitation: ``sysid simulate`` in memory.

    ``building`` states the storeys, hysteretic storeys, sensors and measurement kind (the
    preset's where ``None``; masses are the preset's). ``excitation``: ``elcentro``,
    ``kanai-tajimi``, ``harmonic``, a vendored record by name or a ``.csv``/``.AT2`` path.
    Returns a :class:`Dataset` with the measured arrays, the true states and θ_true; write it
    with ``Dataset.write(dir)`` for ``sysid filter --data dir``.
    """
    b = building or Building()
    if b.measurement not in (None, "absolute", "relative"):
        raise SysidError(
            f"--measurement: unknown measurement kind `{b.measurement}` "
            "(expected absolute or relative)"
        )
    data = _core.simulate(
        preset=preset,
        seed=int(seed),
        run=int(run),
        storeys=None if b.storeys is None else int(b.storeys),
        hysteretic=_storey_list(b.hysteretic),
        sensors=_storey_list(b.sensors),
        excitation=None if excitation is None else os.fspath(excitation),
        units=units,
        scale=None if scale is None else float(scale),
        duration=None if duration is None else float(duration),
        absolute=b.measurement == "absolute",
        noise_fraction=float(noise_fraction),
    )
    made = data.building
    if b.measurement is not None and made["measurement"] != b.measurement:
        raise SysidError(
            f"measurement: the preset `{preset}` simulates {made['measurement']} accelerations; "
            "only absolute can be asked for (--absolute)"
        )
    masses = b._masses()
    if masses is not None:
        want = masses * made["storeys"] if len(masses) == 1 else masses
        if want != made["masses"]:
            raise SysidError(
                f"masses: the preset `{preset}` has masses {made['masses']}; simulate takes "
                "the preset's masses"
            )
    return data


def field_data(
    ug: Any, acc: Any, dt: float, sensors: Sequence[int]
) -> Dataset:
    """Field data from arrays: ü_g of shape (K,), accelerations of shape (K, channels) (or (K,)
    for one channel) at the 1-based storeys ``sensors``, sample interval ``dt`` (times k·dt).
    Write it with ``Dataset.write(dir)`` (``measured.csv``) for the command line."""
    import numpy as np

    ug = np.ascontiguousarray(ug, dtype=np.float64)
    acc = np.asarray(acc, dtype=np.float64)
    if ug.ndim != 1:
        raise SysidError(f"ug: an array of shape (K,) is needed, not {ug.shape}")
    if acc.ndim == 1:
        acc = acc.reshape(-1, 1)
    if acc.ndim != 2:
        raise SysidError(f"acc: an array of shape (K, channels) is needed, not {acc.shape}")
    return _core.field_data(
        ug, np.ascontiguousarray(acc), float(dt), [int(s) for s in sensors]
    )


def identify(
    ug: Union[Dataset, Any],
    acc: Any = None,
    dt: Optional[float] = None,
    building: Optional[Building] = None,
    *,
    algorithm: str = "mpf-ekf2",
    particles: Optional[int] = None,
    seed: int = 1,
    run: int = 0,
    config: Union[None, PathLike, Mapping[str, Any]] = None,
    fix: Optional[Mapping[str, float]] = None,
    resampling: Optional[str] = None,
    ess_threshold: Optional[float] = None,
    discretisation: Optional[str] = None,
    substeps: Optional[int] = None,
    storvik_update: Optional[str] = None,
    experiment: str = "python",
    out: Optional[PathLike] = None,
    learn_noise: bool = False,
) -> Record:
    """One identification run: ``sysid filter`` in memory, same numbers for the same data,
    settings and seed.

    Either ``identify(dataset, ...)`` with a :class:`Dataset` (simulated, loaded or
    :func:`field_data`), or ``identify(ug, acc, dt, building, ...)`` with arrays (field data:
    the building must state storeys, hysteretic storeys, masses and measurement kind).

    ``config``: a TOML file as ``sysid filter --config`` reads, or a dict of the same keys; none:
    the recommended settings (:func:`default_config`: 1000 particles as 8 pooled filters; the
    MPF-EKF2 on field data of a hysteretic building sampled coarsely for its first mode takes
    4000 as 8 × 500, as ``sysid filter`` does; with ``particles=P`` and no config, one pooled
    filter per 125 particles, 1 to 8). The other options
    override it as the flags of the same names do. ``fix``: point-mass priors, e.g. ``{"k1": 8.0}``. ``out``: also
    write the record there (atomically), as ``sysid filter --out``. ``learn_noise``: each
    channel's measurement noise learned by maximum likelihood once the plan is settled, as
    ``sysid filter --learn-noise`` (one Gaussian filter only).

    Returns a :class:`Record`: θ_val, posterior s.d., credible intervals, traces, ESS,
    log-likelihood, warnings, one-step prediction errors and (simulated data) the free-run
    validation. Raises :class:`SysidError` on bad input; Ctrl-C stops the run
    (``KeyboardInterrupt``, nothing written).
    """
    if isinstance(ug, Dataset):
        if acc is not None or dt is not None:
            raise SysidError("identify(dataset, ...): acc and dt come from the data set")
        data = ug
    else:
        if acc is None or dt is None or building is None:
            raise SysidError(
                "identify(ug, acc, dt, building): arrays need acc, dt and the building"
            )
        data = field_data(ug, acc, dt, building._sensors())
    b = building or Building()
    if b.measurement not in (None, "absolute", "relative"):
        raise SysidError(
            f"--measurement: unknown measurement kind `{b.measurement}` "
            "(expected absolute or relative)"
        )
    config_path, config_json = _config_args(config)
    return _core.identify(
        data,
        algorithm,
        particles=None if particles is None else int(particles),
        seed=int(seed),
        run=int(run),
        config=config_path,
        config_json=config_json,
        fix=None if fix is None else [(str(k), float(v)) for k, v in fix.items()],
        resampling=resampling,
        ess_threshold=None if ess_threshold is None else float(ess_threshold),
        discretisation=discretisation,
        substeps=None if substeps is None else int(substeps),
        storvik_update=storvik_update,
        experiment=experiment,
        out=None if out is None else os.fspath(out),
        learn_noise=bool(learn_noise),
        **b._flags(),
    )


def loglik(
    data: Dataset,
    answers: Union[Sequence[Record], Mapping[str, Record]] = (),
    building: Optional[Building] = None,
    *,
    truth: bool = False,
    config: Union[None, PathLike, Mapping[str, Any]] = None,
    particles: int = 250,
    seeds: int = 2,
) -> dict[str, Any]:
    """Which answers the record supports: ``sysid loglik`` in memory, same numbers.

    For each answer (a :class:`Record`'s θ_val; a dict gives them labels, a list labels them
    ``"<index>: <algorithm> seed <seed>"``) and, with ``truth=True``, the data set's true θ: the
    log-likelihood log p̂(y | θ) of ``data``, ``seeds`` estimates by one MPF-EKF2 of
    ``particles`` particles with every parameter fixed at θ, under the model ``identify(data,
    algorithm="mpf-ekf2")`` builds (``config``: a file or dict, as :func:`identify`; field data
    need ``building`` or a config's ``[structure]``).

    Returns a dict: ``answers`` (per answer: ``label``, ``estimates``, ``mean``, ``se``,
    ``below_best``, ``verdict``), ``best``, ``params`` (free parameters), ``region_nats``
    (χ²_p(0.95)/2) and ``table`` (what ``sysid loglik`` prints). A verdict is ``"best"``, ``"not
    shown outside"``, ``"outside"`` (below the best by more than the record's 95 % likelihood
    region plus 2 s.e.: the record itself says that answer is wrong) or ``"not resolved"`` (one
    seed gives no s.e.). Ctrl-C stops it (``KeyboardInterrupt``).
    """
    if not isinstance(data, Dataset):
        raise SysidError("loglik(data, ...): data must be a Dataset (simulate, load_dataset, field_data)")
    if isinstance(answers, Mapping):
        labels = [str(k) for k in answers.keys()]
        records = list(answers.values())
    else:
        records = list(answers)
        labels = [str(i) for i in range(len(records))]
    for label, r in zip(labels, records):
        if not isinstance(r, Record):
            raise SysidError(f"loglik: answer {label!r} is not a Record")
    if not isinstance(answers, Mapping):
        labels = [f"{i}: {r.algorithm} seed {r.seed}" for i, r in enumerate(records)]
    if int(particles) < 1:
        raise SysidError("--particles: at least one particle per estimate")
    if int(seeds) < 1:
        raise SysidError("--seeds: at least one estimate per candidate")
    b = building or Building()
    config_path, config_json = _config_args(config)
    return _core.loglik(
        data,
        records,
        labels,
        truth=bool(truth),
        config=config_path,
        config_json=config_json,
        particles=int(particles),
        seeds=int(seeds),
        **b._flags(),
    )
