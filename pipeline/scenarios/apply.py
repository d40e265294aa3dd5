"""Apply a named scenario to canonical tables: the tables a filter replays, and the metadata.

``apply_scenario`` places the outage windows, removes or reduces the GNSS data inside them,
then injects the faults, all before the replay loop (architecture section 4). The result
carries the windows (for the metrics and for the reports to shade), the satellites chosen per
window and what each fault injected.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pyarrow as pa

from navreplay.ingest.schema import FixType
from navreplay.ingest.typed import to_plain
from navreplay.pipeline.estimation.core.tables import fix_epochs
from navreplay.pipeline.estimation.core.windows import Window
from navreplay.pipeline.nav import earth
from navreplay.pipeline.scenarios.config import SatellitesSpec, ScenarioSpec
from navreplay.pipeline.scenarios.faults import (
    ScenarioError,
    Tables,
    column,
    drop_rows,
    inject,
    times,
    with_values,
)
from navreplay.pipeline.scenarios.satellites import Selection, refix, select
from navreplay.pipeline.scenarios.windows import in_any, place_windows

log = logging.getLogger(__name__)

#: Window kinds during which GNSS is absent or reduced: they get outage-window metrics.
OUTAGE_KINDS = ("outage", "partial", "F4", "F5")


@dataclass(frozen=True)
class AppliedScenario:
    """A scenario applied to one dataset's tables.

    Attributes:
        name: scenario name; spec: its definition.
        tables: the transformed tables (unchanged ones shared with the input).
        t0_ns: first IMU sample (window times in seconds count from here).
        windows: outage, partial-outage and fault windows, by start time.
        selections: satellites chosen per partial-outage window.
        injected: one record per fault (``faults.inject``).
    """

    name: str
    spec: ScenarioSpec
    tables: Tables
    t0_ns: int
    windows: tuple[Window, ...]
    selections: tuple[Selection, ...] = ()
    injected: tuple[dict[str, Any], ...] = field(default_factory=tuple)

    @property
    def outage_windows(self) -> tuple[Window, ...]:
        """The windows without (or with reduced) GNSS: those with drift metrics."""
        return tuple(w for w in self.windows if w.kind in OUTAGE_KINDS)

    def metadata(self) -> dict[str, Any]:
        """The scenario for metrics.json and the Parquet provenance (JSON-ready)."""
        return {
            "name": self.name,
            "description": self.spec.description,
            "spec": to_plain(self.spec),
            "t0_ns": self.t0_ns,
            "windows": [w.to_json(self.t0_ns) for w in self.windows],
            "selections": [s.to_json() for s in self.selections],
            "injected": list(self.injected),
        }


def log_span(tables: Mapping[str, pa.Table]) -> tuple[int, int]:
    """(first, last) time of the log: the IMU's, or all tables' without an IMU."""
    if "imu" in tables and tables["imu"].num_rows:
        t = times(tables["imu"])
        return int(t[0]), int(t[-1])
    spans = [times(t) for t in tables.values() if t.num_rows]
    if not spans:
        raise ScenarioError("all tables are empty: nothing to apply a scenario to")
    return min(int(s[0]) for s in spans), max(int(s[-1]) for s in spans)


def apply_scenario(
    tables: Mapping[str, pa.Table],
    name: str,
    spec: ScenarioSpec,
    *,
    mask_deg: float = 10.0,
    windows: list[tuple[int, int]] | None = None,
) -> AppliedScenario:
    """Transform the tables by scenario ``spec`` (see the module docstring).

    Args:
        tables: canonical tables by name (``imu``, ``gnss``, ``gnss_obs``, ``truth`` ...).
        name: the scenario's name (recorded).
        spec: the scenario.
        mask_deg: satellites below this elevation are never kept inside windows.
        windows: use these ``[start, end)`` ns windows instead of placing ``spec.windows``
            (the Monte Carlo passes its own draws).

    Raises:
        ScenarioError: the scenario needs a column or table the dataset does not have.
    """
    t0, t_end = log_span(tables)
    out: Tables = dict(tables)
    placed: list[tuple[int, int]] = []
    if windows is not None:
        placed = list(windows)
    elif spec.windows is not None:
        placed = place_windows(spec.windows, t0, t_end)
    sats = spec.satellites
    k = 0 if sats is None else sats.keep
    kind, label = ("outage", "GNSS outage") if k == 0 else ("partial", f"{k} satellites kept")
    wins = [Window(a, b, kind, k, label) for a, b in placed]
    selections: list[Selection] = []
    if placed:
        out, selections = _reduce(out, placed, sats, mask_deg)
    injected = []
    for fault in spec.faults:
        out, win, rec = inject(out, fault, t0, t_end)
        wins.append(win)
        injected.append(rec)
    wins.sort(key=lambda w: (w.start_ns, w.end_ns))
    return AppliedScenario(name, spec, out, t0, tuple(wins), tuple(selections), tuple(injected))


def _reduce(
    tables: Tables, placed: list[tuple[int, int]], sats: SatellitesSpec | None, mask_deg: float
) -> tuple[Tables, list[Selection]]:
    """Remove the GNSS data inside the windows, or keep ``sats.keep`` satellites there."""
    out = dict(tables)
    k = 0 if sats is None else sats.keep
    selections: list[Selection] = []
    if "gnss_obs" in out:
        obs = out["gnss_obs"]
        t = times(obs)
        if k == 0 or sats is None:
            out["gnss_obs"] = drop_rows(obs, in_any(t, placed))
        else:
            for col in ("elevation_deg", "azimuth_deg"):
                if col not in obs.column_names:
                    raise ScenarioError(f"keeping {k} satellites needs gnss_obs.{col}")
            sv = np.asarray(obs.column("sv").to_pylist(), dtype=object)
            el, az = column(obs, "elevation_deg"), column(obs, "azimuth_deg")
            keep, selections = select(t, sv, el, az, placed, k, sats.policy, sats.seed, mask_deg)
            out["gnss_obs"] = obs.filter(pa.array(keep))
    if "gnss" in out:
        out["gnss"] = _fixes_in_windows(out["gnss"], out.get("gnss_obs"), placed, sats)
    return out, selections


def _fixes_in_windows(
    gnss: pa.Table, obs: pa.Table | None, placed: list[tuple[int, int]], sats: SatellitesSpec | None
) -> pa.Table:
    """No fix inside the windows below four satellites; recomputed fixes from four on.

    A fix is inside a window when the epoch it describes is (``fix_epochs``: its stamp less
    the fixes' latency), so that the filter's outage is the window on the IMU's clock: a fix
    stamped just after the window but describing a moment inside it stays withheld.
    """
    t = times(gnss)
    inside = in_any(fix_epochs(gnss), placed)
    if sats is None or sats.keep < 4:
        return drop_rows(gnss, inside)
    if not sats.refix or obs is None:
        if obs is None:
            log.warning("no gnss_obs table: the fixes inside the windows are kept as logged")
        return gnss
    rows = np.flatnonzero(inside)
    lat, lon, alt = column(gnss, "lat_deg"), column(gnss, "lon_deg"), column(gnss, "alt_m")
    x0 = np.array(
        [earth.geodetic_to_ecef(np.radians(lat[r]), np.radians(lon[r]), alt[r]) for r in rows]
    ).reshape(-1, 3)
    ok, cols = refix(t[rows], obs, x0)
    out = gnss
    cols["fix_type"] = np.full(rows.size, float(FixType.FIX_3D))
    for name, values in cols.items():
        if name not in gnss.column_names:
            continue
        full = column(gnss, name)
        full[rows[ok]] = values[ok]
        # a velocity the receiver does not provide stays null; the rest is set
        set_rows = None if name.startswith("vel_") else rows[ok]
        out = with_values(out, name, full, set_rows=set_rows)
    drop = np.zeros(t.size, dtype=bool)
    drop[rows[~ok]] = True
    if drop.any():
        log.info("%d fixes inside the windows have no single-point solution: removed", drop.sum())
    return drop_rows(out, drop)
