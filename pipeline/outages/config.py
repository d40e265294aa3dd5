"""Typed parameters of the outage experiments: the ``outages`` section of params.yaml."""

from __future__ import annotations

from dataclasses import dataclass

from navreplay.ingest.typed import FieldError
from navreplay.pipeline.estimation.ins.config import FILTER_KINDS
from navreplay.pipeline.scenarios.config import Policy


@dataclass(frozen=True)
class OutagesParams:
    """The Monte Carlo outage experiments.

    Every seed draws ``windows_per_seed`` window starts independently and uniformly in
    ``[earliest_s, end of log - longest window - tail_s]``; each start is replayed, for every
    filter, as a partial outage of ``sats_window_s`` keeping k satellites for each k in
    ``sats`` (policy ``policy``), and as a complete outage of each length in ``lengths_s``.
    The windows are replayed independently from the nominal run's state at their start.

    Attributes:
        filters: filters of the Monte Carlo (those of ``pairs`` at least).
        pairs: (baseline, candidate) filter pairs of the reduction table.
        sats: satellite counts kept inside the partial-outage windows.
        policy: satellite selection policy of the partial outages.
        sats_window_s: length of the partial-outage windows, s (paper 001: 60).
        lengths_s: lengths of the complete outages of the drift-vs-length table, s.
        seeds: placement seeds.
        windows_per_seed: window starts drawn per seed.
        earliest_s: no window starts earlier (alignment and convergence first), s.
        tail_s: GNSS-aided replay after each window (re-convergence), s.
        confidence: level of the intervals.
        resamples: bootstrap resamples.
        workers: processes that replay the windows (1: in this process).
    """

    filters: tuple[str, ...]
    pairs: tuple[tuple[str, str], ...]
    sats: tuple[int, ...] = (0, 1, 2, 3, 4)
    policy: Policy = "highest_elevation"
    sats_window_s: float = 60.0
    lengths_s: tuple[float, ...] = (10.0, 30.0, 60.0, 120.0)
    seeds: tuple[int, ...] = (1, 2, 3)
    windows_per_seed: int = 8
    earliest_s: float = 120.0
    tail_s: float = 30.0
    confidence: float = 0.95
    resamples: int = 10_000
    workers: int = 2

    def __post_init__(self) -> None:
        for i, name in enumerate(self.filters):
            if name not in FILTER_KINDS:
                raise FieldError(f"filters[{i}]", f"{name!r} is not an INS/GNSS filter")
        for i, (a, b) in enumerate(self.pairs):
            if a not in self.filters or b not in self.filters:
                raise FieldError(f"pairs[{i}]", f"{a} -> {b}: both must be in outages.filters")
        if any(k < 0 for k in self.sats):
            raise FieldError("sats", "satellite counts must be >= 0")
        if min((self.sats_window_s, *self.lengths_s)) <= 0:
            raise FieldError("lengths_s", "window lengths must be > 0")
        if not self.seeds or self.windows_per_seed < 2:
            raise FieldError("windows_per_seed", "needs seeds and >= 2 windows per seed")
        if not 0.5 < self.confidence < 1.0:
            raise FieldError("confidence", "must be within (0.5, 1)")
        if self.resamples < 100 or self.workers < 1:
            raise FieldError("resamples", "resamples >= 100 and workers >= 1")
