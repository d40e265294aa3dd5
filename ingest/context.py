"""The log's context beside its sensor streams: what the vehicle said and did, how it shook.

Readers that find them return a ``LogContext`` from ``LogReader.context()``: text messages
(ArduPilot ``MSG``, MAVLink ``STATUSTEXT``, PX4 ``logged_messages``), mode changes, arming and
disarming, autopilot events and subsystem errors as rows of the ``events`` table; vibration
levels and accelerometer clipping counts per IMU as rows of ``vibration``. ``ingest`` puts
every file's context on the dataset's time base and writes both tables beside the sensor
tables (``schema.ContextName``). Log text is untrusted: it is stored as logged, and whoever
shows it escapes it.

The names of ArduPilot's event ids and error subsystems are those of its ``LogStructure.h``
(``LogEvent``, ``LogErrorSubsystem``: ids are never reused); an id not listed shows as its
number. Mode names come from pymavlink's mode tables (``mavutil.mode_string_v10``,
``mode_mapping_bynumber``).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pyarrow as pa

from navreplay.ingest.arrays import I64
from navreplay.ingest.errors import IngestError
from navreplay.ingest.schema import ContextName, EventKind, from_columns
from navreplay.ingest.tables import Provenance, SourceFile, write_table
from navreplay.ingest.timebase import TimeBase, convert

#: ArduPilot ``LogEvent`` ids (the ``EV`` message's ``Id``).
ARDUPILOT_EVENTS = {
    8: "system time set",
    10: "armed",
    11: "disarmed",
    15: "auto armed",
    16: "takeoff",
    17: "land complete maybe",
    18: "land complete",
    19: "lost GPS",
    21: "flip start",
    22: "flip end",
    25: "set home",
    26: "simple mode on",
    27: "simple mode off",
    28: "not landed",
    29: "super simple mode on",
    30: "autotune initialised",
    31: "autotune off",
    32: "autotune restart",
    33: "autotune success",
    34: "autotune failed",
    35: "autotune reached limit",
    36: "autotune pilot testing",
    37: "autotune saved gains",
    38: "save trim",
    39: "save waypoint",
    41: "fence enabled",
    42: "fence disabled",
    46: "gripper grab",
    47: "gripper release",
    49: "parachute disabled",
    50: "parachute enabled",
    51: "parachute released",
    52: "landing gear deployed",
    53: "landing gear retracted",
    54: "motors emergency stopped",
    55: "motors emergency stop cleared",
    56: "motor interlock disabled",
    57: "motor interlock enabled",
    58: "rotor run-up complete",
    59: "rotor speed below critical",
    60: "EKF altitude reset",
    61: "land cancelled by pilot",
    62: "EKF yaw reset",
    67: "GPS primary changed",
    73: "land reposition active",
    74: "standby enabled",
    75: "standby disabled",
    85: "EKF3 sources set to primary",
    86: "EKF3 sources set to secondary",
    87: "EKF3 sources set to tertiary",
    90: "airspeed primary changed",
}
#: The ``EV`` ids of arming and disarming (events of kind ``arming`` unless ``ARM`` is logged).
ARDUPILOT_ARMING_EVENTS = {10: "armed", 11: "disarmed"}
#: ArduPilot ``LogErrorSubsystem`` ids (the ``ERR`` message's ``Subsys``).
ARDUPILOT_SUBSYSTEMS = {
    1: "main",
    2: "radio",
    3: "compass",
    4: "optical flow",
    5: "radio failsafe",
    6: "battery failsafe",
    7: "GPS failsafe",
    8: "GCS failsafe",
    9: "fence failsafe",
    10: "flight mode",
    11: "GPS",
    12: "crash check",
    13: "flip",
    14: "autotune",
    15: "parachute",
    16: "EKF check",
    17: "EKF/inertial nav failsafe",
    18: "barometer",
    19: "CPU",
    20: "ADS-B failsafe",
    21: "terrain",
    22: "navigation",
    23: "terrain failsafe",
    24: "EKF primary",
    25: "thrust loss check",
    26: "sensors failsafe",
    27: "leak failsafe",
    28: "pilot input",
    29: "vibration failsafe",
    30: "internal error",
    31: "dead-reckoning failsafe",
}
#: ``ECode`` 0 clears a subsystem's error (or failsafe); the other codes depend on it.
ERROR_CLEARED = 0
#: PX4 ``vehicle_status.nav_state`` values.
PX4_NAV_STATES = {
    0: "MANUAL",
    1: "ALTCTL",
    2: "POSCTL",
    3: "AUTO_MISSION",
    4: "AUTO_LOITER",
    5: "AUTO_RTL",
    10: "ACRO",
    12: "DESCEND",
    13: "TERMINATION",
    14: "OFFBOARD",
    15: "STAB",
    17: "AUTO_TAKEOFF",
    18: "AUTO_LAND",
    19: "AUTO_FOLLOW_TARGET",
    20: "AUTO_PRECLAND",
    21: "ORBIT",
    22: "AUTO_VTOL_TAKEOFF",
}
#: MAVLink ``MAV_SEVERITY`` (= syslog) names, for showing ``events.severity``.
SEVERITY_NAMES = ("emergency", "alert", "critical", "error", "warning", "notice", "info", "debug")
#: ArduPilot firmware name -> MAV_TYPE of its mode table (pymavlink ``mode_mapping_bynumber``).
_FIRMWARE_MAV_TYPE = (("copter", 2), ("heli", 2), ("plane", 1), ("rover", 10), ("sub", 12))


@dataclass
class EventRows:
    """Rows of the ``events`` table being collected, on one time base."""

    t_ns: list[I64] = field(default_factory=list)
    kind: list[str] = field(default_factory=list)
    severity: list[int | None] = field(default_factory=list)
    text: list[str] = field(default_factory=list)
    source: list[str] = field(default_factory=list)

    def add(
        self,
        t_ns: I64,
        kind: EventKind,
        texts: Sequence[str],
        source: str,
        severity: Sequence[int | None] | None = None,
    ) -> None:
        """Append ``len(t_ns)`` rows of one kind from one log record type."""
        n = len(t_ns)
        if not n:
            return
        self.t_ns.append(np.asarray(t_ns, np.int64))
        self.kind += [kind.value] * n
        self.text += list(texts)
        self.source += [source] * n
        self.severity += list(severity) if severity is not None else [None] * n

    def __len__(self) -> int:
        return len(self.kind)

    def drop(self, kind: EventKind, source: str) -> None:
        """Remove the rows of ``kind`` from ``source`` (a duplicate of another record)."""
        keep = [
            not (k == kind.value and s == source)
            for k, s in zip(self.kind, self.source, strict=True)
        ]
        if all(keep):
            return
        t = np.concatenate(self.t_ns)[np.array(keep)]
        self.t_ns = [t]
        for name in ("kind", "severity", "text", "source"):
            values = getattr(self, name)
            setattr(self, name, [v for v, k in zip(values, keep, strict=True) if k])


@dataclass
class LogContext:
    """One file's context on ``time_base``: events and, where logged, vibration columns
    (``t_ns``, ``imu`` and the levels; see ``schema.ContextName.VIBRATION``)."""

    time_base: TimeBase
    events: EventRows = field(default_factory=EventRows)
    vibration: dict[str, np.ndarray] = field(default_factory=dict)


def changes(values: np.ndarray) -> np.ndarray:
    """Indices where ``values`` differs from the value before (the first row included)."""
    values = np.asarray(values)
    if not len(values):
        return np.empty(0, np.intp)
    return np.flatnonzero(np.concatenate(([True], values[1:] != values[:-1])))


def forward(t_ns: np.ndarray) -> np.ndarray:
    """Rows whose time is past every earlier row's: a state series read without the rows of
    a clock that went back (a log copied twice into one file repeats its start)."""
    t = np.asarray(t_ns, np.int64)
    if not len(t):
        return np.zeros(0, bool)
    before = np.maximum.accumulate(np.concatenate(([np.iinfo(np.int64).min], t[:-1])))
    return np.asarray(t > before)


def decode_text(raw: Iterable[bytes | str]) -> list[str]:
    """Logged C strings as text: up to the first NUL, undecodable bytes replaced."""
    out = []
    for r in raw:
        b = r if isinstance(r, bytes) else r.encode("utf-8", "replace")
        out.append(b.split(b"\0", 1)[0].decode("utf-8", "replace").strip())
    return out


def severity_name(severity: int | None) -> str:
    """``warning`` for 4; ``-`` for none."""
    if severity is None or not 0 <= severity < len(SEVERITY_NAMES):
        return "-"
    return SEVERITY_NAMES[severity]


def ardupilot_event_name(event_id: int) -> str:
    return ARDUPILOT_EVENTS.get(event_id, f"event {event_id}")


def ardupilot_error_text(subsystem: int, code: int) -> str:
    """``GPS: error 2`` / ``GPS: cleared`` (ArduPilot's codes depend on the subsystem)."""
    name = ARDUPILOT_SUBSYSTEMS.get(subsystem, f"subsystem {subsystem}")
    return f"{name}: {'cleared' if code == ERROR_CLEARED else f'error {code}'}"


def ardupilot_mode_name(mode: int, firmware: str) -> str:
    """An ArduPilot mode number's name for the vehicle of ``firmware`` (its ``MSG`` banner,
    e.g. ``ArduCopter V4.3.6``); ``mode N`` when neither is known."""
    from pymavlink import mavutil

    lower = firmware.lower()
    for word, mav_type in _FIRMWARE_MAV_TYPE:
        if word in lower:
            table = mavutil.mode_mapping_bynumber(mav_type) or {}
            return str(table.get(mode, f"mode {mode}"))
    return f"mode {mode}"


def mavlink_mode_name(mav_type: int, autopilot: int, base_mode: int, custom_mode: int) -> str:
    """A HEARTBEAT's mode as pymavlink names it (ArduPilot and PX4 custom modes)."""
    from pymavlink import mavutil

    beat = SimpleNamespace(
        type=mav_type,
        autopilot=autopilot,
        base_mode=base_mode,
        custom_mode=custom_mode,
        get_type=lambda: "HEARTBEAT",
    )
    return str(mavutil.mode_string_v10(beat))


def px4_mode_name(nav_state: int) -> str:
    return PX4_NAV_STATES.get(nav_state, f"nav_state {nav_state}")


def events_table(rows: EventRows) -> pa.Table:
    """The ``events`` table of collected rows: sorted by time (stable: rows of one instant keep
    the order the log gave them), exact repeats dropped, ``seq`` numbering the rows that share
    a ``t_ns``."""
    t = np.concatenate(rows.t_ns) if rows.t_ns else np.empty(0, np.int64)
    order = np.argsort(t, kind="stable")
    seen: set[tuple[Any, ...]] = set()
    unique = []  # a row repeated exactly (a log written twice into one file) is kept once
    for i in order.tolist():
        row = (int(t[i]), rows.kind[i], rows.severity[i], rows.text[i], rows.source[i])
        if row not in seen:
            seen.add(row)
            unique.append(i)
    order = np.asarray(unique, np.intp)
    t = t[order]
    seq = np.zeros(len(t), np.int32)
    if len(t):
        same = np.concatenate(([False], t[1:] == t[:-1]))
        run_start = np.maximum.accumulate(np.where(~same, np.arange(len(t)), 0))
        seq = (np.arange(len(t)) - run_start).astype(np.int32)
    pick = order.tolist()
    return from_columns(
        ContextName.EVENTS,
        {
            "t_ns": t,
            "seq": seq,
            "kind": [rows.kind[i] for i in pick],
            "severity": pa.array([rows.severity[i] for i in pick], pa.int8()),
            "text": [rows.text[i] for i in pick],
            "source": [rows.source[i] for i in pick],
        },
    )


def vibration_table(parts: Sequence[dict[str, np.ndarray]]) -> pa.Table | None:
    """The ``vibration`` table of the files' columns, sorted by (t_ns, imu) with exact
    duplicates of a key dropped; None when no file logged vibration."""
    parts = [p for p in parts if p and len(p["t_ns"])]
    if not parts:
        return None
    names = sorted({k for p in parts for k in p})
    n = [len(p["t_ns"]) for p in parts]
    cols: dict[str, np.ndarray] = {}
    for name in names:
        fill = np.zeros if name in ("t_ns", "imu") else _nan
        cols[name] = np.concatenate(
            [p[name] if name in p else fill(k) for p, k in zip(parts, n, strict=True)]
        )
    order = np.lexsort((cols["imu"], cols["t_ns"]))
    cols = {k: v[order] for k, v in cols.items()}
    keep = np.concatenate(
        ([True], (np.diff(cols["t_ns"]) != 0) | (np.diff(cols["imu"].astype(np.int64)) != 0))
    )
    cols = {k: v[keep] for k, v in cols.items()}
    cols["imu"] = cols["imu"].astype(np.int16)
    for name in ("vibe_x_mps2", "vibe_y_mps2", "vibe_z_mps2", "clip_count"):
        if name in cols:
            continue
        cols[name] = np.full(len(cols["t_ns"]), np.nan)
    return from_columns(ContextName.VIBRATION, cols)


def _nan(n: int) -> np.ndarray:
    return np.full(n, np.nan)


def write_context(
    out_dir: Path,
    contexts: Sequence[tuple[str, LogContext]],
    base: TimeBase,
    sources: Sequence[SourceFile],
    params: dict[str, Any],
) -> tuple[dict[str, int], list[str]]:
    """Write ``events.parquet`` and ``vibration.parquet`` of the files' contexts (file name,
    context) on ``base``. Returns the rows written per table (a table nothing logged is not
    written) and warnings: a file whose context cannot be put on ``base`` is left out."""
    events = EventRows()
    vibration: list[dict[str, np.ndarray]] = []
    warnings: list[str] = []
    for name, ctx in contexts:
        try:
            moved = [convert(t, ctx.time_base, base) for t in ctx.events.t_ns]
            vib = dict(ctx.vibration)
            if vib:
                vib["t_ns"] = convert(vib["t_ns"], ctx.time_base, base)
        except IngestError as err:
            warnings.append(f"{name}: its messages, modes and vibration are left out: {err}")
            continue
        ev = ctx.events
        events.t_ns += moved
        events.kind += ev.kind
        events.severity += ev.severity
        events.text += ev.text
        events.source += ev.source
        if vib:
            vibration.append(vib)
    written: dict[str, int] = {}
    tables = {ContextName.EVENTS: events_table(events) if len(events) else None}
    tables[ContextName.VIBRATION] = vibration_table(vibration)
    for cname, table in tables.items():
        if table is None:
            continue
        prov = Provenance.create(cname, sources=sources, params=params)
        write_table(out_dir / f"{cname.value}.parquet", cname, table, prov)
        written[cname.value] = table.num_rows
    return written, warnings
