"""Typed parameters: ``params.yaml`` loaded into frozen dataclasses.

Every knob of the pipeline lives in ``params.yaml``; stages read it through ``load_params``.
Unknown or misspelled keys, wrong types, duplicated keys and missing sections are errors
(``ParamsError``) naming the dotted key path.

The package carries the built-in defaults: the repository's ``params.yaml``, installed as
``navreplay/pipeline/params.yaml`` (in the checkout a link to it), so every command works from
any directory and from a wheel. A parameter file a user gives (``--params``, or
``./params.yaml`` when present) is laid over them: its mappings merge key by key, anything
else (a list, a number) replaces the default. A file holding only ``run: {filters:
[lc_ekf]}`` changes that and nothing else; a complete file (the repository's own) replaces
everything. ``navreplay params`` prints the result.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import yaml

from navreplay.ingest.typed import FieldError, load_dataclass, to_plain
from navreplay.pipeline.compute import ComputeParams
from navreplay.pipeline.errors import ParamsError
from navreplay.pipeline.estimation.cascaded.config import CASCADED_KINDS
from navreplay.pipeline.estimation.config import FiltersParams
from navreplay.pipeline.estimation.ins.config import FILTER_KINDS
from navreplay.pipeline.estimation.vehicle.config import VEHICLE_FILTERS
from navreplay.pipeline.experiments.tractor_cascaded.config import TractorExperimentParams
from navreplay.pipeline.experiments.vehicle_bands_config import VehicleBandsParams
from navreplay.pipeline.outages.config import OutagesParams
from navreplay.pipeline.scenarios.config import ScenariosParams
from navreplay.pipeline.synth.car import CarSpeedRampParams
from navreplay.pipeline.synth.car_drives import CarDriveParams
from navreplay.pipeline.synth.fwekf import FwekfReferenceParams
from navreplay.pipeline.synth.multirotor_params import MultirotorFlightParams
from navreplay.pipeline.synth.seoul_params import SeoulCampusParams
from navreplay.pipeline.synth.tractor import TractorStraightParams

#: The parameter file a command uses, when present in its working directory, without --params.
LOCAL_PARAMS = Path("params.yaml")
#: The built-in defaults (installed with the package).
BUILTIN_PARAMS = Path(__file__).with_name("params.yaml")
_ID_RE = re.compile(r"^[a-z][a-z0-9_]*$")


@dataclass(frozen=True)
class SynthParams:
    """``synth``: the synthesized datasets. ``seed`` seeds every random draw. ``car_drives``:
    the campus car on other drives, by dataset id (``pipeline.synth.car_drives``)."""

    seed: int
    seoul_campus: SeoulCampusParams
    tractor_straight: TractorStraightParams
    fwekf_reference: FwekfReferenceParams
    car_speed_ramp: CarSpeedRampParams
    multirotor_flight: MultirotorFlightParams
    car_drives: dict[str, CarDriveParams]


@dataclass(frozen=True)
class IngestParams:
    """``ingest``: how logs become canonical tables.

    Attributes:
        strict: turn every recoverable defect (truncation, corrupt chunk ...) into an error.
        reorder_window_s: out-of-order samples within this window are re-sorted; older dropped.
        gap_factor: a gap is an interval longer than ``gap_factor`` nominal sample periods.
    """

    strict: bool
    reorder_window_s: float
    gap_factor: float

    def __post_init__(self) -> None:
        if self.reorder_window_s < 0:
            raise FieldError("reorder_window_s", "must be >= 0")
        if self.gap_factor <= 1:
            raise FieldError("gap_factor", "must be > 1")


@dataclass(frozen=True)
class FamilyRun:
    """One filter replayed over one dataset under one scenario outside the INS run matrix:
    the vehicle-model and cascaded filters on their datasets, fwekf on paper 004's. DVC reads
    the entries as written, so ``params.yaml`` names the scenario of every entry."""

    dataset: str
    filter: str
    scenario: str = "nominal"


@dataclass(frozen=True)
class RunParams:
    """``run``: the run matrix of dvc.yaml (datasets x filters, each under every scenario of
    ``scenarios``; the Monte Carlo and outage experiments cover the same datasets), the
    backend, and the processes one ``navreplay run`` spreads its scenarios over.
    ``datasets`` may hold built-in and recorded datasets; ``filters`` and ``scenarios`` are
    also the defaults of ``navreplay analyze``. ``family_runs`` are single runs (dataset,
    filter, scenario) beside that matrix, so that every family (vehicle-model, cascaded,
    fwekf) has runs in the reports and the summary's ranking."""

    backend: Literal["numba", "filterpy"]
    datasets: tuple[str, ...]
    filters: tuple[str, ...]
    scenarios: tuple[str, ...]
    workers: int = 1
    family_runs: tuple[FamilyRun, ...] = ()

    def __post_init__(self) -> None:
        if self.workers < 1:
            raise FieldError("workers", "must be >= 1")


