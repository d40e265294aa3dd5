"""The filter families, in one small table, and a run from a tables directory.

``navreplay run --filter NAME`` looks the name up here (``family_of``). Every family
implements the run contract (``estimation.core.contract.Family``): the INS/GNSS filters
(``estimation.ins.run``), the vehicle-model filters (``estimation.vehicle.run``) and the cascaded
filters (``estimation.cascaded.run``). Their runs are written by one writer
(``contract.write_run``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from navreplay.pipeline.estimation.cascaded.run import CASCADED
from navreplay.pipeline.estimation.core.contract import Backend, Family, RunInputs, RunOutput
from navreplay.pipeline.estimation.ins.run import INS
from navreplay.pipeline.estimation.vehicle.run import VEHICLE

#: every family, in the order of the reports and the ranking
FAMILIES: tuple[Family, ...] = (INS, VEHICLE, CASCADED)


def filter_names() -> tuple[str, ...]:
    """Every filter name, in family order."""
    return tuple(n for family in FAMILIES for n in family.filters)


def family_of(name: str) -> Family:
    """The family of filter ``name``; KeyError naming the known filters otherwise."""
    for family in FAMILIES:
        if name in family.filters:
            return family
    raise KeyError(f"unknown filter {name!r} (known: {', '.join(filter_names())})")


def run_tables(tables_dir: Path, name: str, section: Any, backend: Backend) -> RunOutput:
    """Replay filter ``name`` with its parameter ``section`` over the tables in
    ``tables_dir`` (``params.filters.section(name)``)."""
    family = family_of(name)
    return family.run(RunInputs.read(tables_dir, family.inputs), name, section, backend)
