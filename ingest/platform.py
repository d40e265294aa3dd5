"""The kind of vehicle a log was recorded on, and where that knowledge comes from.

``meta.json`` ``sensors.platform`` holds it: ``kind`` is one of ``ground``, ``multirotor``,
``fixed_wing``, ``vtol`` or ``unknown``; ``source`` says what decided it (``HEARTBEAT type 2
(MAV_TYPE_QUADROTOR)``, ``firmware "ArduCopter V4.3.7"``, ``dataset.yaml``). The pipeline uses
it to pick the filters that fit (the non-holonomic constraint holds only for ground vehicles).

The readers decide from what their format carries:

- MAVLink tlog: the autopilot's ``HEARTBEAT.type`` (``MAV_TYPE``; ground stations, gimbals
  and cameras are ignored);
- ArduPilot DataFlash: the firmware string of the first ``MSG``/``VER`` records;
- both: an ArduPlane whose ``Q_ENABLE`` parameter is set is a QuadPlane, a VTOL;
- PX4 ULog: ``vehicle_status`` (``system_type``, ``is_vtol``, ``is_rotary_wing``,
  ``vehicle_type``) or the ``MAV_TYPE`` parameter;
- comma2k19 (a car) and smartLoc (a car): ground; every other format: unknown.

``dataset.yaml`` ``platform:`` overrides whatever the log says.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Literal

PlatformKind = Literal["ground", "multirotor", "fixed_wing", "vtol", "unknown"]
PLATFORM_KINDS: tuple[str, ...] = ("ground", "multirotor", "fixed_wing", "vtol", "unknown")


@dataclass(frozen=True)
class Platform:
    """The vehicle kind and what it was decided from.

    Attributes:
        kind: ``ground``, ``multirotor``, ``fixed_wing``, ``vtol`` or ``unknown``.
        source: what decided it (a message and value, a firmware string, ``dataset.yaml``),
            or ``"nothing in the log"``.
    """

    kind: PlatformKind = "unknown"
    source: str = "nothing in the log"

    @property
    def known(self) -> bool:
        return self.kind != "unknown"

    def text(self) -> str:
        """``multirotor (from HEARTBEAT type 2 (MAV_TYPE_QUADROTOR))``."""
        return f"{self.kind} (from {self.source})"


UNKNOWN = Platform()

#: MAV_TYPE value -> (enum name as in pymavlink 2.4, kind, remark); values not listed say
#: nothing of the vehicle (generic, GCS, gimbal, camera, ADS-B, onboard computer ...)
MAV_TYPES: dict[int, tuple[str, PlatformKind, str]] = {
    1: ("MAV_TYPE_FIXED_WING", "fixed_wing", ""),
    2: ("MAV_TYPE_QUADROTOR", "multirotor", ""),
    3: ("MAV_TYPE_COAXIAL", "multirotor", "a coaxial helicopter, hovers as a multirotor"),
    4: ("MAV_TYPE_HELICOPTER", "multirotor", "a helicopter, hovers as a multirotor"),
    7: ("MAV_TYPE_AIRSHIP", "unknown", "an airship"),
    10: ("MAV_TYPE_GROUND_ROVER", "ground", ""),
    11: ("MAV_TYPE_SURFACE_BOAT", "ground", "a surface boat, moves on the surface"),
    12: ("MAV_TYPE_SUBMARINE", "unknown", "a submarine"),
    13: ("MAV_TYPE_HEXAROTOR", "multirotor", ""),
    14: ("MAV_TYPE_OCTOROTOR", "multirotor", ""),
    15: ("MAV_TYPE_TRICOPTER", "multirotor", ""),
    19: ("MAV_TYPE_VTOL_DUOROTOR", "vtol", ""),
    20: ("MAV_TYPE_VTOL_QUADROTOR", "vtol", ""),
    21: ("MAV_TYPE_VTOL_TILTROTOR", "vtol", ""),
    22: ("MAV_TYPE_VTOL_RESERVED2", "vtol", "a fixed-rotor VTOL in later MAVLink"),
    23: ("MAV_TYPE_VTOL_RESERVED3", "vtol", "a tailsitter in later MAVLink"),
    24: ("MAV_TYPE_VTOL_RESERVED4", "vtol", "a tiltwing in later MAVLink"),
    25: ("MAV_TYPE_VTOL_RESERVED5", "vtol", ""),
    29: ("MAV_TYPE_DODECAROTOR", "multirotor", ""),
    35: ("MAV_TYPE_DECAROTOR", "multirotor", ""),
    43: ("MAV_TYPE_GENERIC_MULTIROTOR", "multirotor", ""),
    47: ("MAV_TYPE_VTOL_GYRODYNE", "vtol", ""),
}
#: MAV_TYPE of a ground control station
MAV_TYPE_GCS = 6
#: MAV_AUTOPILOT of a component that is no flight controller (GCS, companion, gimbal)
MAV_AUTOPILOT_INVALID = 8


def from_mav_type(value: int, where: str) -> Platform | None:
    """The platform a ``MAV_TYPE`` value names, None when it names no vehicle.

    Args:
        value: the ``MAV_TYPE`` number.
        where: what carried it, e.g. ``HEARTBEAT`` or ``vehicle_status.system_type``.
    """
    entry = MAV_TYPES.get(int(value))
    if entry is None:
        return None
    name, kind, remark = entry
    source = f"{where} type {int(value)} ({name}{': ' + remark if remark else ''})"
    return Platform(kind, source)


def from_heartbeats(types: Iterable[tuple[int, int, int]]) -> Platform:
    """The platform from a tlog's HEARTBEAT ``(type, autopilot, count)`` of one sender.

    The most frequent type that names a vehicle wins; a GCS heartbeat, or one whose
    autopilot is ``MAV_AUTOPILOT_INVALID``, never does.
    """
    best: tuple[int, int] | None = None
    for mav_type, autopilot, count in types:
        if mav_type == MAV_TYPE_GCS or autopilot == MAV_AUTOPILOT_INVALID:
            continue
        if mav_type in MAV_TYPES and (best is None or count > best[1]):
            best = (mav_type, count)
    if best is None:
        return UNKNOWN
    return from_mav_type(best[0], "HEARTBEAT") or UNKNOWN


def with_q_enable(found: Platform, q_enable: float | None) -> Platform:
    """An ArduPlane QuadPlane: a fixed wing whose ``Q_ENABLE`` parameter is set is a VTOL."""
    if found.kind != "fixed_wing" or q_enable is None or q_enable < 1:
        return found
    return Platform("vtol", f"{found.source} with parameter Q_ENABLE {q_enable:g} (a QuadPlane)")


#: firmware name (lowercase prefix of the text) -> kind, most specific first
_FIRMWARES: tuple[tuple[str, PlatformKind, str], ...] = (
    ("arducopter", "multirotor", ""),
    ("apm:copter", "multirotor", ""),
    ("arduheli", "multirotor", "a helicopter, hovers as a multirotor"),
    ("arduplane", "fixed_wing", ""),
    ("apm:plane", "fixed_wing", ""),
    ("ardurover", "ground", ""),
    ("apmrover2", "ground", ""),
    ("apm:rover", "ground", ""),
    ("ardusub", "unknown", "a submarine"),
    ("blimp", "unknown", "a blimp"),
)


def from_firmware(lines: Iterable[str]) -> Platform:
    """The platform from an ArduPilot log's first text messages (``MSG``/``VER``).

    ``ArduCopter``/``APM:Copter``/``ArduHeli`` -> multirotor, ``ArduPlane`` -> fixed_wing (a
    QuadPlane is not told apart here), ``ArduRover``/``APMrover2`` -> ground, ``ArduSub``
    -> unknown (said in the source).
    """
    for line in lines:
        words = line.strip().split()
        for i, word in enumerate(words):
            low = word.lower()
            for prefix, kind, remark in _FIRMWARES:
                if low.startswith(prefix):
                    text = " ".join(words[i : i + 2])
                    return Platform(kind, f'firmware "{text}"' + (f" ({remark})" if remark else ""))
    return UNKNOWN


#: PX4 ``vehicle_status.vehicle_type`` (PX4 1.13 on): 1 rotary wing, 2 fixed wing, 3 rover
_PX4_VEHICLE_TYPES: dict[int, PlatformKind] = {1: "multirotor", 2: "fixed_wing", 3: "ground"}


def from_px4_status(fields: dict[str, int]) -> Platform:
    """The platform from the first ``vehicle_status`` of a PX4 ULog.

    Args:
        fields: the values of those of ``system_type``, ``is_vtol``, ``is_rotary_wing`` and
            ``vehicle_type`` the log's version has.
    """
    if fields.get("is_vtol"):
        return Platform("vtol", "vehicle_status.is_vtol")
    if "system_type" in fields:
        found = from_mav_type(fields["system_type"], "vehicle_status.system_type")
        if found is not None:
            return found
    if "vehicle_type" in fields and fields["vehicle_type"] in _PX4_VEHICLE_TYPES:
        value = fields["vehicle_type"]
        return Platform(_PX4_VEHICLE_TYPES[value], f"vehicle_status.vehicle_type {value}")
    if fields.get("is_rotary_wing"):
        return Platform("multirotor", "vehicle_status.is_rotary_wing")
    return UNKNOWN


def resolve(declared: str | None, found: Iterable[Platform]) -> Platform:
    """The dataset's platform: ``dataset.yaml``'s if declared, else the first log's that
    knows it, else the first unknown one with a reason (``ArduSub``), else unknown."""
    if declared is not None:
        return Platform(_kind(declared), "dataset.yaml")
    found = list(found)
    return next((p for p in found if p.known), next((p for p in found if p != UNKNOWN), UNKNOWN))


def _kind(value: str) -> PlatformKind:
    for k in ("ground", "multirotor", "fixed_wing", "vtol", "unknown"):
        if value == k:
            return k
    raise ValueError(f"{value!r} is not one of {', '.join(PLATFORM_KINDS)}")