@dataclass(frozen=True)
class ReportParams:
    """``report``: rendering of the HTML reports."""

    figure_dpi: int

    def __post_init__(self) -> None:
        if not 50 <= self.figure_dpi <= 600:
            raise FieldError("figure_dpi", "must be within 50..600")


@dataclass(frozen=True)
class ExperimentsParams:
    """``experiments``: the experiments run by ``navreplay experiment NAME``."""

    tractor_cascaded: TractorExperimentParams
    vehicle_bands: VehicleBandsParams = field(default_factory=VehicleBandsParams)


@dataclass(frozen=True)
class Params:
    """The whole of ``params.yaml``; ``filters`` holds one section per filter
    (``pipeline.estimation.config``), ``scenarios`` the named scenarios
    (``pipeline.scenarios.config``) and ``outages`` the outage experiments
    (``pipeline.outages.config``); ``compute`` where sweeps run (``pipeline.compute``).
    ``datasets`` are the built-in, synthesized datasets;
    ``recorded`` the datasets whose logs the user put under ``datasets/<id>/raw/``."""

    datasets: tuple[str, ...]
    synth: SynthParams
    ingest: IngestParams
    run: RunParams
    report: ReportParams
    filters: FiltersParams
    experiments: ExperimentsParams
    scenarios: ScenariosParams
    outages: OutagesParams
    recorded: tuple[str, ...] = ()
    compute: ComputeParams = field(default_factory=ComputeParams)

    def __post_init__(self) -> None:
        for i, ds in enumerate(self.run.datasets):
            if ds not in self.datasets and ds not in self.recorded:
                raise FieldError(
                    f"run.datasets[{i}]", f"{ds!r} is in neither datasets nor recorded"
                )
        self._check_family_runs()
        for i, name in enumerate(self.run.scenarios):
            if name not in self.scenarios.named:
                raise FieldError(f"run.scenarios[{i}]", f"{name!r} is not in scenarios.named")
        for i, ds in enumerate(self.datasets):
            if not _ID_RE.match(ds):
                raise FieldError(
                    f"datasets[{i}]", f"{ds!r} is not a dataset id (lowercase, digits, underscores)"
                )
        if len(set(self.datasets)) != len(self.datasets):
            raise FieldError("datasets", "lists a dataset twice")
        for i, ds in enumerate(self.recorded):
            if not _ID_RE.match(ds) or ds in self.datasets:
                raise FieldError(f"recorded[{i}]", f"{ds!r}: a new dataset id (lowercase)")

    def _check_family_runs(self) -> None:
        """Each of run.family_runs names a dataset, a filter and a scenario that exist."""
        for i, fr in enumerate(self.run.family_runs):
            if fr.dataset not in self.datasets and fr.dataset not in self.recorded:
                raise FieldError(
                    f"run.family_runs[{i}].dataset",
                    f"{fr.dataset!r} is in neither datasets nor recorded",
                )
            known = (*FILTER_KINDS, *VEHICLE_FILTERS, *CASCADED_KINDS)
            if fr.filter not in known:
                raise FieldError(
                    f"run.family_runs[{i}].filter",
                    f"{fr.filter!r} is not a filter (known: {', '.join(known)})",
                )
            if fr.scenario not in self.scenarios.named:
                raise FieldError(
                    f"run.family_runs[{i}].scenario", f"{fr.scenario!r} is not in scenarios.named"
                )


