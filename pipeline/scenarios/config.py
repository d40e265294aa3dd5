"""Typed scenario parameters: the ``scenarios`` section of params.yaml.

A scenario is a data transformation applied to the canonical tables before the replay loop
(architecture section 4); it never branches inside a filter. ``ScenarioSpec`` combines:

- ``windows``: outage windows (explicit start times, ``count`` random placements drawn with a
  seed, or periodic), in seconds from the first IMU sample;
- ``satellites``: inside every window keep only ``keep`` satellites chosen by a named policy
  (without it the windows are complete outages);
- ``faults``: the GNSS and IMU faults F1, F2, F4, F5, F7, F9, F11, F12 of
  ``docs/bad-inputs.md``.

Default magnitudes and durations of the faults are the catalogue's.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Literal

from navreplay.ingest.typed import FieldError
from navreplay.pipeline.estimation.core.windows import WindowMetricsParams

Placement = Literal["explicit", "random", "periodic"]
Policy = Literal["highest_elevation", "lowest_elevation", "random", "best_dop", "worst_dop"]
FaultKind = Literal["F1", "F2", "F4", "F5", "F7", "F9", "F11", "F12"]

#: Catalogue defaults per fault: (duration_s, magnitude, fraction).
FAULT_DEFAULTS: dict[str, tuple[float, float, float]] = {
    "F1": (0.0, 100.0, 0.0),  # +100 m north on one epoch
    "F2": (0.0, 100.0, 0.0),  # +100 m north from at_s on (duration 0: to the end)
    "F4": (300.0, 0.0, 0.0),  # GNSS outage of 300 s
    "F5": (60.0, 0.0, 0.0),  # fix_type 0, 0 satellites, stale coordinates for 60 s
    "F7": (30.0, 20.0, 0.1),  # 10 % of the samples in 30 s get N(0, 20 m) errors
    "F9": (1.0, 5.0, 0.0),  # GNSS velocity +5 m/s north for 1 s
    "F11": (0.0, 0.0, 0.0),  # one NaN field
    "F12": (2.0, 0.0, 0.0),  # IMU dropout of 2 s
}


@dataclass(frozen=True)
class WindowsSpec:
    """Where the outage windows lie; all times in seconds from the first IMU sample.

    Attributes:
        placement: ``explicit`` (``starts_s``), ``random`` (up to ``count`` windows drawn
            uniformly with ``seed``, non-overlapping and at least ``min_gap_s`` apart) or
            ``periodic`` (every ``period_s`` from ``earliest_s``).
        length_s: duration of every window, s.
        starts_s: explicit window starts, s.
        count: random: number of windows to place (fewer if the log is too short; logged).
        seed: random: seed of the placement draw.
        period_s: periodic: start-to-start period, s.
        earliest_s: random and periodic: no window starts before this (alignment and
            convergence first), s.
        latest_s: no window ends after this; None: ``tail_s`` before the end of the log.
        tail_s: random and periodic with ``latest_s`` None: GNSS-aided time kept after the last
            window (to measure re-convergence), s.
        min_gap_s: random: GNSS-aided time between two windows, s.
    """

    placement: Placement
    length_s: float
    starts_s: tuple[float, ...] = ()
    count: int = 1
    seed: int = 0
    period_s: float = 0.0
    earliest_s: float = 120.0
    latest_s: float | None = None
    tail_s: float = 30.0
    min_gap_s: float = 60.0

    def __post_init__(self) -> None:
        if self.length_s <= 0:
            raise FieldError("length_s", "must be > 0")
        if self.placement == "explicit" and not self.starts_s:
            raise FieldError("starts_s", "explicit placement needs at least one start")
        if self.placement != "explicit" and self.starts_s:
            raise FieldError("starts_s", f"only explicit placement takes starts ({self.placement})")
        if self.placement == "periodic" and self.period_s < self.length_s:
            raise FieldError("period_s", "periodic placement needs period_s >= length_s")
        if self.count < 1:
            raise FieldError("count", "must be >= 1")
        if min(self.earliest_s, self.tail_s, self.min_gap_s) < 0:
            raise FieldError("earliest_s", "earliest_s, tail_s and min_gap_s must be >= 0")


@dataclass(frozen=True)
class SatellitesSpec:
    """A partial outage: inside each window only ``keep`` satellites remain.

    The set is chosen at the window's first epoch from the satellites above
    ``ScenariosParams.selection_mask_deg`` and kept for the window; a chosen satellite that
    disappears is replaced by the next one in the policy's order. Loosely coupled filters see
    no fix when ``keep < 4``; with ``keep >= 4`` and ``refix`` the receiver fix is recomputed
    from the kept pseudoranges (single-point positioning), as a receiver tracking only those
    satellites would report it.

    Attributes:
        keep: satellites kept inside each window (0 = complete outage).
        policy: ``highest_elevation``, ``lowest_elevation``, ``random`` (seeded),
            ``best_dop`` or ``worst_dop`` (GDOP for ``keep >= 4``; below four satellites, whose
            geometry has no DOP, the Gram determinant of the geometry rows: the volume they
            span).
        seed: random policy: seed (combined with the window index).
        refix: recompute the fixes of the windows from the kept satellites (``keep >= 4``).
    """

    keep: int
    policy: Policy = "highest_elevation"
    seed: int = 0
    refix: bool = True

    def __post_init__(self) -> None:
        if not 0 <= self.keep <= 64:
            raise FieldError("keep", "must be within 0..64")


@dataclass(frozen=True)
class FaultSpec:
    """One fault of the catalogue (``docs/bad-inputs.md``), injected at ``at_s``.

    Faults hit both GNSS streams (fixes and pseudoranges), so loosely and tightly coupled
    filters see the same event (``faults`` says how each one maps onto each stream).

    Attributes:
        kind: F1 jump (one epoch), F2 step (from ``at_s`` for ``duration_s``, 0 = to the end),
            F4 outage, F5 stuck receiver (fix_type 0, no satellites, stale coordinates), F7
            outlier burst, F9 velocity glitch, F11 NaN field, F12 IMU dropout.
        at_s: time of the fault, s from the first IMU sample.
        duration_s: length of the fault; 0 takes the catalogue's value.
        magnitude: offset north in m (F1, F2), outlier 1-sigma in m (F7), velocity offset
            north in m/s (F9); 0 takes the catalogue's value.
        fraction: F7: fraction of the samples in the burst that get an outlier.
        seed: F7: seed of the outlier draw.
    """

    kind: FaultKind
    at_s: float
    duration_s: float = 0.0
    magnitude: float = 0.0
    fraction: float = 0.0
    seed: int = 0

    def __post_init__(self) -> None:
        if min(self.at_s, self.duration_s, self.magnitude, self.fraction) < 0:
            raise FieldError("at_s", "at_s, duration_s, magnitude and fraction must be >= 0")
        if self.fraction > 1:
            raise FieldError("fraction", "must be within [0, 1]")

    def resolved(self) -> tuple[float, float, float]:
        """(duration_s, magnitude, fraction) with the catalogue's defaults filled in."""
        d, m, f = FAULT_DEFAULTS[self.kind]
        return self.duration_s or d, self.magnitude or m, self.fraction or f


