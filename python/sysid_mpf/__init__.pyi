import os
from dataclasses import dataclass
from typing import Any, Mapping, Optional, Sequence, Union

from ._core import (
    Dataset as Dataset,
    Record as Record,
    SysidError as SysidError,
    default_config as default_config,
    load_dataset as load_dataset,
    parse_record as parse_record,
    read_record as read_record,
    table1 as table1,
)

__version__: str
ALGORITHMS: tuple[str, ...]

PathLike = Union[str, os.PathLike[str]]

@dataclass(frozen=True)
class Building:
    storeys: Optional[int] = ...
    hysteretic: Optional[Sequence[int]] = ...
    masses: Optional[Union[float, Sequence[float]]] = ...
    sensors: Optional[Sequence[int]] = ...
    measurement: Optional[str] = ...

def simulate(
    building: Optional[Building] = ...,
    *,
    preset: str = ...,
    excitation: Optional[str] = ...,
    units: str = ...,
    scale: Optional[float] = ...,
    duration: Optional[float] = ...,
    noise_fraction: float = ...,
    seed: int = ...,
    run: int = ...,
) -> Dataset: ...
def field_data(ug: Any, acc: Any, dt: float, sensors: Sequence[int]) -> Dataset: ...
def identify(
    ug: Union[Dataset, Any],
    acc: Any = ...,
    dt: Optional[float] = ...,
    building: Optional[Building] = ...,
    *,
    algorithm: str = ...,
    particles: Optional[int] = ...,
    seed: int = ...,
    run: int = ...,
    config: Union[None, PathLike, Mapping[str, Any]] = ...,
    fix: Optional[Mapping[str, float]] = ...,
    resampling: Optional[str] = ...,
    ess_threshold: Optional[float] = ...,
    discretisation: Optional[str] = ...,
    substeps: Optional[int] = ...,
    storvik_update: Optional[str] = ...,
    experiment: str = ...,
    out: Optional[PathLike] = ...,
) -> Record: ...
def loglik(
    data: Dataset,
    answers: Union[Sequence[Record], Mapping[str, Record]] = ...,
    building: Optional[Building] = ...,
    *,
    truth: bool = ...,
    config: Union[None, PathLike, Mapping[str, Any]] = ...,
    particles: int = ...,
    seeds: int = ...,
) -> dict[str, Any]: ...
