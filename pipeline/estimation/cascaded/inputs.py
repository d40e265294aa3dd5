"""Canonical tables -> the cascaded filters' input arrays (the data barrier of a replay).

- ``vehicle`` (required): ``speed_mps`` (radar), ``yaw_rate_radps`` (FOG), ``steer_rad``
  (potentiometer) and, if present, ``steer_rate_cmd_radps``: the steering command applied
  after each sample (the control filter's input ``u``; without it the control filter
  predicts with ``u = 0`` and an ``no_steer_command`` event says so).
- ``gnss`` (required): position as latitude/longitude, mapped to metres East/North of the
  first usable fix (``pipeline.nav.local.LocalFrame``, the filters' map), and the
  multi-antenna ``heading_rad`` if the table has that column. A fix with ``fix_type`` below
  2 (no fix) or a NaN coordinate gives no position rows; a NaN heading no heading row.
- ``truth`` (optional, for metrics): the same map.

Vehicle NaNs pass through: a NaN potentiometer skips that row's update, a NaN radar or gyro
reading holds the previous input (``cascade``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
import pyarrow as pa

from navreplay.ingest.schema import FixType
from navreplay.pipeline.estimation.cascaded import cascade as cs
from navreplay.pipeline.estimation.core.tables import Event, ReplayInputError
from navreplay.pipeline.nav.earth import F64, I64
from navreplay.pipeline.nav.local import LocalFrame


@dataclass(frozen=True)
class CascadedInputs:
    """Arrays for ``backends.replay``.

    Attributes:
        veh_t (K,), veh (K, 4): vehicle samples (``cascade.V_*`` columns).
        gps_t (M,), gps (M, 3): East, North (m, in ``frame``), heading (rad); NaN = absent.
        frame: the local map (origin: the first usable fix).
        events: data events found here.
    """

    veh_t: I64
    veh: F64
    gps_t: I64
    gps: F64
    frame: LocalFrame
    events: tuple[Event, ...] = field(default=())


def _col(table: pa.Table, name: str) -> F64 | None:
    if name not in table.column_names:
        return None
    col = table.column(name)
    out: F64 = np.asarray(col.to_numpy(zero_copy_only=False), dtype=np.float64)
    return out


def _required(table: pa.Table, name: str) -> F64:
    """A column the canonical schema requires (validated when the table was read)."""
    values = _col(table, name)
    if values is None:
        raise ReplayInputError(f"the gnss table has no {name!r} column")
    return values


def prepare_inputs(tables: Mapping[str, pa.Table], name: str) -> CascadedInputs:
    """The input arrays of filter ``name`` from canonical tables.

    Raises:
        ReplayInputError: the ``vehicle`` or ``gnss`` table is missing or empty, or no fix
            has a usable position.
    """
    for need in ("vehicle", "gnss"):
        if need not in tables or tables[need].num_rows == 0:
            raise ReplayInputError(
                f"filter {name} needs the {need!r} table, which is absent or empty"
            )
    vt, gt = tables["vehicle"], tables["gnss"]
    veh_t = np.asarray(vt.column("t_ns").to_numpy(), dtype=np.int64)
    events: list[Event] = []
    veh = np.full((veh_t.size, cs.VEH_COLS), np.nan)
    for j, col in ((cs.V_RADAR, "speed_mps"), (cs.V_GYRO, "yaw_rate_radps"),
                   (cs.V_POT, "steer_rad")):  # fmt: skip
        values = _col(vt, col)
        if values is not None:
            veh[:, j] = values
    cmd = _col(vt, "steer_rate_cmd_radps")
    if cmd is None:
        events.append(Event(int(veh_t[0]), "no_steer_command", "vehicle"))
    else:
        veh[:, cs.V_CMD] = cmd
    gps_t = np.asarray(gt.column("t_ns").to_numpy(), dtype=np.int64)
    lat, lon, alt = (_required(gt, c) for c in ("lat_deg", "lon_deg", "alt_m"))
    fix_type = _col(gt, "fix_type")
    usable = np.isfinite(lat) & np.isfinite(lon)
    if fix_type is not None:
        usable &= fix_type >= FixType.FIX_2D
    if not usable.any():
        raise ReplayInputError(f"filter {name}: no GNSS fix has a usable position")
    i0 = int(np.argmax(usable))
    alt0 = float(alt[i0]) if np.isfinite(alt[i0]) else 0.0
    frame = LocalFrame(float(lat[i0]), float(lon[i0]), alt0)
    north, east, _ = frame.to_ned(lat, lon, np.full(lat.size, alt0))
    gps = np.full((gps_t.size, cs.GPS_COLS), np.nan)
    gps[usable, cs.G_E] = east[usable]
    gps[usable, cs.G_N] = north[usable]
    heading = _col(gt, "heading_rad")
    if heading is None:
        events.append(Event(int(gps_t[0]), "no_gnss_heading", "gnss"))
    else:
        gps[:, cs.G_PSI] = heading
    return CascadedInputs(veh_t, veh, gps_t, gps, frame, tuple(events))
