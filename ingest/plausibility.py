"""Unit and frame plausibility of the first block of a stream, and the IMU mounting decision.

IMU (catalogue cases 23, 24, 26):

- Rest: the block is cut into 1 s windows; a window is at rest when the norm of the per-axis
  standard deviation of specific force is below ``REST_ACC_STD_MPS2``. Gravity is the mean
  specific force over the rest windows or, when there is none (a vehicle that never stops),
  over the whole block (a land vehicle's mean acceleration over minutes is ~0), which the
  report marks as ``quasi_static``.
- Accelerometer units: |gravity| must lie in 9.81 +- 0.5 m/s^2. About 1.0 means g units:
  E-FATAL (``PlausibilityError``) unless the descriptor says ``accel_units: g``, which scales
  by 9.80665 and is recorded in provenance. Any other magnitude is E-FATAL too.
- Gyro units: at rest the rate (bias, the median over at least ``REST_MIN_WINDOWS`` rest
  windows of each window's median) must stay below ``REST_GYRO_MAX_RADPS`` about the
  horizontal axes: a rotation about gravity leaves the accelerometer unchanged, so a vehicle
  turning while it stands (a hovering copter yawing, a SITL vehicle spinning on the ground)
  looks at rest, and its yaw rate is no evidence of units; without rest the median |rate|
  must stay below ``MOVING_GYRO_MEDIAN_MAX_RADPS``; and no vehicle exceeds ``GYRO_MAX_RADPS``
  (2000 deg/s, the widest full scale of MEMS gyros, plus the 25 % a saturated axis can read
  beyond it: a tumbling copter's MPU6000 reads 35.6 rad/s) for ``PEAK_MIN_SAMPLES`` samples.
  Failing: probable deg/s, E-FATAL unless ``gyro_units: degps`` (scaled to rad/s, recorded)
  or ``radps`` (accepted as is).
- Samples beyond physical limits (``ingest.audit.LIMITS``: a bit flip in a format without
  checksums, a glitch) are left out of every decision, like NaN ones; the audit counts them.
- Mounting: ``mounting_rpy_deg`` from the descriptor, else levelled from gravity when the tilt
  exceeds ``MOUNTING_MIN_TILT_DEG`` (smaller tilts are the vehicle standing on a slope, not a
  mounting; they are reported and left alone).

GNSS (case 24): latitudes outside [-90, 90] or longitudes outside [-180, 180] are E-FATAL;
all valid fixes within [-pi/2, pi/2] x [-pi, pi] (but not at 0, 0) look like radians: E-FATAL
unless ``latlon_units`` says ``deg`` (accepted) or ``rad`` (converted, recorded).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from navreplay.ingest.audit import LIMITS
from navreplay.ingest.config import GnssConfig, ImuConfig
from navreplay.ingest.errors import PlausibilityError
from navreplay.ingest.frames import (
    ACC,
    GYRO,
    dcm_from_rpy_deg,
    level_from_gravity,
    rotate_imu,
    tilt_deg,
)
from navreplay.ingest.schema import FixType

G0 = 9.80665
GRAVITY_TOL_MPS2 = 0.5
REST_ACC_STD_MPS2 = 0.2
REST_GYRO_MAX_RADPS = 0.05
REST_MIN_WINDOWS = 2
#: the accelerometer passes when this share of the rest windows (and at least
#: ``REST_MIN_WINDOWS``) each show |f| = 9.81 +- 0.5 m/s^2, even if steady turns in flight
#: that pass for rest pull the mean away (a short or truncated log); g units never do
REST_FIT_SHARE = 0.25
#: rest windows whose |f| is this close to gravity's are level rest: the gyro bias is taken
#: from them only (a steady banked turn shows |f| > g and a rate)
LEVEL_TOL_MPS2 = 0.2
#: the horizontal rate of the rest windows must agree to within this fraction of it to count
#: as a bias (a bias is one vector; steady turns in flight that pass for rest each differ)
REST_SPREAD_MAX = 0.5
PEAK_MIN_SAMPLES = 3
MOVING_GYRO_MEDIAN_MAX_RADPS = 1.0
GYRO_MAX_RADPS = 1.25 * math.radians(2000.0)
MOUNTING_MIN_TILT_DEG = 10.0
ACC_LIMIT = LIMITS["acc_x_mps2"]
GYRO_LIMIT = LIMITS["gyro_x_radps"]


@dataclass
class ImuDecision:
    """What ingest does to every IMU block, decided on the first one."""

    accel_scale: float = 1.0
    gyro_scale: float = 1.0
    mounting_rpy_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)
    mounting_source: str = "none"
    c_body_sensor: np.ndarray = field(default_factory=lambda: np.eye(3))
    report: dict[str, Any] = field(default_factory=dict)
    provenance: dict[str, str] = field(default_factory=dict)

    def apply(self, columns: dict[str, np.ndarray]) -> None:
        """Scale units and rotate into body FRD, in place (columns already FRD)."""
        if self.accel_scale != 1.0:
            for n in ACC:
                columns[n] = columns[n] * self.accel_scale
        if self.gyro_scale != 1.0:
            for n in GYRO:
                columns[n] = columns[n] * self.gyro_scale
        if self.mounting_source != "none":
            rotate_imu(columns, self.c_body_sensor)


def _windows(t: np.ndarray) -> list[slice]:
    dt = np.diff(t)
    dt = dt[dt > 0]
    per = max(5, round(1e9 / float(np.median(dt)))) if dt.size else len(t)
    return [slice(i, i + per) for i in range(0, len(t) - per + 1, per)]


def decide_imu(
    columns: dict[str, np.ndarray], config: ImuConfig, path: Path, stream: str
) -> ImuDecision:
    """Check units at rest and decide the mounting from the first IMU block (FRD axes).

    Raises:
        PlausibilityError: implausible accelerometer or gyro units without an override.
    """
    d = ImuDecision()
    acc = np.stack([columns[n] for n in ACC], axis=1)
    gyro = np.stack([columns[n] for n in GYRO], axis=1)
    finite = np.isfinite(acc).all(axis=1) & np.isfinite(gyro).all(axis=1)
    nonfinite = int(len(finite) - np.count_nonzero(finite))
    within = (np.abs(acc) <= ACC_LIMIT).all(axis=1) & (np.abs(gyro) <= GYRO_LIMIT).all(axis=1)
    good = finite & within
    acc, gyro, t = acc[good], gyro[good], columns["t_ns"][good]
    if len(t) < 2:
        d.report["checked"] = False
        return d
    if config.accel_units == "g":
        d.accel_scale = G0
        d.provenance["imu_accel_units"] = "g (scaled by 9.80665, from dataset.yaml)"
    if config.gyro_units == "degps":
        d.gyro_scale = math.pi / 180.0
        d.provenance["imu_gyro_units"] = "deg/s (scaled to rad/s, from dataset.yaml)"
    if config.accel_units == "mps2":
        d.provenance["imu_accel_units"] = "m/s^2 (declared in dataset.yaml, check not enforced)"
    if config.gyro_units == "radps":
        d.provenance["imu_gyro_units"] = "rad/s (declared in dataset.yaml, check not enforced)"
    acc, gyro = acc * d.accel_scale, gyro * d.gyro_scale
    wins = _windows(t)
    rest = [w for w in wins if float(np.linalg.norm(acc[w].std(axis=0))) < REST_ACC_STD_MPS2]
    f = np.mean([acc[w].mean(axis=0) for w in rest], axis=0) if rest else acc.mean(axis=0)
    mags = np.array([float(np.linalg.norm(acc[w].mean(axis=0))) for w in rest])
    fits = mags[np.abs(mags - G0) <= GRAVITY_TOL_MPS2]
    ref = float(np.median(fits)) if fits.size else float(np.linalg.norm(f))
    level = [w for w, m in zip(rest, mags, strict=True) if abs(m - ref) <= LEVEL_TOL_MPS2]
    bias, horizontal = _gyro_at_rest(d, gyro, level, f)
    rate = np.linalg.norm(gyro, axis=1)
    d.report.update(
        checked=True,
        block_s=(int(t[-1]) - int(t[0])) * 1e-9,
        rest_windows_1s=len(rest),
        gravity_estimate="rest" if rest else "quasi_static (no rest window: mean over the block)",
        specific_force_sensor_mps2=f.tolist(),
        gravity_magnitude_mps2=float(np.linalg.norm(f)),
        gyro_bias_at_rest_radps=None if bias is None else bias.tolist(),
        gyro_bias_at_rest_horizontal_radps=horizontal,
        gyro_median_radps=float(np.median(rate)),
        gyro_max_radps=float(rate.max()),
        implausible_samples_ignored=int(len(good) - np.count_nonzero(good) - nonfinite),
    )
    if rest and bias is None:
        d.report["gyro_bias_at_rest_radps"] = (
            f"not checked: {len(level)} level rest window(s), fewer than {REST_MIN_WINDOWS}"
        )
    peak = float(np.sort(rate)[-PEAK_MIN_SAMPLES]) if len(rate) >= PEAK_MIN_SAMPLES else 0.0
    d.report["rest_windows_level"] = len(level)
    if fits.size < max(REST_MIN_WINDOWS, REST_FIT_SHARE * len(rest)):
        _check_accel(float(np.linalg.norm(f)), config, path, stream)
    _check_gyro(
        None if bias is None else (bias, horizontal),
        float(np.median(rate)),
        peak,
        config,
        path,
        stream,
        agree=bool(d.report.get("gyro_rest_windows_agree", True)),
    )
    _decide_mounting(d, f, config)
    return d


def _gyro_at_rest(
    d: ImuDecision, gyro: np.ndarray, level: list[slice], f: np.ndarray
) -> tuple[np.ndarray | None, float | None]:
    """The gyro bias over the level rest windows (median of each window's median) and its
    component about horizontal axes; ``gyro_rest_windows_agree`` in the report says whether
    the windows show one bias (rest) or differ (steady motion that passed for rest)."""
    if len(level) < REST_MIN_WINDOWS:
        return None, None
    per_window = np.array([np.median(gyro[w], axis=0) for w in level])
    bias = np.median(per_window, axis=0)
    up = f / max(float(np.linalg.norm(f)), 1e-9)
    flat = per_window - np.outer(per_window @ up, up)
    middle = np.median(flat, axis=0)
    horizontal = float(np.linalg.norm(middle))
    spread = float(np.median(np.linalg.norm(flat - middle, axis=1)))
    d.report["gyro_rest_windows_spread_radps"] = spread
    d.report["gyro_rest_windows_agree"] = spread <= REST_SPREAD_MAX * horizontal
    return bias, horizontal


def _check_accel(g: float, config: ImuConfig, path: Path, stream: str) -> None:
    if abs(g - G0) <= GRAVITY_TOL_MPS2 or config.accel_units == "mps2":
        return
    probable = " - probable g units" if abs(g - 1.0) < 0.1 else ""
    raise PlausibilityError(
        f"static |a| = {g:.2f} is not 9.81 +- {GRAVITY_TOL_MPS2} m/s^2{probable}",
        path=path,
        record=f"stream {stream}",
        hint="set imu.accel_units: g (or mps2 to accept the values) in dataset.yaml",
    )


def _check_gyro(
    rest: tuple[np.ndarray, float | None] | None,
    median: float,
    peak: float,
    config: ImuConfig,
    path: Path,
    stream: str,
    *,
    agree: bool = True,
) -> None:
    """``rest``: the bias at rest and its component about horizontal axes, evidence only when
    the rest windows ``agree``; ``peak``: the ``PEAK_MIN_SAMPLES``-th largest rate."""
    if config.gyro_units != "auto":
        return
    problems = []
    if rest is not None and rest[1] is not None and rest[1] > REST_GYRO_MAX_RADPS and agree:
        problems.append(
            f"rate at rest {float(np.linalg.norm(rest[0])):.3f} rad/s, "
            f"{rest[1]:.3f} rad/s about horizontal axes"
        )
    if rest is None and median > MOVING_GYRO_MEDIAN_MAX_RADPS:
        problems.append(f"median rate {median:.2f} rad/s")
    if peak > GYRO_MAX_RADPS:
        problems.append(f"peak rate {peak:.1f} rad/s")
    if problems:
        raise PlausibilityError(
            f"gyro implausible for rad/s ({'; '.join(problems)}) - probable deg/s",
            path=path,
            record=f"stream {stream}",
            hint="set imu.gyro_units: degps (or radps to accept the values) in dataset.yaml",
        )


def _decide_mounting(d: ImuDecision, f: np.ndarray, config: ImuConfig) -> None:
    tilt = tilt_deg(f)
    d.report["tilt_before_mounting_deg"] = tilt
    if config.mounting_rpy_deg is not None:
        d.mounting_rpy_deg = config.mounting_rpy_deg
        d.mounting_source = "dataset.yaml"
    elif tilt > MOUNTING_MIN_TILT_DEG:
        d.mounting_rpy_deg = level_from_gravity(f)
        d.mounting_source = "detected from gravity (yaw about gravity unobservable, set to 0)"
    else:
        d.report["mounting"] = {
            "source": "none",
            "note": f"tilt {tilt:.1f} deg <= {MOUNTING_MIN_TILT_DEG} deg: taken as the "
            "vehicle's attitude at rest, not corrected",
        }
        return
    d.c_body_sensor = dcm_from_rpy_deg(d.mounting_rpy_deg)
    after = d.c_body_sensor @ f
    d.report["mounting"] = {
        "source": d.mounting_source,
        "rpy_deg": list(d.mounting_rpy_deg),
        "specific_force_body_mps2": after.tolist(),
        "tilt_after_deg": tilt_deg(after),
    }
    d.provenance["imu_mounting_rpy_deg"] = ",".join(f"{a:.4f}" for a in d.mounting_rpy_deg)
    d.provenance["imu_mounting_source"] = d.mounting_source


@dataclass
class GnssDecision:
    latlon_scale: float = 1.0
    report: dict[str, Any] = field(default_factory=dict)
    provenance: dict[str, str] = field(default_factory=dict)

    def apply(self, columns: dict[str, np.ndarray]) -> None:
        if self.latlon_scale != 1.0:
            for n in ("lat_deg", "lon_deg"):
                columns[n] = columns[n] * self.latlon_scale


def decide_gnss(
    columns: dict[str, np.ndarray], config: GnssConfig, path: Path, stream: str
) -> GnssDecision:
    """Range checks of lat/lon on the first block; raises ``PlausibilityError``."""
    d = GnssDecision()
    if config.latlon_units == "rad":
        d.latlon_scale = 180.0 / math.pi
        d.provenance["gnss_latlon_units"] = "rad (scaled to deg, from dataset.yaml)"
    elif config.latlon_units == "deg":
        d.provenance["gnss_latlon_units"] = "deg (declared in dataset.yaml, check not enforced)"
    lat = columns["lat_deg"] * d.latlon_scale
    lon = columns["lon_deg"] * d.latlon_scale
    fix = columns.get("fix_type")
    ok = np.isfinite(lat) & np.isfinite(lon)
    if fix is not None:
        ok &= fix >= FixType.FIX_2D
    lat, lon = lat[ok], lon[ok]
    d.report = {"valid_fixes_checked": len(lat)}
    if not len(lat):
        return d
    d.report.update(lat_range_deg=[float(lat.min()), float(lat.max())])
    d.report.update(lon_range_deg=[float(lon.min()), float(lon.max())])
    if np.abs(lat).max() > 90.0 or np.abs(lon).max() > 180.0:
        raise PlausibilityError(
            f"latitude/longitude out of range (lat {lat.min():.4f}..{lat.max():.4f}, "
            f"lon {lon.min():.4f}..{lon.max():.4f})",
            path=path,
            record=f"stream {stream}",
            hint="the columns are not degrees; map or scale them in dataset.yaml",
        )
    radians_like = np.abs(lat).max() <= math.pi / 2 and np.abs(lon).max() <= math.pi
    null_island = np.abs(lat).max() < 1e-6 and np.abs(lon).max() < 1e-6
    if radians_like and not null_island and config.latlon_units == "auto":
        raise PlausibilityError(
            f"every fix lies within lat +-pi/2, lon +-pi ({lat.min():.5f}..{lat.max():.5f}, "
            f"{lon.min():.5f}..{lon.max():.5f}) - probable radians",
            path=path,
            record=f"stream {stream}",
            hint="set gnss.latlon_units: rad (or deg if the position really is near 0 N 0 E)",
        )
    return d
