"""Heading from a magnetometer: tilt-compensated, onto true north with the World Magnetic Model.

Conventions (those of ``pipeline.nav.rotations``): body FRD, navigation NED,
``C_b^n = Rz(yaw) Ry(pitch) Rx(roll)``, yaw clockwise from true north seen from above;
``scipy.spatial.transform.Rotation.from_euler("ZYX", [yaw, pitch, roll])`` is the same
rotation. The field is the canonical ``mag`` table's (gauss, body FRD, the IMU's axes).

Method, over a window where the vehicle stands still:

- roll and pitch from the mean specific force, ``f_b = C_n^b (0, 0, -g)``:
  roll = atan2(-f_y, -f_z), pitch = atan2(f_x, hypot(f_y, f_z)) (or given by the caller);
- each field sample levelled, ``m_h = Ry(pitch) Rx(roll) m_b``; with the horizontal field
  pointing to magnetic north, ``m_h = Rz(-psi_m) (H, 0, Z)``, so the magnetic heading is
  psi_m = atan2(-m_h,y, m_h,x); the true heading adds the declination D (east positive):
  yaw = psi_m + D;
- the heading is the circular mean of the samples' headings.

The 1-sigma is the root sum of squares of the samples' scatter (their circular standard
deviation, not divided by sqrt(n): vibration and interference are correlated over a window),
the tilt error (``TILT_SIGMA_DEG`` of roll/pitch from an unknown accelerometer bias, which
moves the heading by up to tan(inclination) times as much), the WMM's own declination
uncertainty, and a floor for what the log cannot show: uncalibrated hard and soft iron. The
floor comes from comparing the measured field with the WMM's. Its strength and inclination do
not depend on the heading, so the horizontal and vertical components measured must match the
model's; the vector difference ``d`` of the two is a disturbance at least that large, which can
turn the heading by up to asin(d / H). ``d / F`` within ``MATCH_FRACTION``: the calibration
looks right, floor ``max(CALIBRATED_FLOOR_DEG, asin(d / H))``; within ``REFUSE_FRACTION``:
floor ``max(UNCALIBRATED_FLOOR_DEG, asin(d / H))``, said in ``check``; beyond it (or d >= H):
``usable`` is False, the heading is not to be used.

The WMM coefficients are those of ``pygeomag`` (WMM 2010 to 2025, the model of the date);
a date outside every model's five-year span uses the nearest model, said in ``check``.
"""

from __future__ import annotations

import datetime as dt
import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np
import numpy.typing as npt

F64 = npt.NDArray[np.float64]

#: 1 gauss = 1e5 nT (the WMM's unit)
NT_PER_GAUSS = 1.0e5
#: roll/pitch 1-sigma from the accelerometer at rest (an unknown bias of ~0.1 m/s^2)
TILT_SIGMA_DEG = 0.5
#: measured field within this fraction of the WMM's total intensity: calibrated
MATCH_FRACTION = 0.05
#: beyond this fraction the magnetometer is refused (``usable`` False)
REFUSE_FRACTION = 0.25
#: heading floor when the field matches the WMM (residual soft iron, local disturbances)
CALIBRATED_FLOOR_DEG = 3.0
#: heading floor when it does not (uncalibrated hard/soft iron)
UNCALIBRATED_FLOOR_DEG = 8.0
#: fewest finite samples a heading is given from
MIN_SAMPLES = 3

_MODEL_YEARS = (2010, 2015, 2020, 2025)


@dataclass(frozen=True)
class WmmField:
    """The WMM's field at a place and date.

    Attributes:
        model: e.g. ``WMM-2020``.
        declination_rad: east of true north, positive east.
        inclination_rad: below the horizontal, positive down.
        total_gauss, horizontal_gauss, down_gauss: intensities (down: the NED z component).
        declination_sigma_rad: the model's 1-sigma declination uncertainty (NaN if unknown).
        note: set when the date is outside the model's five-year span.
    """

    model: str
    declination_rad: float
    inclination_rad: float
    total_gauss: float
    horizontal_gauss: float
    down_gauss: float
    declination_sigma_rad: float
    note: str = ""


