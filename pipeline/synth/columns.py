"""Canonical table columns from the synthesizers' per-axis arrays."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pyarrow as pa

from navreplay.ingest.schema import from_columns

NED = ("n", "e", "d")
RPY = ("roll", "pitch", "yaw")


def axis_columns(
    template: str, values: np.ndarray, axes: Sequence[str] = "xyz"
) -> dict[str, np.ndarray]:
    """One column per axis of the (n, len(axes)) array ``values``, named by ``template`` with
    the axis name for ``{}`` (``axis_columns("vel_{}_mps", v, NED)``: vel_n_mps ...)."""
    return {template.format(axis): values[:, j] for j, axis in enumerate(axes)}


def imu_table(t_ns: np.ndarray, acc: np.ndarray, gyro: np.ndarray) -> pa.Table:
    """The canonical ``imu`` table: specific force and angular rate, (n, 3) each, body FRD."""
    return from_columns(
        "imu",
        {
            "t_ns": t_ns,
            **axis_columns("acc_{}_mps2", acc),
            **axis_columns("gyro_{}_radps", gyro),
        },
    )
