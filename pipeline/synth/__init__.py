"""Synthesized datasets with exact truth, written as the log files users' own tools open.

``DATASETS`` maps each synthesized dataset id to the module that makes it; such a module has
``write_dataset(name, synth_params, out_dir) -> list[Path]`` (the files it wrote). A
synthesizer's pure entry point returns a ``SynthResult``: the canonical tables (validated) and
the sensor metadata that matches what was simulated.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

if TYPE_CHECKING:
    import pyarrow as pa

    from navreplay.ingest.gnss.ephemeris import Ephemeris
    from navreplay.ingest.meta import SensorMeta
    from navreplay.pipeline.synth.car import CarSpeedRampParams
    from navreplay.pipeline.synth.car_drives import CarDriveParams
    from navreplay.pipeline.synth.fwekf import FwekfReferenceParams
    from navreplay.pipeline.synth.multirotor_params import MultirotorFlightParams
    from navreplay.pipeline.synth.seoul_params import SeoulCampusParams
    from navreplay.pipeline.synth.tractor import TractorStraightParams

# dataset id -> module with write_dataset(name, synth_params, out_dir)
DATASETS: dict[str, str] = {
    "seoul_campus_cw": "navreplay.pipeline.synth.seoul_campus",
    "seoul_campus_ccw": "navreplay.pipeline.synth.seoul_campus",
    "tractor_straight": "navreplay.pipeline.synth.tractor_log",
    "fwekf_reference": "navreplay.pipeline.synth.fwekf",
    "fwekf_reference_noise_free": "navreplay.pipeline.synth.fwekf",
    "car_speed_ramp": "navreplay.pipeline.synth.car",
    "multirotor_flight": "navreplay.pipeline.synth.multirotor",
    "bench_static": "navreplay.pipeline.synth.multirotor",
    "car_rolling_start": "navreplay.pipeline.synth.car_drives",
    "car_parking_reverse": "navreplay.pipeline.synth.car_drives",
    "car_stop_and_go": "navreplay.pipeline.synth.car_drives",
}


@dataclass(frozen=True)
class SynthResult:
    """What a synthesizer produced.

    Attributes:
        tables: canonical tables by name (``imu``, ``gnss``, ``gnss_obs``, ``truth`` ...), each
            validated against ``ingest.schema``; t_ns on ``time_base``.
        sensors: sensor metadata matching the simulation (IMU noise model, lever arm).
        ephemeris: the broadcast ephemerides the satellites used, if any.
        time_base: the clock of ``t_ns`` (``gps``: ns since 1980-01-06, no leap seconds;
            ``utc``: UNIX time, as the MAVLink and CSV datasets use).
    """

    tables: Mapping[str, pa.Table]
    sensors: SensorMeta
    ephemeris: Ephemeris | None = None
    time_base: str = "gps"


class SynthSection(Protocol):
    """What the synthesizers' ``write_dataset`` read of ``params.synth``
    (``pipeline.params.SynthParams``): the seed and each dataset's section."""

    @property
    def seed(self) -> int: ...

    @property
    def seoul_campus(self) -> SeoulCampusParams: ...

    @property
    def tractor_straight(self) -> TractorStraightParams: ...

    @property
    def fwekf_reference(self) -> FwekfReferenceParams: ...

    @property
    def car_speed_ramp(self) -> CarSpeedRampParams: ...

    @property
    def multirotor_flight(self) -> MultirotorFlightParams: ...

    @property
    def car_drives(self) -> Mapping[str, CarDriveParams]: ...