class _UniqueKeyLoader(yaml.SafeLoader):
    """A safe YAML loader that rejects a key given twice in one mapping."""


def _construct_mapping(loader: _UniqueKeyLoader, node: yaml.MappingNode) -> dict[Any, Any]:
    seen: dict[Any, Any] = {}
    for key_node, value_node in node.value:
        key = loader.construct_object(key_node)
        if key in seen:
            raise yaml.constructor.ConstructorError(
                None, None, f"duplicate key {key!r}", key_node.start_mark
            )
        seen[key] = loader.construct_object(value_node, deep=True)
    return seen


_UniqueKeyLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping)


def read_yaml(path: str | Path) -> Any:
    """Parse a YAML file safely, rejecting duplicate keys; errors are ``ParamsError``."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as err:
        raise ParamsError("", f"cannot read: {err.strerror}", source=str(path)) from err
    try:
        return yaml.load(text, Loader=_UniqueKeyLoader)
    except yaml.YAMLError as err:
        raise ParamsError("", f"not valid YAML: {err}", source=str(path)) from err


def parse_params(data: object, *, source: str | None = None) -> Params:
    """Build ``Params`` from a parsed mapping; raises ``ParamsError`` naming the key path."""
    return load_dataclass(Params, data, source=source, error=ParamsError)


def params_source(path: str | Path | None = None) -> Path | None:
    """The user's parameter file a command reads: ``path`` when given, else
    ``./params.yaml`` when present; None means the built-in defaults alone."""
    if path is not None:
        return Path(path)
    return LOCAL_PARAMS if LOCAL_PARAMS.is_file() else None


def params_label(path: str | Path | None = None) -> str:
    """The name errors give the parameters ``load_params(path)`` reads."""
    source = params_source(path)
    return str(source) if source is not None else f"built-in defaults ({BUILTIN_PARAMS})"


def overlay(base: Any, over: Any) -> Any:
    """``over`` laid over ``base``: mappings merge key by key, anything else replaces."""
    if isinstance(base, Mapping) and isinstance(over, Mapping):
        merged = dict(base)
        for key, value in over.items():
            merged[key] = overlay(base[key], value) if key in base else value
        return merged
    return over


def effective_params(path: str | Path | None = None) -> dict[str, Any]:
    """The parameters as plain data: the user's file (``params_source``) laid over the
    built-in defaults (see the module docstring)."""
    defaults = read_yaml(BUILTIN_PARAMS)
    source = params_source(path)
    if source is None:
        return dict(defaults)
    data = read_yaml(source)
    if data is None:
        data = {}
    if not isinstance(data, Mapping):
        raise ParamsError(
            "", "must be a mapping of sections (run:, filters:, ...)", source=str(source)
        )
    return dict(overlay(defaults, data))


def load_params(path: str | Path | None = None) -> Params:
    """Load and check the parameters: ``path`` (or ``./params.yaml`` when present) laid over
    the built-in defaults."""
    return parse_params(effective_params(path), source=params_label(path))


def section(params: Params, dotted: str) -> Any:
    """The plain-data value at a dotted path (``"run"``, ``"synth.seed"``) for hashing."""
    node: Any = to_plain(params)
    for part in dotted.split("."):
        if not isinstance(node, dict) or part not in node:
            raise ParamsError(dotted, "no such parameter section")
        node = node[part]
    return node
