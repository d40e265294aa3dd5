"""Dataset descriptors: ``datasets/<id>/dataset.yaml``.

A descriptor says which logs make up a dataset, overrides the automatic choice of topics or
messages where needed, and carries the sensor metadata a log cannot: the IMU noise model,
the IMU mounting rotation, the GNSS antenna lever arm. Ingest copies the sensor metadata into
the dataset's ``meta.json``, where the filters read it.

Every section is optional except ``id``. Paths in ``logs`` are relative to the descriptor's
folder. Example::

    id: seoul_campus_cw
    description: synthesized campus drive (paper 001), clockwise loops first
    logs: [raw/seoul_campus_cw.mcap, raw/seoul_campus_cw.obs, raw/seoul_campus_cw.nav]
    required: [imu, gnss, gnss_obs, truth]
    imu:
      topic: /imu/data
      noise: {accel_noise_mps2_rthz: 0.002, gyro_noise_radps_rthz: 0.0002, ...}
    gnss:
      topic: /gps/fix
      lever_arm_m: [0.5, 0.0, -1.2]
    truth:
      topic: /truth
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import yaml

from navreplay.ingest.errors import ConfigError
from navreplay.ingest.platform import PlatformKind
from navreplay.ingest.schema import TableName
from navreplay.ingest.typed import FieldError, KeyPathError, load_dataclass

_ID_RE = re.compile(r"^[a-z][a-z0-9_]*$")
_DATE_RE = re.compile(r"^(19[89]\d|2\d{3})-(0[1-9]|1[0-2])-(0[1-9]|[12]\d|3[01])$")
_TABLES = tuple(t.value for t in TableName)

Vec3 = tuple[float, float, float]


class DescriptorError(KeyPathError):
    """A key of a dataset descriptor is wrong (raised as ``ConfigError`` to callers)."""


@dataclass(frozen=True)
class ImuNoise:
    """Per-axis continuous-time IMU error model, the filters' process noise.

    Attributes:
        accel_noise_mps2_rthz: accelerometer white noise (velocity random walk), m/s^2/sqrt(Hz).
        gyro_noise_radps_rthz: gyro white noise (angle random walk), rad/s/sqrt(Hz).
        accel_bias_sigma_mps2: initial accelerometer bias uncertainty, 1 sigma, m/s^2.
        gyro_bias_sigma_radps: initial gyro bias uncertainty, 1 sigma, rad/s.
        accel_bias_rw_mps3_rthz: accelerometer bias random walk, m/s^3/sqrt(Hz).
        gyro_bias_rw_radps2_rthz: gyro bias random walk, rad/s^2/sqrt(Hz).
    """

    accel_noise_mps2_rthz: float
    gyro_noise_radps_rthz: float
    accel_bias_sigma_mps2: float
    gyro_bias_sigma_radps: float
    accel_bias_rw_mps3_rthz: float
    gyro_bias_rw_radps2_rthz: float

    def __post_init__(self) -> None:
        for name in self.__dataclass_fields__:
            if getattr(self, name) < 0:
                raise FieldError(name, "must be >= 0")


@dataclass(frozen=True)
class ImuConfig:
    """The ``imu`` section.

    Attributes:
        topic: ROS topic, MAVLink/DataFlash message or ULog topic to read (default: automatic).
        instance: sensor instance for logs with several IMUs (default: the first).
        frame: axis convention of the source; ``flu`` (REP-103) is converted to FRD; the
            magnetometer (``mag`` table) is taken to share it.
        mounting_rpy_deg: roll, pitch, yaw (deg) rotating sensor axes into body FRD, applied
            after the frame conversion; absent: detected from gravity at rest and reported;
            the magnetometer gets the same rotation.
        accel_units: ``g`` scales by 9.80665 (recorded in provenance); ``auto`` checks the
            static magnitude and refuses implausible units.
        gyro_units: ``degps`` scales to rad/s; ``auto`` checks the rate at rest.
        noise: the noise model the filters use (default: the filter's params).
    """

    topic: str | None = None
    instance: int | None = None
    frame: Literal["auto", "frd", "flu"] = "auto"
    mounting_rpy_deg: Vec3 | None = None
    accel_units: Literal["auto", "mps2", "g"] = "auto"
    gyro_units: Literal["auto", "radps", "degps"] = "auto"
    noise: ImuNoise | None = None


@dataclass(frozen=True)
class GnssConfig:
    """The ``gnss`` section: receiver fixes.

    Attributes:
        topic: topic or message to read (default: automatic).
        instance: receiver instance (default: the first).
        lever_arm_m: antenna position relative to the IMU in body FRD, m.
        latlon_units: ``rad`` scales lat/lon to degrees (recorded in provenance); ``deg``
            accepts degrees as they are; ``auto`` refuses values that look like radians.
        velocity_topic: stream with the receiver's velocity, joined to the fixes by time
            (default: automatic, e.g. a TwistWithCovarianceStamped on ``/gps/vel``).
        latency_s: how late the fixes' stamps are against the IMU's, s: the filters apply a
            fix at ``t_ns - latency_s`` (a receiver's output delay the log's clock pairing
            kept). Default: measured at ingest against the onboard estimator where the log
            has one (``ingest.latency``), else none.
    """

    topic: str | None = None
    instance: int | None = None
    lever_arm_m: Vec3 = (0.0, 0.0, 0.0)
    velocity_topic: str | None = None
    latlon_units: Literal["auto", "deg", "rad"] = "auto"
    latency_s: float | None = None

    def __post_init__(self) -> None:
        if self.latency_s is not None and not 0.0 <= self.latency_s <= 2.0:
            raise FieldError("latency_s", f"{self.latency_s} is not within [0, 2] s")


@dataclass(frozen=True)
class StreamConfig:
    """A section naming only where a stream comes from (``gnss_obs``, ``truth`` ...)."""

    topic: str | None = None
    instance: int | None = None


@dataclass(frozen=True)
class VehicleConfig:
    """The ``vehicle`` section: wheel/radar speed, steering angle, yaw rate.

    Attributes:
        topic: topic or message to read (default: automatic).
        wheelbase_m: distance between axles, m (vehicle-model filters).
        steer_ratio: steering-wheel angle / road-wheel angle, when the log has the former.
    """

    topic: str | None = None
    wheelbase_m: float | None = None
    steer_ratio: float | None = None


@dataclass(frozen=True)
class MavlinkConfig:
    """The ``mavlink`` section: how MAVLink tlogs are decoded.

    Attributes:
        dialect: pymavlink dialect module whose definitions (field layout, scalings,
            ``crc_extra``) decode the packets: ``ardupilotmega`` (default, includes
            ``common``), ``common``, ``development``, ...
    """

    dialect: str = "ardupilotmega"

    def __post_init__(self) -> None:
        if not self.dialect.isidentifier():
            raise FieldError("dialect", f"{self.dialect!r} is not a pymavlink dialect name")


@dataclass(frozen=True)
class CsvSource:
    """One CSV/text file mapped onto a canonical table.

    Attributes:
        path: the file, relative to the descriptor's folder.
        table: canonical table it fills.
        time_column: source column with the time.
        time_unit: unit of that column.
        columns: canonical column name -> source column name.
        scale: canonical column name -> factor applied after reading (e.g. 0.0174533 deg->rad).
        delimiter: field separator; ``whitespace`` for runs of blanks.
        comment: lines starting with this are skipped.
        time_base: the clock of ``time_column`` (``ingest.timebase``): ``gps`` (since
            1980-01-06), ``utc`` (POSIX) or ``recorder`` (boot time, unknown epoch); default:
            the dataset's ``time_base`` (``recorder`` when that is ``auto``).
        frame: axis convention of vector columns: ``frd``/``ned`` (canonical) or
            ``flu``/``enu`` (converted at ingest).
        constants: canonical column name -> value for every row, for columns the file lacks
            (e.g. ``fix_type: 3`` for a receiver log that only holds 3-D fixes).
    """

    path: str
    table: str
    time_column: str
    time_unit: Literal["ns", "us", "ms", "s"]
    columns: dict[str, str]
    scale: dict[str, float] = field(default_factory=dict)
    delimiter: str = ","
    comment: str = "#"
    time_base: Literal["gps", "utc", "recorder"] | None = None
    frame: Literal["frd", "flu"] = "frd"
    constants: dict[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.table not in _TABLES:
            raise FieldError("table", f"{self.table!r} is not one of {', '.join(_TABLES)}")


@dataclass(frozen=True)
class DatasetConfig:
    """A whole ``dataset.yaml``.

    Attributes:
        utc_date: UTC date (``YYYY-MM-DD``) of the first record, for logs whose records carry
            only a time of day (NMEA without a valid RMC or ZDA sentence).
        platform: the vehicle kind (``ground``, ``multirotor``, ``fixed_wing``, ``vtol``,
            ``unknown``); overrides what the log says (``ingest.platform``).
    """

    id: str
    description: str = ""
    logs: tuple[str, ...] = ()
    required: tuple[str, ...] = ()
    time_base: Literal["auto", "gps", "utc", "recorder"] = "auto"
    utc_date: str | None = None
    platform: PlatformKind | None = None
    imu: ImuConfig = field(default_factory=ImuConfig)
    gnss: GnssConfig = field(default_factory=GnssConfig)
    gnss_obs: StreamConfig = field(default_factory=StreamConfig)
    vehicle: VehicleConfig = field(default_factory=VehicleConfig)
    truth: StreamConfig = field(default_factory=StreamConfig)
    estimator: StreamConfig = field(default_factory=StreamConfig)
    mag: StreamConfig = field(default_factory=StreamConfig)
    mavlink: MavlinkConfig = field(default_factory=MavlinkConfig)
    csv: tuple[CsvSource, ...] = ()

    def __post_init__(self) -> None:
        if not _ID_RE.match(self.id):
            raise FieldError("id", f"{self.id!r} is not a dataset id (lowercase, digits, _)")
        for i, name in enumerate(self.required):
            if name not in _TABLES:
                raise FieldError(f"required[{i}]", f"{name!r} is not one of {', '.join(_TABLES)}")
        if self.utc_date is not None and not _DATE_RE.match(self.utc_date):
            raise FieldError("utc_date", f"{self.utc_date!r} is not a date YYYY-MM-DD")


def parse_dataset_config(data: object, *, source: str | Path | None = None) -> DatasetConfig:
    """Build a ``DatasetConfig`` from parsed YAML.

    Raises:
        ConfigError: naming the descriptor file and the dotted key path.
    """
    try:
        return load_dataclass(DatasetConfig, data, error=DescriptorError)
    except DescriptorError as err:
        raise ConfigError(f"{err.key_path or '<top level>'}: {err.reason}", path=source) from err


def load_dataset_config(path: str | Path) -> DatasetConfig:
    """Read and check ``dataset.yaml``; raises ``ConfigError`` naming the file and key."""
    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except OSError as err:
        raise ConfigError(f"cannot read dataset descriptor: {err.strerror}", path=path) from err
    except yaml.YAMLError as err:
        raise ConfigError(f"not valid YAML: {err}", path=path) from err
    return parse_dataset_config(data, source=path)


def log_paths(config: DatasetConfig, descriptor: str | Path) -> list[Path]:
    """The descriptor's ``logs`` as paths, resolved against the descriptor's folder."""
    base = Path(descriptor).parent
    return [p if (p := Path(s)).is_absolute() else base / p for s in config.logs]


def input_paths(config: DatasetConfig, descriptor: str | Path) -> list[Path]:
    """Every file the descriptor names: its ``logs``, then the ``csv:`` files not among them."""
    base = Path(descriptor).parent
    paths = log_paths(config, descriptor)
    for src in config.csv:
        p = Path(src.path) if Path(src.path).is_absolute() else base / src.path
        if p not in paths:
            paths.append(p)
    return paths