@dataclass(frozen=True)
class MagHeading:
    """A heading from the magnetometer (see the module docstring).

    Attributes:
        t_ns: the window's last sample time (the heading holds for the window).
        t_start_ns: the window's first sample time.
        yaw_rad: true heading of body FRD, (-pi, pi], clockwise from true north.
        sigma_rad: its 1-sigma (scatter, tilt, WMM and calibration floor, root sum square).
        usable: False when the measured field disagrees with the WMM beyond
            ``REFUSE_FRACTION``: the heading is then not to be used (``check`` says why).
        magnetic_yaw_rad: heading from magnetic north.
        declination_rad: the WMM declination added (east positive).
        roll_rad, pitch_rad: the attitude the field was levelled with.
        tilt_source: ``specific force`` or ``given``.
        samples: finite field samples used.
        scatter_rad: circular standard deviation of the samples' headings.
        floor_rad: the calibration floor in ``sigma_rad``.
        field_gauss: mean measured field strength; wmm_field_gauss: the model's.
        inclination_rad: measured inclination (down positive); wmm_inclination_rad: the model's.
        disturbance_gauss: the smallest disturbance that explains the mismatch (vector
            difference of the measured and the model's horizontal and vertical components).
        model: the WMM used.
        check: the calibration check in words (agreement or mismatch, and what was done).
    """

    t_ns: int
    t_start_ns: int
    yaw_rad: float
    sigma_rad: float
    usable: bool
    magnetic_yaw_rad: float
    declination_rad: float
    roll_rad: float
    pitch_rad: float
    tilt_source: str
    samples: int
    scatter_rad: float
    floor_rad: float
    field_gauss: float
    wmm_field_gauss: float
    inclination_rad: float
    wmm_inclination_rad: float
    disturbance_gauss: float
    model: str
    check: str

    def summary(self) -> dict[str, object]:
        """The result in degrees, for reports and logs."""
        return {
            "t_ns": self.t_ns,
            "usable": self.usable,
            "yaw_deg": math.degrees(self.yaw_rad),
            "sigma_deg": math.degrees(self.sigma_rad),
            "magnetic_yaw_deg": math.degrees(self.magnetic_yaw_rad),
            "declination_deg": math.degrees(self.declination_rad),
            "roll_deg": math.degrees(self.roll_rad),
            "pitch_deg": math.degrees(self.pitch_rad),
            "samples": self.samples,
            "scatter_deg": math.degrees(self.scatter_rad),
            "floor_deg": math.degrees(self.floor_rad),
            "field_gauss": self.field_gauss,
            "wmm_field_gauss": self.wmm_field_gauss,
            "inclination_deg": math.degrees(self.inclination_rad),
            "wmm_inclination_deg": math.degrees(self.wmm_inclination_rad),
            "model": self.model,
            "check": self.check,
        }


def decimal_year(when: dt.date | float) -> float:
    """``when`` (a date, a datetime, or already a decimal year) as a decimal year."""
    if isinstance(when, (int, float)):
        return float(when)
    if isinstance(when, dt.datetime):
        start = dt.datetime(when.year, 1, 1, tzinfo=when.tzinfo)
        end = dt.datetime(when.year + 1, 1, 1, tzinfo=when.tzinfo)
        return when.year + (when - start) / (end - start)
    days = (dt.date(when.year + 1, 1, 1) - dt.date(when.year, 1, 1)).days
    return when.year + (when.toordinal() - dt.date(when.year, 1, 1).toordinal()) / days


@lru_cache(maxsize=8)
def _geomag(base_year: int) -> Any:
    from pygeomag import GeoMag

    return GeoMag(base_year=base_year)


