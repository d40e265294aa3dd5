"""The comma2k19 example segment (shared data): its original logs and their CSV copy
(``derived_csv``), with the dataset.yaml ``csv:`` mappings of the copy's files."""

from __future__ import annotations

from pathlib import Path
from typing import Any

COMMA2K19 = Path(__file__).resolve().parents[3] / "shared" / "data" / "comma2k19_example_segment"
SEGMENT = COMMA2K19 / "original"
DERIVED = COMMA2K19 / "derived_csv"


def fix_mapping(receiver: str) -> dict[str, Any]:
    """The ``csv:`` entry of ``gnss_fix_<receiver>.csv``: 3D fixes on the boot clock (s)."""
    return {
        "path": f"gnss_fix_{receiver}.csv",
        "table": "gnss",
        "time_column": "t_boot_s",
        "time_unit": "s",
        "constants": {"fix_type": 3},
        "columns": {"lat_deg": "lat_deg", "lon_deg": "lon_deg", "alt_m": "altitude_m"},
    }
