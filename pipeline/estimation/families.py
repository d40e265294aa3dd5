"""Filter families: which code runs a filter name, and the ``filters`` params of all of them.

``navreplay run --filter NAME`` looks the name up in ``FAMILY_OF`` and calls the family's
module (``FAMILY_MODULES``), which provides::

    run_tables(tables_dir: Path, name: str, section, backend) -> run   (the pure core)
    write_run(out_dir: Path, run, section, scenario: str) -> None        (atomic run dir)

and whose ``run.metrics`` is the run's ``metrics.json`` (``status``, ``epochs``,
``realtime_factor`` and, with truth, ``pos_err_h_rms_m`` at least). Adding a family is one
entry in each dict below and its sections in ``FiltersParams``.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol, cast

from pipeline.estimation.cascaded.config import (
    CASCADED_KINDS,
    CascadedFilterParams,
    check_sections,
)
from pipeline.estimation.config import FILTER_KINDS
from pipeline.estimation.config import FiltersParams as InsFiltersParams

#: family name -> module implementing it
FAMILY_MODULES: dict[str, str] = {
    "ins": "pipeline.estimation.run",
    "cascaded": "pipeline.estimation.cascaded.run",
}

#: filter name -> family name
FAMILY_OF: dict[str, str] = {
    **dict.fromkeys(FILTER_KINDS, "ins"),
    **dict.fromkeys(CASCADED_KINDS, "cascaded"),
}


class Family(Protocol):
    """A family module (see the module docstring)."""

    def run_tables(self, tables_dir: Path, name: str, section: Any, backend: Any) -> Any: ...

    def write_run(self, out_dir: Path, run: Any, section: Any, scenario: str) -> None: ...


def family(name: str) -> Family:
    """The module running filter ``name``; raises ``KeyError`` naming the known filters."""
    if name not in FAMILY_OF:
        raise KeyError(f"unknown filter {name!r} (known: {', '.join(FAMILY_OF)})")
    return cast(Family, importlib.import_module(FAMILY_MODULES[FAMILY_OF[name]]))


@dataclass(frozen=True)
class FiltersParams(InsFiltersParams):
    """The ``filters`` section: the INS filters' sections (``estimation.config``) and the
    cascaded filters' (``cascaded.config``)."""

    cascaded_ekf: CascadedFilterParams
    cascaded_ukf: CascadedFilterParams
    cascaded_hybrid: CascadedFilterParams

    def __post_init__(self) -> None:
        super().__post_init__()
        check_sections({name: getattr(self, name) for name in CASCADED_KINDS})

    def section(self, name: str) -> Any:
        """The params section of any filter ``name``; ``KeyError`` if unknown."""
        if name not in FAMILY_OF:
            raise KeyError(f"unknown filter {name!r} (known: {', '.join(FAMILY_OF)})")
        return getattr(self, name)