def wmm_field(lat_deg: float, lon_deg: float, alt_m: float, when: dt.date | float) -> WmmField:
    """The WMM's field at (lat, lon, height above the WGS-84 ellipsoid) on ``when``."""
    from pygeomag import GeoMagUncertaintyResult

    year = decimal_year(when)
    base = max((y for y in _MODEL_YEARS if y <= year), default=_MODEL_YEARS[0])
    outside = not base <= year < base + 5
    geo = _geomag(base)
    r = geo.calculate(
        glat=float(lat_deg),
        glon=float(lon_deg),
        alt=float(alt_m) / 1000.0,
        time=year,
        allow_date_outside_lifespan=True,
    )
    model = str(geo.model)
    try:
        d_sigma = math.radians(float(GeoMagUncertaintyResult(r).d))
    except ValueError:  # WMM-2010 and dates outside the models carry no error model
        d_sigma = float("nan")
    note = f"{year:.2f} is outside {model}'s span: extrapolated" if outside else ""
    return WmmField(
        model=model,
        declination_rad=math.radians(float(r.d)),
        inclination_rad=math.radians(float(r.i)),
        total_gauss=float(r.f) / NT_PER_GAUSS,
        horizontal_gauss=float(r.h) / NT_PER_GAUSS,
        down_gauss=float(r.z) / NT_PER_GAUSS,
        declination_sigma_rad=d_sigma,
        note=note,
    )


def level(mag_b: F64, roll: float, pitch: float) -> F64:
    """The field rotated onto the local level (yaw-free) frame: ``Ry(pitch) Rx(roll) m_b``;
    rows are samples."""
    cr, sr, cp, sp = math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch)
    c = np.array([[cp, sp * sr, sp * cr], [0.0, cr, -sr], [-sp, cp * sr, cp * cr]])
    return np.asarray(mag_b @ c.T, dtype=np.float64)


def _tilt(f_b: F64) -> tuple[float, float]:
    f = np.asarray(f_b, dtype=np.float64).reshape(-1, 3)
    f = f[np.isfinite(f).all(axis=1)]
    if not len(f):
        return float("nan"), float("nan")
    fx, fy, fz = (float(v) for v in f.mean(axis=0))
    return math.atan2(-fy, -fz), math.atan2(fx, math.hypot(fy, fz))