@dataclass(frozen=True)
class ScenarioSpec:
    """One named scenario: outage windows, satellites kept inside them, faults.

    ``{}`` is the nominal scenario (the tables unchanged).
    """

    description: str = ""
    windows: WindowsSpec | None = None
    satellites: SatellitesSpec | None = None
    faults: tuple[FaultSpec, ...] = ()

    def __post_init__(self) -> None:
        if self.satellites is not None and self.windows is None:
            raise FieldError("satellites", "a partial outage needs windows")


@dataclass(frozen=True)
class FitParams:
    """``scenarios.fit``: how ``navreplay analyze`` fits outage scenarios to a log too short
    for them (``scenarios.fit`` module).

    Attributes:
        settle_s: least GNSS-aided time before a window, from the first fix, s.
        tail_s: least GNSS-aided time after the last window, s.
        lengths_s: shorter window lengths to fall back on, s.
        max_windows: most windows an ``--outage LEN`` scenario places.
        outages: outage scenarios analyze runs besides its ``--scenarios`` (the ``--outage``
            syntax: ``30s``, ``30s@45s``).
    """

    settle_s: float = 30.0
    tail_s: float = 10.0
    lengths_s: tuple[float, ...] = (10.0, 30.0, 60.0)
    max_windows: int = 5
    outages: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if min(self.settle_s, self.tail_s) < 0:
            raise FieldError("settle_s", "settle_s and tail_s must be >= 0")
        if any(x <= 0 for x in self.lengths_s):
            raise FieldError("lengths_s", "every length must be > 0")
        if self.max_windows < 1:
            raise FieldError("max_windows", "must be >= 1")


@dataclass(frozen=True)
class ScenariosParams:
    """The ``scenarios`` section.

    Attributes:
        selection_mask_deg: satellites below this elevation are never chosen (nor kept) by a
            partial outage; match the filters' ``gnss.elevation_mask_deg``.
        metrics: the outage-window metric definitions.
        named: scenario name -> spec; ``nominal`` must be there.
        fit: fitting outage scenarios to short logs (``analyze``).
    """

    selection_mask_deg: float
    metrics: WindowMetricsParams
    named: Mapping[str, ScenarioSpec]
    fit: FitParams = FitParams()

    def __post_init__(self) -> None:
        if "nominal" not in self.named:
            raise FieldError("named", "must define 'nominal' (an empty mapping: {})")
        if self.named["nominal"] != ScenarioSpec(description=self.named["nominal"].description):
            raise FieldError("named.nominal", "must not change the tables")

    def get(self, name: str) -> ScenarioSpec:
        """The spec of scenario ``name``; ``KeyError`` naming the known ones."""
        if name not in self.named:
            raise KeyError(f"unknown scenario {name!r} (known: {', '.join(self.named)})")
        return self.named[name]
