"""Car test beds for filters that start anywhere (issue 21): the ``seoul_campus`` car, IMU and
receiver on three other drives, with exact truth.

- ``car_rolling_start``: the log begins with the car already moving (no standstill at all),
  a curve a few seconds in;
- ``car_parking_reverse``: at rest in a parking bay, the car reverses out of it (backwards at
  walking pace while turning by 90 deg: the course is the heading plus 180 deg), stops, then
  drives forwards;
- ``car_stop_and_go``: city traffic: short accelerations, stops of 5-30 s, slow creeping.

Each drive is a ``CarDriveParams`` under ``synth.car_drives.<dataset>`` in ``params.yaml``: its
route (``trajectory.Leg``; a negative speed reverses), the rest before it, a start speed for a
rolling start, the initial heading and the length. Everything else (place, start time, rates,
lever arm, comfort limits, IMU, receiver and constellation error models) is
``synth.seoul_campus``'s, and the simulation is ``seoul_campus.simulate_drive``: one simulator,
the same writers (MCAP, ROS 1 bag, RINEX observation and navigation files, ``reference/``).
The random streams of a drive derive from ``synth.seed`` and a hash of its dataset id.
"""

from __future__ import annotations

import dataclasses
import zlib
from dataclasses import dataclass
from pathlib import Path

from navreplay.ingest.typed import FieldError
from navreplay.pipeline.synth import SynthResult, SynthSection
from navreplay.pipeline.synth.seoul_params import SeoulCampusParams
from navreplay.pipeline.synth.trajectory import Leg

DRIVES = ("car_rolling_start", "car_parking_reverse", "car_stop_and_go")


@dataclass(frozen=True)
class CarDriveParams:
    """``synth.car_drives.<dataset>``: one drive of the campus car.

    Attributes:
        duration_s: length of the log, s (the route repeats if it is shorter).
        stationary_s: at rest before the route, s (0 for a rolling start).
        start_speed_mps: speed at the first sample, along the body x axis (a rolling start:
            held straight ahead until the route takes over); 0: a start at rest.
        yaw_deg: heading at the first sample, clockwise from north.
        route: the legs, in order (``trajectory.Leg``; a negative speed reverses).
    """

    duration_s: float
    stationary_s: float
    start_speed_mps: float
    yaw_deg: float
    route: tuple[Leg, ...]

    def __post_init__(self) -> None:
        if self.duration_s <= 0:
            raise FieldError("duration_s", "must be > 0")
        if self.stationary_s < 0:
            raise FieldError("stationary_s", "must be >= 0")
        if not self.route:
            raise FieldError("route", "needs at least one leg")
        if self.start_speed_mps < 0:
            raise FieldError("start_speed_mps", "a rolling start rolls forwards (>= 0)")


def drive_params(campus: SeoulCampusParams, drive: CarDriveParams) -> SeoulCampusParams:
    """The simulator's parameters of ``drive``: the campus car's, with the drive's length,
    rest and initial heading."""
    return dataclasses.replace(
        campus,
        duration_s=drive.duration_s,
        stationary_s=drive.stationary_s,
        yaw_deg=drive.yaw_deg,
    )


def stream_of(name: str) -> int:
    """The random stream of dataset ``name`` (``seoul_campus.simulate_drive``): a hash of
    its id (the campus variants use 1 and 2)."""
    return zlib.crc32(name.encode())


def simulate(
    name: str, campus: SeoulCampusParams, drive: CarDriveParams, *, seed: int
) -> SynthResult:
    """Synthesize dataset ``name`` (its ``drive`` with the ``campus`` car and sensors)."""
    from navreplay.pipeline.synth.seoul_campus import simulate_drive

    return simulate_drive(
        drive_params(campus, drive),
        list(drive.route),
        seed=seed,
        stream=stream_of(name),
        start_speed_mps=drive.start_speed_mps,
    )


def write_dataset(name: str, synth: SynthSection, out_dir: Path) -> list[Path]:
    """The synth registry's entry point: simulate drive ``name`` of ``synth.car_drives`` and
    write its files into ``out_dir`` (``pipeline.synth.files``); returns the paths written."""
    from navreplay.pipeline.synth.files import write_result

    if name not in synth.car_drives:
        known = ", ".join(sorted(synth.car_drives))
        raise ValueError(f"no drive {name!r} in synth.car_drives (known: {known})")
    drive = synth.car_drives[name]
    result = simulate(name, synth.seoul_campus, drive, seed=synth.seed)
    plain = {"seed": synth.seed, "seoul_campus": synth.seoul_campus, name: drive}
    return write_result(name, result, out_dir, params=plain)
