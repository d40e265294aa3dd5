"""Outage windows as a run's metrics see them: the ``Window`` record and the definitions of
the window metrics (``WindowMetricsParams``, the ``scenarios.metrics`` section).

Where the windows lie in a log is the scenarios' business (``scenarios.windows``); the
metrics of a run over them are ``metrics`` and ``outage_metrics``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from navreplay.ingest.typed import FieldError
from navreplay.pipeline.nav.earth import I64

NS = 1_000_000_000


@dataclass(frozen=True)
class Window:
    """One window of a scenario, as written into the run's metadata.

    Attributes:
        start_ns, end_ns: ``[start, end)`` on the log's time base, ns.
        kind: ``outage`` (no GNSS), ``partial`` (``sats`` satellites kept), or the fault
            kind (``F1`` ...) for fault windows.
        sats: satellites available inside (0 for outages; None for faults that keep them).
        label: human-readable description.
    """

    start_ns: int
    end_ns: int
    kind: str
    sats: int | None
    label: str

    @property
    def duration_s(self) -> float:
        return (self.end_ns - self.start_ns) / NS

    def contains(self, t_ns: I64) -> np.ndarray:
        """Boolean mask of the times inside the window."""
        return np.asarray((t_ns >= self.start_ns) & (t_ns < self.end_ns))

    def to_json(self, t0_ns: int) -> dict[str, object]:
        """The window for metrics.json: absolute ns and seconds from ``t0_ns``."""
        return {
            "kind": self.kind,
            "label": self.label,
            "start_t_ns": self.start_ns,
            "end_t_ns": self.end_ns,
            "start_s": (self.start_ns - t0_ns) / NS,
            "duration_s": self.duration_s,
            "sats": self.sats,
        }


@dataclass(frozen=True)
class WindowMetricsParams:
    """Definitions of the outage-window metrics (``estimation.outage_metrics``).

    Attributes:
        reconverge_factor: re-converged once the 3-D error is below this factor times its
            RMS over the ``pre_window_s`` before the window ...
        reconverge_floor_m: ... or below this, whichever is larger, m ...
        reconverge_hold_s: ... and stays there this long, s.
        pre_window_s: the span before a window that sets the error level to return to, s.
        min_distance_m: drift as a percentage of distance is undefined below this, m.
    """

    reconverge_factor: float = 2.0
    reconverge_floor_m: float = 1.0
    reconverge_hold_s: float = 5.0
    pre_window_s: float = 30.0
    min_distance_m: float = 1.0

    def __post_init__(self) -> None:
        if self.reconverge_factor < 1:
            raise FieldError("reconverge_factor", "must be >= 1")
        if min(self.reconverge_floor_m, self.reconverge_hold_s, self.pre_window_s) <= 0:
            raise FieldError("reconverge_floor_m", "floor, hold and pre-window must be > 0")
