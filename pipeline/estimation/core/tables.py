"""What every family reads of the canonical tables: float columns with nulls filled, the truth at
given times, and the events of a run.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pyarrow as pa

from navreplay.pipeline.errors import PipelineError
from navreplay.pipeline.nav.earth import F64, I64

B8 = npt.NDArray[np.bool_]


@dataclass(frozen=True)
class Event:
    """A data or filter event of a run (see ``outputs.events_table``)."""

    t_ns: int
    kind: str
    stream: str = ""
    sv: str = ""
    value: float = math.nan


def float_column(table: pa.Table, name: str, default: float = math.nan) -> F64:
    """A float column as float64 numpy (null -> ``default``; absent -> all ``default``)."""
    if name not in table.column_names:
        return np.full(table.num_rows, default)
    arr = table.column(name).to_numpy(zero_copy_only=False)
    out = np.asarray(arr, dtype=np.float64)
    nulls = table.column(name).is_null().to_numpy(zero_copy_only=False)
    if nulls.any():
        out = out.copy()
        out[nulls] = default
    return out


def _is_null(table: pa.Table, name: str) -> B8:
    if name not in table.column_names:
        return np.ones(table.num_rows, dtype=bool)
    return np.asarray(table.column(name).is_null().to_numpy(zero_copy_only=False), dtype=bool)


_ANGLES = ("roll_rad", "pitch_rad", "yaw_rad")


def truth_at(truth: pa.Table, t_ns: np.ndarray) -> tuple[np.ndarray, dict[str, F64]]:
    """Truth columns interpolated to ``t_ns`` (only times inside the truth's span).

    Returns:
        (boolean mask of the usable times, column name -> values at those times); angles
        are interpolated unwrapped.
    """
    tt = np.asarray(truth.column("t_ns").to_numpy(), dtype=np.int64)
    inside = (t_ns >= tt[0]) & (t_ns <= tt[-1])
    t = t_ns[inside].astype(np.float64)
    ttf = tt.astype(np.float64)
    out: dict[str, F64] = {}
    for name in truth.column_names:
        if name == "t_ns":
            continue
        col = truth.column(name)
        if col.null_count == len(col):
            continue
        v = np.asarray(col.to_numpy(zero_copy_only=False), dtype=np.float64)
        if name in _ANGLES:
            out[name] = np.angle(np.exp(1j * np.interp(t, ttf, np.unwrap(v))))
        else:
            out[name] = np.interp(t, ttf, v)
    return inside, out


class ReplayInputError(PipelineError):
    """The tables cannot drive this filter (a required table or column is missing)."""


def fix_epochs(table: pa.Table) -> I64:
    """The epochs a ``gnss`` table's fixes describe: ``t_ns - latency_s`` where the table has
    a finite ``latency_s`` (the reader's, or the dataset's latency: ``with_fix_latency``),
    else ``t_ns``."""
    t = np.asarray(table.column("t_ns").to_numpy(), dtype=np.int64)
    latency = float_column(table, "latency_s", 0.0)
    shift = np.where(np.isfinite(latency), np.round(latency * 1e9), 0.0).astype(np.int64)
    return np.asarray(t - shift, dtype=np.int64)


def with_fix_latency(tables: dict[str, pa.Table], latency_s: float | None) -> None:
    """Give the ``gnss`` table (in place in ``tables``) the dataset's fix latency
    (``SensorMeta.gnss_latency_s``) as its ``latency_s`` column, unless it has its own."""
    gnss = tables.get("gnss")
    if latency_s is None or gnss is None or "latency_s" in gnss.column_names:
        return
    column = pa.array(np.full(gnss.num_rows, float(latency_s)), pa.float64())
    tables["gnss"] = gnss.append_column("latency_s", column)
