"""libRSF dataset text (TU Chemnitz), the format of the smartLoc GNSS datasets.

One measurement per line, whitespace-separated: ``<type> <time_s> <values...>``. Types read:

============  =========  ========================================================================
type          table      fields after the time (smartLoc readme) and conversion
============  =========  ========================================================================
pseudorange3  gnss_obs   pseudorange (satellite clock and atmospheric delays already removed, so
                         ``sat_clock_m`` = 0), variance (-> ``pseudorange_std_m``), satellite
                         ECEF x/y/z, satellite id, system (1 GPS, 2 SBAS, 4 GLONASS, 8 Galileo,
                         16 QZSS, 32 BeiDou), elevation (deg), C/N0 (dB-Hz). Satellite velocity,
                         azimuth and pseudorange rate are not given (null).
odom3         vehicle    velocity x/y/z (only x, forward, is used), turn rate x/y/z (only z, the
                         yaw rate), their six variances (-> ``speed_std_mps``,
                         ``yaw_rate_std_radps``). The turn rate is counter-clockwise positive
                         (z up, FLU: checked against the ground truth's course), converted to FRD.
point3        truth      ego ECEF x/y/z (+ a zero covariance) -> lat/lon/alt; velocity and
                         attitude not given (null)
============  =========  ========================================================================

Satellite ids: GPS ids are PRNs (``G12``); GLONASS ids are 300 + slot (``R01``); other systems
``id mod 100``.

Earth rotation: the satellite positions in smartLoc are at transmit time in the ECEF frame of
the transmit time (with the ground truth, pseudorange residuals drop from 6.3 m to 2.4 m median
once the rotation is applied). ``gnss_obs`` wants them in the ECEF frame of the receive time
(``ingest.schema``), so each is rotated about z by omega_E * tau, tau = range / c, with the range
from a coarse per-epoch least-squares position (a 100 m error in it moves tau by 0.3 us: < 1 mm).

Time: the stamps are seconds from the start of the run; the files carry no absolute epoch, so
the time base is ``recorder`` (Input and GT files share it). Row offsets are 1-based line
numbers. Bad input: a line of a known type with the wrong number of fields or a value that is
not a number is skipped and counted with its line number; a last line without a newline is a
truncated write and dropped (E-RECOVER, ``--strict`` makes both errors).
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from navreplay.ingest.arrays import F64, I64
from navreplay.ingest.detect import Format
from navreplay.ingest.ecef import geodetic_from_ecef
from navreplay.ingest.errors import CorruptLogError
from navreplay.ingest.gnss.ephemeris import C_MPS, rotate_earth
from navreplay.ingest.platform import UNKNOWN, Platform
from navreplay.ingest.readers._lines import BadLines, partial_line_defect
from navreplay.ingest.readers.base import (
    Batch,
    Inventory,
    LogReader,
    Selection,
    StreamInfo,
)
from navreplay.ingest.schema import TableName
from navreplay.ingest.timebase import NS_PER_S, TimeBase

# type -> (table, number of fields after the type token, axis frame, what it holds)
_TYPES: dict[str, tuple[TableName, int, str | None, str]] = {
    "pseudorange3": (TableName.GNSS_OBS, 10, None, "pseudoranges with satellite ECEF positions"),
    "odom3": (TableName.VEHICLE, 13, "flu", "forward speed and yaw rate"),
    "point3": (TableName.TRUTH, 13, "ned", "ego ECEF position"),
}
_SYSTEMS = {1: "G", 2: "S", 4: "R", 8: "E", 16: "J", 32: "C"}
#: odom3 is a wheel speed and yaw rate: the smartLoc datasets are recorded in cars
ODOMETRY_PLATFORM = Platform("ground", "libRSF odom3 (wheel speed and yaw rate of a car)")
TIME_NOTE = (
    "libRSF stamps count seconds from the start of the run; the files carry no absolute epoch "
    "(time base recorder)"
)


@dataclass
class _Chunk:
    """Lines of one type gathered for a batch."""

    numbers: list[int] = field(default_factory=list)
    fields: list[list[str]] = field(default_factory=list)


class LibrsfReader(LogReader):
    """Reader of one libRSF text file (see the module docstring)."""

    format = Format.LIBRSF
    offsets_are_lines = True

    def inventory(self) -> Inventory:
        counts: dict[str, int] = {}
        first: dict[str, float] = {}
        last: dict[str, float] = {}
        with self.file.open("rb") as fh:
            for raw in fh:
                parts = raw.split(None, 2)
                if len(parts) < 2 or parts[0].startswith(b"#"):
                    continue
                name = parts[0].decode("ascii", "replace")
                counts[name] = counts.get(name, 0) + 1
                try:
                    t = float(parts[1])
                except ValueError:
                    continue
                first.setdefault(name, t)
                last[name] = t
        streams = []
        for name, count in counts.items():
            table, _, frame, what = _TYPES.get(name, (None, 0, None, "not converted"))
            epochs = "" if name != "pseudorange3" else " (one row per satellite and epoch)"
            streams.append(
                StreamInfo(
                    key=name,
                    msgtype=f"libRSF {name}",
                    count=count,
                    start_ns=_ns(first[name]) if name in first else None,
                    end_ns=_ns(last[name]) if name in last else None,
                    table=table,
                    time_base=TimeBase.RECORDER,
                    frame=frame,
                    detail=what + epochs,
                )
            )
        platform = ODOMETRY_PLATFORM if "odom3" in counts else UNKNOWN
        return Inventory(self.path, self.format, tuple(streams), (TIME_NOTE,), platform)

    def read(self, selections: Sequence[Selection]) -> Iterator[Batch]:
        wanted = {s.key for s in selections if s.key in _TYPES}
        if not wanted:
            return
        chunks = {name: _Chunk() for name in wanted}
        bad = BadLines()
        partial: int | None = None
        with self.file.open("rb") as fh:
            for number, raw in enumerate(fh, start=1):
                if not raw.endswith(b"\n"):
                    partial = number
                    break
                parts = raw.decode("ascii", "replace").split()
                if not parts or parts[0] not in wanted:
                    continue
                name = parts[0]
                expected = _TYPES[name][1]
                if len(parts) - 1 != expected:
                    bad.add(number, f"{name} with {len(parts) - 1} fields, expected {expected}")
                    continue
                chunk = chunks[name]
                if len(chunk.numbers) >= self.ctx.batch_rows and _new_epoch(chunk, parts[1]):
                    yield from self._convert(name, chunk, bad)
                    chunks[name] = chunk = _Chunk()
                chunk.numbers.append(number)
                chunk.fields.append(parts[1:])
        for name, chunk in chunks.items():
            if chunk.numbers:
                yield from self._convert(name, chunk, bad)
        self._report(bad, partial)

    def _convert(self, name: str, chunk: _Chunk, bad: BadLines) -> Iterator[Batch]:
        values, ok = _parse(chunk.fields)
        numbers = np.asarray(chunk.numbers, np.int64)
        for r in np.flatnonzero(~ok).tolist():
            bad.add(int(numbers[r]), f"{name}: a field is not a number")
        values, numbers = values[ok], numbers[ok]
        if not len(values):
            return
        t_ns = np.rint(values[:, 0] * NS_PER_S).astype(np.int64)
        if name == "pseudorange3":
            yield _pseudoranges(t_ns, values, numbers)
        elif name == "odom3":
            yield _odometry(t_ns, values, numbers)
        else:
            yield _truth(t_ns, values, numbers)

    def _report(self, bad: BadLines, partial: int | None) -> None:
        if bad.lines:
            self.damage.record(bad.defect())
        if partial is not None:
            self.damage.record(partial_line_defect(partial))


def _ns(t_s: float) -> int:
    return round(t_s * NS_PER_S)


def _new_epoch(chunk: _Chunk, time_field: str) -> bool:
    """A chunk is cut only between epochs (Sagnac needs every satellite of an epoch)."""
    return chunk.fields[-1][0] != time_field


def _parse(fields: list[list[str]]) -> tuple[F64, npt.NDArray[np.bool_]]:
    try:
        return np.array(fields, dtype=np.float64), np.ones(len(fields), bool)
    except ValueError:
        pass
    out = np.full((len(fields), len(fields[0])), np.nan)
    ok = np.ones(len(fields), bool)
    for r, row in enumerate(fields):
        try:
            out[r] = [float(x) for x in row]
        except ValueError:
            ok[r] = False
    return out, ok


def _sv_names(sat_id: F64, system: F64) -> npt.NDArray[np.str_]:
    ids = np.rint(sat_id).astype(np.int64)
    codes = np.rint(system).astype(np.int64)
    out = []
    for i, c in zip(ids.tolist(), codes.tolist(), strict=True):
        letter = _SYSTEMS.get(c, "X")
        number = i - 300 if letter == "R" and i > 300 else i if letter == "G" else i % 100
        out.append(f"{letter}{number:02d}")
    return np.array(out, dtype="<U4")


def _pseudoranges(t_ns: I64, v: F64, numbers: I64) -> Batch:
    sat = v[:, 3:6]
    pr = v[:, 1]
    epoch = np.unique(t_ns, return_inverse=True)[1]
    rx = coarse_positions(epoch, sat, pr, np.rint(v[:, 7]).astype(np.int64))
    tau = np.linalg.norm(sat - rx[epoch], axis=1) / C_MPS
    rotated = rotate_earth(sat, tau)
    u = (rotated - rx[epoch]) / np.linalg.norm(rotated - rx[epoch], axis=1, keepdims=True)
    shift = np.abs(np.einsum("ij,ij->i", rotated - sat, u))
    sv = _sv_names(v[:, 6], v[:, 7])
    order = np.lexsort((sv, t_ns))
    cols: dict[str, np.ndarray] = {
        "t_ns": t_ns,
        "sv": sv,
        "pseudorange_m": pr,
        "pseudorange_std_m": np.sqrt(v[:, 2]),
        "cn0_dbhz": v[:, 9],
        "sat_x_m": rotated[:, 0],
        "sat_y_m": rotated[:, 1],
        "sat_z_m": rotated[:, 2],
        "sat_clock_m": np.zeros(len(t_ns)),
        "elevation_deg": v[:, 8],
    }
    info = {
        "sat_clock_m": "0: satellite clock and atmospheric delays already removed (libRSF)",
        "earth_rotation": "satellite positions rotated into the receive-time ECEF frame "
        f"(line-of-sight effect median {np.median(shift):.2f} m, max {shift.max():.2f} m)",
        "not_provided": "satellite velocity, azimuth, pseudorange rate",
    }
    return Batch(
        "pseudorange3",
        TableName.GNSS_OBS,
        {k: c[order] for k, c in cols.items()},
        numbers[order],
        info=info,
    )


def _odometry(t_ns: I64, v: F64, numbers: I64) -> Batch:
    cols: dict[str, np.ndarray] = {
        "t_ns": t_ns,
        "speed_mps": v[:, 1],
        "yaw_rate_radps": v[:, 6],
        "speed_std_mps": np.sqrt(v[:, 7]),
        "yaw_rate_std_radps": np.sqrt(v[:, 12]),
    }
    info = {"yaw_rate": "turn rate z, counter-clockwise positive (FLU), converted to FRD"}
    return Batch("odom3", TableName.VEHICLE, cols, numbers, frame="flu", info=info)


def _truth(t_ns: I64, v: F64, numbers: I64) -> Batch:
    lat, lon, alt = geodetic_from_ecef(v[:, 1:4])
    cols = {"t_ns": t_ns, "lat_deg": lat, "lon_deg": lon, "alt_m": alt}
    info = {"truth": "smartLoc reference position (ECEF -> WGS-84); no velocity or attitude"}
    return Batch("point3", TableName.TRUTH, cols, numbers, info=info)


def coarse_positions(epoch: I64, sat_m: F64, pr_m: F64, system: I64, iterations: int = 8) -> F64:
    """Per-epoch least-squares receiver positions (ECEF, m), one clock per system.

    Gauss-Newton on ``pr = |sat - rx| + b_system`` for every epoch at once (the normal
    equations are accumulated per epoch); the start is the earth's surface below the mean
    satellite. An epoch with fewer measurements than unknowns takes the position of the
    nearest solved epoch; with none solved, the earth's surface below the satellites.

    Args:
        epoch: epoch index (0..E-1) of each row, shape (N,).
        sat_m: satellite positions, shape (N, 3).
        pr_m: pseudoranges, shape (N,).
        system: constellation code per row, shape (N,).

    Returns:
        Receiver positions, shape (E, 3).
    """
    n_epochs = int(epoch.max()) + 1 if len(epoch) else 0
    systems, sys_idx = np.unique(system, return_inverse=True)
    k = 3 + len(systems)
    mean_sat = np.zeros((n_epochs, 3))
    np.add.at(mean_sat, epoch, sat_m)
    rx: F64 = 6_371_000.0 * mean_sat / np.linalg.norm(mean_sat, axis=1, keepdims=True)
    clock = np.zeros((n_epochs, len(systems)))
    present = np.zeros((n_epochs, len(systems)), bool)
    present[epoch, sys_idx] = True
    rows_per_epoch = np.bincount(epoch, minlength=n_epochs)
    solvable = rows_per_epoch >= 3 + present.sum(axis=1)
    for _ in range(iterations):
        d = rx[epoch] - sat_m
        rng = np.linalg.norm(d, axis=1)
        h = np.zeros((len(pr_m), k))
        h[:, :3] = d / rng[:, None]
        h[np.arange(len(pr_m)), 3 + sys_idx] = 1.0
        res = pr_m - rng - clock[epoch, sys_idx]
        normal = np.zeros((n_epochs, k, k))
        np.add.at(normal, epoch, h[:, :, None] * h[:, None, :])
        rhs = np.zeros((n_epochs, k))
        np.add.at(rhs, epoch, h * res[:, None])
        absent = np.concatenate([np.zeros((n_epochs, 3), bool), ~present], axis=1)
        idx = np.arange(k)
        normal[:, idx, idx] += np.where(absent | ~solvable[:, None], 1.0, 0.0)
        step = np.linalg.solve(normal, rhs[..., None])[..., 0]
        step[~solvable] = 0.0
        rx += step[:, :3]
        clock += step[:, 3:]
    if solvable.any() and not solvable.all():
        good = np.flatnonzero(solvable)
        nearest = good[np.clip(np.searchsorted(good, np.arange(n_epochs)), 0, len(good) - 1)]
        rx[~solvable] = rx[nearest[~solvable]]
    _check_finite(rx)
    return rx


def _check_finite(rx: F64) -> None:
    if not np.isfinite(rx).all():
        raise CorruptLogError("satellite geometry gives no receiver position (non-finite)")