def mag_heading(
    t_ns: npt.NDArray[np.int64],
    f_b: F64,
    mag_b: F64,
    lat_deg: float,
    lon_deg: float,
    alt_m: float,
    when: dt.date | float,
    *,
    roll_pitch_rad: tuple[float, float] | None = None,
) -> MagHeading | None:
    """The true heading from the magnetometer over a window where the vehicle is still.

    Args:
        t_ns: the field samples' times, shape (n,), on any time base.
        f_b: specific force in body FRD, m/s^2, shape (3,) (the window's mean) or (k, 3)
            (the IMU samples of the window; averaged); unused when ``roll_pitch_rad`` is given.
        mag_b: the field in body FRD (the ``mag`` table), gauss, shape (n, 3); NaN rows are
            skipped.
        lat_deg, lon_deg: the place, WGS-84 degrees; alt_m: height above the ellipsoid, m.
        when: the date (``datetime.date``/``datetime``, UTC) or a decimal year, for the WMM.
        roll_pitch_rad: roll and pitch (rad) to level the field with, instead of the
            specific force (a vehicle that moves, with its attitude from elsewhere).

    Returns:
        The heading and its 1-sigma, with the calibration check (see ``MagHeading``;
        ``usable`` False when the field disagrees with the WMM too much to trust); None when
        there is nothing to compute: fewer than ``MIN_SAMPLES`` finite samples, no finite
        specific force, or a zero horizontal field.

    Raises:
        ValueError: ``t_ns`` and ``mag_b`` of different lengths, or ``mag_b`` not (n, 3).
    """
    t = np.asarray(t_ns, dtype=np.int64).reshape(-1)
    m = np.asarray(mag_b, dtype=np.float64)
    if m.ndim != 2 or m.shape[1] != 3 or len(m) != len(t):
        raise ValueError(f"mag_b must be (n, 3) with n = len(t_ns) = {len(t)}, got shape {m.shape}")
    ok = np.isfinite(m).all(axis=1)
    if int(ok.sum()) < MIN_SAMPLES:
        return None
    t, m = t[ok], m[ok]
    if roll_pitch_rad is not None:
        roll, pitch = (float(a) for a in roll_pitch_rad)
        source = "given"
    else:
        roll, pitch = _tilt(f_b)
        source = "specific force"
    if not (math.isfinite(roll) and math.isfinite(pitch)):
        return None
    mh = level(m, roll, pitch)
    horizontal = np.hypot(mh[:, 0], mh[:, 1])
    if not float(horizontal.mean()) > 0.0:
        return None
    psi = np.arctan2(-mh[:, 1], mh[:, 0])
    c, s = float(np.cos(psi).mean()), float(np.sin(psi).mean())
    psi_m = math.atan2(s, c)
    resultant = min(1.0, math.hypot(c, s))
    scatter = math.sqrt(-2.0 * math.log(resultant)) if resultant > 0.0 else math.pi

    wmm = wmm_field(lat_deg, lon_deg, alt_m, when)
    h_meas = float(horizontal.mean())
    z_meas = float(mh[:, 2].mean())
    field = float(np.linalg.norm(m, axis=1).mean())
    incl = math.atan2(z_meas, h_meas)
    d = math.hypot(h_meas - wmm.horizontal_gauss, z_meas - wmm.down_gauss)
    ratio = d / wmm.total_gauss
    turn = math.asin(d / wmm.horizontal_gauss) if d < wmm.horizontal_gauss else math.pi / 2
    usable = ratio <= REFUSE_FRACTION and d < wmm.horizontal_gauss
    base = CALIBRATED_FLOOR_DEG if ratio <= MATCH_FRACTION else UNCALIBRATED_FLOOR_DEG
    floor = max(math.radians(base), turn)
    tilt = math.radians(TILT_SIGMA_DEG) * abs(math.tan(wmm.inclination_rad))
    d_sigma = wmm.declination_sigma_rad if math.isfinite(wmm.declination_sigma_rad) else 0.0
    sigma = math.sqrt(scatter**2 + tilt**2 + d_sigma**2 + floor**2)

    strength = 100.0 * (field / wmm.total_gauss - 1.0)
    dip = math.degrees(incl - wmm.inclination_rad)
    compared = (
        f"field {field:.3f} G vs {wmm.model} {wmm.total_gauss:.3f} G ({strength:+.1f} %), "
        f"inclination {math.degrees(incl):.1f} vs {math.degrees(wmm.inclination_rad):.1f} deg "
        f"({dip:+.1f} deg); a disturbance of at least {d:.3f} G "
        f"({100.0 * ratio:.1f} % of the field) turns the heading by up to "
        f"{math.degrees(turn):.1f} deg"
    )
    if not usable:
        check = f"refused: the field disagrees with the WMM: {compared}"
    elif ratio <= MATCH_FRACTION:
        check = f"calibration consistent with the WMM: {compared}; floor {base:.0f} deg or more"
    else:
        check = (
            f"the field disagrees with the WMM (uncalibrated hard/soft iron or a magnetic "
            f"environment): {compared}; sigma widened, floor {math.degrees(floor):.1f} deg"
        )
    if wmm.note:
        check += f"; {wmm.note}"
    yaw = math.remainder(psi_m + wmm.declination_rad, 2.0 * math.pi)
    return MagHeading(
        t_ns=int(t[-1]),
        t_start_ns=int(t[0]),
        yaw_rad=yaw,
        sigma_rad=sigma,
        usable=usable,
        magnetic_yaw_rad=psi_m,
        declination_rad=wmm.declination_rad,
        roll_rad=roll,
        pitch_rad=pitch,
        tilt_source=source,
        samples=len(t),
        scatter_rad=scatter,
        floor_rad=floor,
        field_gauss=field,
        wmm_field_gauss=wmm.total_gauss,
        inclination_rad=incl,
        wmm_inclination_rad=wmm.inclination_rad,
        disturbance_gauss=d,
        model=wmm.model,
        check=check,
    )
