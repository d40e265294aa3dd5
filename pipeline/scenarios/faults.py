"""The filter-level faults of ``docs/bad-inputs.md`` as transformations of the tables.

``inject`` takes the tables (``imu``, ``gnss``, ``gnss_obs``; absent ones are left out), one
fault spec (the catalogue's defaults filled in) and the log's span, and returns the new
tables, the fault's window and a record of what was injected (times, rows, errors) so a
check (``criteria``) can compare the filter's reaction with it.

Faults hit both GNSS streams, so loosely and tightly coupled filters see the same event: an
antenna offset ``d`` (NED) moves the fix by ``d`` and changes every pseudorange of the epoch
by ``-e . d`` (``e`` the receiver-to-satellite unit vector from ``elevation_deg`` and
``azimuth_deg``; F2); a velocity offset changes the pseudorange rates the same way (F9).
F1's observation fault is one bad pseudorange (see ``_jump``); F7's outliers hit fixes and
observation epochs independently.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import pyarrow as pa

from navreplay.ingest.schema import FixType
from navreplay.pipeline.errors import PipelineError
from navreplay.pipeline.estimation.core.windows import NS, Window
from navreplay.pipeline.nav import earth
from navreplay.pipeline.nav.earth import F64, I64
from navreplay.pipeline.scenarios.config import FaultSpec
from navreplay.pipeline.scenarios.satellites import los_rows

Tables = dict[str, pa.Table]
Record = dict[str, Any]

LABELS = {
    "F1": "GPS position jump (one epoch)",
    "F2": "GPS position step",
    "F4": "GPS outage",
    "F5": "receiver stuck: no satellites, stale fix",
    "F7": "GPS outlier burst",
    "F9": "GPS velocity glitch",
    "F11": "NaN GNSS field",
    "F12": "IMU dropout",
}


class ScenarioError(PipelineError):
    """A scenario cannot be applied to these tables (a column it needs is missing)."""


def times(table: pa.Table) -> I64:
    return np.asarray(table.column("t_ns").to_numpy(), dtype=np.int64)


def column(table: pa.Table, name: str) -> F64:
    """A float column as a writable float64 array (null -> NaN)."""
    col = table.column(name)
    out = np.asarray(col.to_numpy(zero_copy_only=False), dtype=np.float64).copy()
    out[np.asarray(col.is_null().to_numpy(zero_copy_only=False), dtype=bool)] = math.nan
    return out


def with_values(
    table: pa.Table,
    name: str,
    values: np.ndarray,
    keep_nulls: bool = True,
    set_rows: np.ndarray | None = None,
) -> pa.Table:
    """``table`` with column ``name`` replaced by ``values`` in its own Arrow type.

    With ``keep_nulls`` the column's nulls ("not provided") stay null, except in ``set_rows``
    (indices given a value).
    """
    i = table.column_names.index(name)
    field = table.schema.field(i)
    mask = None
    if keep_nulls and table.column(name).null_count:
        mask = np.asarray(table.column(name).is_null().to_numpy(zero_copy_only=False), dtype=bool)
        if set_rows is not None:
            mask[set_rows] = False
    arr = pa.array(values, mask=mask, from_pandas=False).cast(field.type)
    return table.set_column(i, field, arr)


def drop_rows(table: pa.Table, drop: np.ndarray) -> pa.Table:
    return table.filter(pa.array(~drop))


def line_of_sight(obs: pa.Table, why: str) -> F64:
    """Receiver-to-satellite NED unit vectors (n, 3) from elevation and azimuth."""
    for name in ("elevation_deg", "azimuth_deg"):
        if name not in obs.column_names:
            raise ScenarioError(f"{why} needs gnss_obs.{name}, which this dataset does not have")
    return los_rows(column(obs, "elevation_deg"), column(obs, "azimuth_deg"))[:, :3]


def shift_fixes(gnss: pa.Table, rows: np.ndarray, d_ned: F64) -> pa.Table:
    """Move the fixes ``rows`` by ``d_ned`` (len(rows), 3) metres."""
    lat, lon, alt = column(gnss, "lat_deg"), column(gnss, "lon_deg"), column(gnss, "alt_m")
    for i, r in enumerate(rows):
        rm, rn = earth.radii(math.radians(lat[r]))
        lat[r] += math.degrees(d_ned[i, 0] / (rm + alt[r]))
        lon[r] += math.degrees(d_ned[i, 1] / ((rn + alt[r]) * math.cos(math.radians(lat[r]))))
        alt[r] -= d_ned[i, 2]
    out = with_values(gnss, "lat_deg", lat)
    return with_values(with_values(out, "lon_deg", lon), "alt_m", alt)


def shift_ranges(obs: pa.Table, rows: np.ndarray, d_ned: F64, name: str, why: str) -> pa.Table:
    """Change ``name`` (pseudorange or its rate) of ``rows`` by ``-e . d`` for offsets d."""
    if rows.size == 0:
        return obs
    e = line_of_sight(obs, why)[rows]
    values = column(obs, name)
    values[rows] -= np.sum(e * d_ned, axis=1)
    return with_values(obs, name, values)


def _first_at(t: I64, at_ns: int) -> int | None:
    k = int(np.searchsorted(t, at_ns))
    return k if k < t.size else None


def _north(n: int, metres: float) -> F64:
    d = np.zeros((n, 3))
    d[:, 0] = metres
    return d


@dataclass
class _Fault:
    """One fault being injected: the tables (modified in place), its interval and record."""

    out: Tables
    at: int
    end: int
    magnitude: float
    fraction: float
    seed: int
    rec: Record

    def rows(self, name: str) -> np.ndarray:
        t = times(self.out[name])
        return np.flatnonzero((t >= self.at) & (t < self.end))

    def why(self) -> str:
        return f"fault {self.rec['kind']}"


def _jump(f: _Fault) -> None:
    """F1 (one epoch) and F2 (an interval): the fix moved ``magnitude`` north.

    F2 moves every pseudorange of the interval consistently (an antenna swap or a datum
    change moves the antenna for every satellite). F1 puts ``magnitude`` on the pseudorange
    of one satellite, the highest (the measurement fault behind a one-epoch fix jump; a
    consistent shift of every range is a spoofer's signature, not a glitch).
    """
    if "gnss" in f.out:
        rows = f.rows("gnss")
        f.out["gnss"] = shift_fixes(f.out["gnss"], rows, _north(rows.size, f.magnitude))
    if "gnss_obs" not in f.out or (rows := f.rows("gnss_obs")).size == 0:
        return
    obs = f.out["gnss_obs"]
    if f.rec["kind"] == "F2":
        d = _north(rows.size, f.magnitude)
        f.out["gnss_obs"] = shift_ranges(obs, rows, d, "pseudorange_m", f.why())
        return
    r = _highest(obs, rows)
    pr = column(obs, "pseudorange_m")
    pr[r] += f.magnitude
    f.out["gnss_obs"] = with_values(obs, "pseudorange_m", pr)
    f.rec["gnss_obs_sv"] = str(obs.column("sv")[r].as_py())


def _highest(obs: pa.Table, rows: np.ndarray) -> int:
    """The row of the highest satellite among ``rows`` (the first one without elevations)."""
    if "elevation_deg" not in obs.column_names:
        return int(rows[0])
    el = column(obs, "elevation_deg")[rows]
    return int(rows[int(np.nanargmax(el))]) if np.isfinite(el).any() else int(rows[0])


def _outage(f: _Fault) -> None:
    """F4: no GNSS at all in the interval."""
    for name in ("gnss", "gnss_obs"):
        if name in f.out:
            f.out[name] = drop_rows(
                f.out[name], np.isin(np.arange(f.out[name].num_rows), f.rows(name))
            )


def _stuck_receiver(f: _Fault) -> None:
    """F5: no satellites; the fixes repeat the last one before with fix_type 0."""
    if "gnss_obs" in f.out:
        obs = f.out["gnss_obs"]
        f.out["gnss_obs"] = drop_rows(obs, np.isin(np.arange(obs.num_rows), f.rows("gnss_obs")))
    if "gnss" in f.out:
        f.out["gnss"], f.rec["stale_rows"] = _stuck(f.out["gnss"], f.at, f.end)


def _burst(f: _Fault) -> None:
    """F7: ``fraction`` of the samples in the interval get N(0, magnitude) errors.

    A sample is what the receiver outputs at one instant: a fix (each NED component its own
    draw) or an observation epoch (each pseudorange of a hit epoch its own draw), so both
    couplings see outliers at the same fraction of instants, like a multipath burst.
    The record keeps the rows hit and their errors (fixes: NED metres; pseudoranges: m).
    """
    rng = np.random.default_rng(f.seed)
    if "gnss" in f.out:
        gnss = f.out["gnss"]
        rows = f.rows("gnss")
        hit = np.sort(rng.choice(rows, size=round(f.fraction * rows.size), replace=False))
        err = rng.normal(0.0, f.magnitude, (hit.size, 3))
        f.out["gnss"] = shift_fixes(gnss, hit, err)
        f.rec["gnss_rows"], f.rec["gnss_hit_t_ns"] = int(rows.size), times(gnss)[hit].tolist()
        f.rec["gnss_hit_err_m"] = err.tolist()
    if "gnss_obs" in f.out:
        obs = f.out["gnss_obs"]
        rows = f.rows("gnss_obs")
        t_rows = times(obs)[rows]
        epochs = np.unique(t_rows)
        hit_t = np.sort(rng.choice(epochs, size=round(f.fraction * epochs.size), replace=False))
        hit = rows[np.isin(t_rows, hit_t)]
        err = rng.normal(0.0, f.magnitude, hit.size)
        pr = column(obs, "pseudorange_m")
        pr[hit] += err
        f.out["gnss_obs"] = with_values(obs, "pseudorange_m", pr)
        f.rec["gnss_obs_rows"], f.rec["gnss_obs_hit"] = int(rows.size), hit.tolist()
        f.rec["gnss_obs_hit_t_ns"] = times(obs)[hit].tolist()
        f.rec["gnss_obs_hit_sv"] = [str(obs.column("sv")[int(j)].as_py()) for j in hit]
        f.rec["gnss_obs_hit_err_m"] = err.tolist()
        f.rec["gnss_obs_epochs"], f.rec["gnss_obs_hit_epochs"] = int(epochs.size), hit_t.tolist()


def _velocity_glitch(f: _Fault) -> None:
    """F9: the GNSS velocity (and the pseudorange rates) off by ``magnitude`` north."""
    if "gnss" in f.out:
        gnss = f.out["gnss"]
        rows = f.rows("gnss")
        vn = column(gnss, "vel_n_mps")
        vn[rows] += f.magnitude
        f.out["gnss"] = with_values(gnss, "vel_n_mps", vn)
        f.rec["gnss_rows"] = int(rows.size)
    if "gnss_obs" in f.out:
        rows = f.rows("gnss_obs")
        d = _north(rows.size, f.magnitude)
        f.out["gnss_obs"] = shift_ranges(
            f.out["gnss_obs"], rows, d, "pseudorange_rate_mps", f.why()
        )


def _nan_field(f: _Fault) -> None:
    """F11: the fix's latitude and the highest satellite's pseudorange become NaN."""
    if "gnss" in f.out:
        gnss = f.out["gnss"]
        lat = column(gnss, "lat_deg")
        lat[f.rows("gnss")] = math.nan
        f.out["gnss"] = with_values(gnss, "lat_deg", lat)
    if "gnss_obs" in f.out and (rows := f.rows("gnss_obs")).size:
        obs = f.out["gnss_obs"]
        r = _highest(obs, rows)
        pr = column(obs, "pseudorange_m")
        pr[r] = math.nan
        f.out["gnss_obs"] = with_values(obs, "pseudorange_m", pr)
        f.rec["gnss_obs_sv"] = str(obs.column("sv")[r].as_py())


def _imu_dropout(f: _Fault) -> None:
    """F12: no IMU samples in the interval."""
    if "imu" not in f.out:
        raise ScenarioError(f"{f.why()} needs an imu table")
    rows = f.rows("imu")
    f.out["imu"] = drop_rows(f.out["imu"], np.isin(np.arange(f.out["imu"].num_rows), rows))
    f.rec["imu_rows_removed"] = int(rows.size)


_INJECT: dict[str, Callable[[_Fault], None]] = {
    "F1": _jump,
    "F2": _jump,
    "F4": _outage,
    "F5": _stuck_receiver,
    "F7": _burst,
    "F9": _velocity_glitch,
    "F11": _nan_field,
    "F12": _imu_dropout,
}


def _epoch_at(tables: Mapping[str, pa.Table], at: int) -> int | None:
    """The first GNSS epoch (fix, else observation) at or after ``at``."""
    for name in ("gnss", "gnss_obs"):
        if name in tables and (k := _first_at(times(tables[name]), at)) is not None:
            return int(times(tables[name])[k])
    return None


def inject(
    tables: Mapping[str, pa.Table], fault: FaultSpec, t0_ns: int, t_end_ns: int
) -> tuple[Tables, Window, Record]:
    """Apply one fault; returns (tables, its window, what was injected).

    Raises:
        ScenarioError: a one-epoch fault (F1, F11) has no GNSS epoch at or after its time, or
            the fault needs a column or table the dataset lacks.
    """
    duration_s, magnitude, fraction = fault.resolved()
    at = t0_ns + round(fault.at_s * NS)
    end = t_end_ns + 1 if fault.kind == "F2" and duration_s == 0 else at + round(duration_s * NS)
    rec: Record = {"kind": fault.kind, "at_t_ns": at}
    if fault.kind in ("F1", "F11"):
        epoch = _epoch_at(tables, at)
        if epoch is None:
            raise ScenarioError(f"fault {fault.kind} at {fault.at_s} s: no GNSS epoch after it")
        at, end = epoch, epoch + 1
        rec["epoch_t_ns"] = epoch
    f = _Fault(dict(tables), at, end, magnitude, fraction, fault.seed, rec)
    _INJECT[fault.kind](f)
    sats = 0 if fault.kind in ("F4", "F5") else None
    label = f"{fault.kind} {LABELS[fault.kind]}"
    return f.out, Window(at, min(end, t_end_ns + 1), fault.kind, sats, label), rec


def _stuck(gnss: pa.Table, at: int, end: int) -> tuple[pa.Table, int]:
    """F5: the fixes in ``[at, end)`` repeat the last fix before ``at`` with fix_type 0."""
    t = times(gnss)
    rows = np.flatnonzero((t >= at) & (t < end))
    last = int(np.searchsorted(t, at)) - 1
    if rows.size == 0 or last < 0:
        return gnss, 0
    out = gnss
    for name in ("lat_deg", "lon_deg", "alt_m", "vel_n_mps", "vel_e_mps", "vel_d_mps"):
        if name in gnss.column_names:
            v = column(gnss, name)
            v[rows] = v[last]
            out = with_values(out, name, v)
    ft = np.asarray(gnss.column("fix_type").to_numpy(zero_copy_only=False)).copy()
    ft[rows] = FixType.NO_GPS
    out = with_values(out, "fix_type", ft, keep_nulls=False)
    if "num_sats" in gnss.column_names:
        ns = np.asarray(column(gnss, "num_sats"))
        ns[rows] = 0
        out = with_values(out, "num_sats", np.nan_to_num(ns), keep_nulls=False)
    return out, int(rows.size)
