"""The benchmark sweeps' view of ``navreplay.pipeline.experiments.drives``: its helpers, the
repository's root, and the filters' sections taken from a whole ``Params``."""

from __future__ import annotations

from pathlib import Path

from navreplay.pipeline.estimation.ins.config import InsFilterParams
from navreplay.pipeline.experiments import drives
from navreplay.pipeline.experiments.drives import (
    FILTERS,
    Tables,
    add_imu_bias,
    bias_signs,
    pool_map,
    without_velocity,
    write_csv,
)
from navreplay.pipeline.params import Params

REPO = Path(__file__).resolve().parents[1]

__all__ = [
    "FILTERS",
    "REPO",
    "Tables",
    "add_imu_bias",
    "bias_signs",
    "filter_params",
    "pool_map",
    "without_velocity",
    "write_csv",
]


def filter_params(params: Params, name: str) -> InsFilterParams:
    """``drives.filter_params`` of ``params.filters``."""
    return drives.filter_params(params.filters, name)
