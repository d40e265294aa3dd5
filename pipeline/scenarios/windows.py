"""Outage windows: where they lie in a log, and the masks of the rows inside them.

Times are int64 ns on the log's time base; a window is the half-open interval
``[start_ns, end_ns)``: the GNSS epoch at ``end_ns`` is the first one back.
"""

from __future__ import annotations

import logging

import numpy as np

from navreplay.pipeline.estimation.core.windows import NS
from navreplay.pipeline.nav.earth import I64
from navreplay.pipeline.scenarios.config import WindowsSpec

log = logging.getLogger(__name__)


def place_windows(spec: WindowsSpec, t0_ns: int, t_end_ns: int) -> list[tuple[int, int]]:
    """The ``[start, end)`` ns intervals of ``spec`` in a log spanning ``[t0_ns, t_end_ns]``.

    Random placement draws the starts uniformly over every arrangement of ``count``
    non-overlapping windows separated by at least ``min_gap_s`` inside ``[earliest_s,
    latest]`` (sorted uniform offsets in the free time, each shifted by the windows and gaps
    before it), with ``numpy.random.default_rng(seed)``. Windows that do not fit are dropped
    with a warning (explicit, periodic) or not drawn (random: as many as fit). Explicit
    windows need only lie inside the log (and before ``latest_s``); ``tail_s`` applies to
    the placed ones.
    """
    length = spec.length_s
    span = (t_end_ns - t0_ns) / NS
    tail = 0.0 if spec.placement == "explicit" else spec.tail_s
    latest = min(spec.latest_s if spec.latest_s is not None else span - tail, span)
    if spec.placement == "explicit":
        starts = [s for s in spec.starts_s if s >= 0.0 and s + length <= latest]
        if len(starts) < len(spec.starts_s):
            log.warning(
                "%d of %d explicit windows lie outside the log's [0, %.1f] s and are skipped",
                len(spec.starts_s) - len(starts),
                len(spec.starts_s),
                latest,
            )
    elif spec.placement == "periodic":
        n = int(np.floor((latest - length - spec.earliest_s) / spec.period_s)) + 1
        starts = [spec.earliest_s + k * spec.period_s for k in range(max(n, 0))]
    else:
        starts = random_starts(spec, latest)
    return [(t0_ns + round(s * NS), t0_ns + round((s + length) * NS)) for s in sorted(starts)]


def random_fit(length_s: float, min_gap_s: float, earliest_s: float, latest_s: float) -> int:
    """How many windows of ``length_s``, ``min_gap_s`` apart, fit in ``[earliest_s, latest_s]``."""
    room = latest_s - earliest_s
    if room < length_s:
        return 0
    return int(np.floor((room - length_s) / (length_s + min_gap_s))) + 1


def random_starts(spec: WindowsSpec, latest_s: float) -> list[float]:
    """Up to ``spec.count`` window starts drawn uniformly (see ``place_windows``)."""
    pitch = spec.length_s + spec.min_gap_s
    room = latest_s - spec.earliest_s
    n = min(spec.count, random_fit(spec.length_s, spec.min_gap_s, spec.earliest_s, latest_s))
    if n < spec.count:
        log.warning(
            "only %d of %d windows of %.0f s (%.0f s apart) fit in [%.1f, %.1f] s: %d placed; "
            "for more, shorten the scenario's windows (length_s, count, earliest_s, tail_s), "
            "or let `navreplay analyze` fit them to the log",
            n,
            spec.count,
            spec.length_s,
            spec.min_gap_s,
            spec.earliest_s,
            latest_s,
            n,
        )
    if n == 0:
        return []
    free = room - n * spec.length_s - (n - 1) * spec.min_gap_s
    u = np.sort(np.random.default_rng(spec.seed).uniform(0.0, free, n))
    return [float(spec.earliest_s + u[k] + k * pitch) for k in range(n)]


def in_any(t_ns: I64, windows: list[tuple[int, int]]) -> np.ndarray:
    """Boolean mask of the times inside any of the ``[start, end)`` windows."""
    mask = np.zeros(t_ns.shape, dtype=bool)
    for a, b in windows:
        mask |= (t_ns >= a) & (t_ns < b)
    return mask
