"""GNSS outages as a data transformation (architecture section 4): windows without fixes.

A stand-in for the scenario engine's complete outages, for the experiments of papers 003 and
004: periodic windows of ``length_s`` every ``period_s`` from ``start_s`` after the first fix.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import pyarrow as pa

Window = tuple[int, int]


def periodic_windows(
    t_ns: np.ndarray, start_s: float, period_s: float, length_s: float
) -> list[Window]:
    """Windows ``[t0 + start + k period, ... + length)`` (ns) that end before the last time."""
    t0, t1 = int(t_ns[0]), int(t_ns[-1])
    out: list[Window] = []
    k = 0
    while True:
        a = t0 + round((start_s + k * period_s) * 1e9)
        b = a + round(length_s * 1e9)
        if b > t1:
            return out
        out.append((a, b))
        k += 1


def in_windows(t_ns: np.ndarray, windows: list[Window]) -> np.ndarray:
    """Boolean mask of the times inside any window."""
    mask = np.zeros(t_ns.size, bool)
    for a, b in windows:
        mask |= (t_ns >= a) & (t_ns < b)
    return mask


def drop_fixes(
    tables: Mapping[str, pa.Table],
    windows: list[Window],
    names: tuple[str, ...] = ("gnss", "gnss_obs"),
) -> dict[str, pa.Table]:
    """The tables with every GNSS row inside a window removed (others unchanged)."""
    out = dict(tables)
    for name in names:
        if name in out:
            t = np.asarray(out[name].column("t_ns").to_numpy(), dtype=np.int64)
            out[name] = out[name].filter(pa.array(~in_windows(t, windows)))
    return out
