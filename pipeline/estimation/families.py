"""Filter families: which replay runs a filter name, in one small table.

``navreplay run --filter NAME`` looks the name up here. Each family runs a filter over a
tables directory and writes the run directory (same contract for every family:
``estimate.parquet``, ``innovations.parquet``, ``events.parquet``, ``metrics.json``) and
returns the run's metrics.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any, Literal

from pipeline.estimation.cascaded_config import CASCADED_KINDS
from pipeline.estimation.config import FILTER_KINDS, FiltersParams
from pipeline.estimation.vehicle_config import VEHICLE_FILTERS

Backend = Literal["numba", "filterpy"]
RunFn = Callable[[Path, str, FiltersParams, Backend, Path, str], dict[str, Any]]


def _run_ins(
    tables: Path, name: str, filters: FiltersParams, backend: Backend, out: Path, scenario: str
) -> dict[str, Any]:
    from pipeline.estimation.run import run_tables, write_run

    section = filters.get(name)
    run = run_tables(tables, name, section, backend)
    write_run(out, run, section, scenario)
    return run.metrics


def _run_vehicle(
    tables: Path, name: str, filters: FiltersParams, backend: Backend, out: Path, scenario: str
) -> dict[str, Any]:
    from pipeline.estimation.vehicle_run import run_tables, write_run

    section = filters.vehicle(name)
    run = run_tables(tables, name, section, backend)
    write_run(out, run, section, scenario)
    return run.metrics


def _run_cascaded(
    tables: Path, name: str, filters: FiltersParams, backend: Backend, out: Path, scenario: str
) -> dict[str, Any]:
    from pipeline.estimation.cascaded.run import run_tables, write_run

    section = filters.cascaded(name)
    run = run_tables(tables, name, section, backend)
    write_run(out, run, section, scenario)
    return run.metrics


#: family name -> (its filter names, its runner)
FAMILIES: dict[str, tuple[tuple[str, ...], RunFn]] = {
    "ins": (tuple(FILTER_KINDS), _run_ins),
    "vehicle": (VEHICLE_FILTERS, _run_vehicle),
    "cascaded": (tuple(CASCADED_KINDS), _run_cascaded),
}


def filter_names() -> tuple[str, ...]:
    """Every filter name, in family order."""
    return tuple(n for names, _ in FAMILIES.values() for n in names)


def runner(name: str) -> RunFn:
    """The runner of filter ``name``; KeyError naming the known filters otherwise."""
    for names, run in FAMILIES.values():
        if name in names:
            return run
    raise KeyError(f"unknown filter {name!r} (known: {', '.join(filter_names())})")
