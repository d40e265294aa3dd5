"""Heading from motion: an IMU whose x axis is not along the course (a multirotor flying
sideways; here a seoul_campus drive with the IMU turned about its z axis)."""

from __future__ import annotations

import datetime as dt
import math
from dataclasses import replace

import numpy as np
import pyarrow as pa
import pytest
from scipy.spatial.transform import Rotation

from navreplay.ingest.meta import SensorMeta
from navreplay.ingest.platform import Platform
from navreplay.ingest.timebase import gps_to_utc_ns
from navreplay.pipeline.estimation.config import FiltersParams
from navreplay.pipeline.estimation.ins import inputs as inp
from navreplay.pipeline.estimation.ins.alignment import Alignment, align
from navreplay.pipeline.estimation.ins.magheading import wmm_field
from navreplay.pipeline.estimation.ins.models import ins
from navreplay.pipeline.estimation.ins.replay import run_filter
from navreplay.pipeline.params import load_params
from navreplay.pipeline.synth import car_drives
from tests.pipeline.estimation.conftest import REPO, Tables, seoul, t0_ns


def turned(tables: Tables, sensors: SensorMeta, angle_deg: float) -> tuple[Tables, SensorMeta]:
    """The same drive with the IMU turned by ``angle_deg`` about its z axis (its x axis
    ``angle_deg`` right of the vehicle's): readings, lever arm and truth attitude follow."""
    r = Rotation.from_euler("z", angle_deg, degrees=True)
    imu = tables["imu"]
    cols = {c: imu.column(c).to_numpy() for c in imu.column_names}
    for kind in ("acc", "gyro"):
        names = [n for n in imu.column_names if n.startswith(f"{kind}_")]
        v = r.inv().apply(np.column_stack([cols[n] for n in names]))
        for j, n in enumerate(names):
            cols[n] = v[:, j]
    truth = tables["truth"]
    rpy = np.column_stack([truth.column(c).to_numpy() for c in ("yaw_rad", "pitch_rad",
                                                                "roll_rad")])  # fmt: skip
    ypr = (Rotation.from_euler("ZYX", rpy) * r).as_euler("ZYX")
    for j, c in enumerate(("yaw_rad", "pitch_rad", "roll_rad")):
        truth = truth.set_column(truth.column_names.index(c), c, pa.array(ypr[:, j]))
    lever = tuple(float(x) for x in r.inv().apply(np.array(sensors.lever_arm_m)))
    multirotor = Platform("multirotor", "test")
    return (
        dict(tables, imu=pa.table(cols), truth=truth),
        replace(sensors, lever_arm_m=lever, platform=multirotor),  # type: ignore[arg-type]
    )


def _yaw_error_deg(truth: pa.Table, t_ns: int, yaw: float) -> float:
    t = truth.column("t_ns").to_numpy()
    k = int(np.searchsorted(t, t_ns))
    return math.degrees(math.remainder(yaw - truth.column("yaw_rad")[k].as_py(), 2 * math.pi))


@pytest.mark.parametrize(("seed", "angle_deg"), [(1, 90.0), (2, -135.0), (3, 180.0)])
def test_heading_from_motion_when_the_course_is_not_the_heading(
    filters: FiltersParams, seed: int, angle_deg: float
) -> None:
    """At rest for 20 s, then driving: the heading from the course would be ``angle_deg`` off;
    the heading from motion, smoothed back over the standstill, starts the filter at the
    first fix, within 3 degrees and within 3 of its own sigma; and where the course does start
    the filter (the platform taken for a ground vehicle), the heading from motion catches it."""
    tables, sensors = turned(*seoul(120.0, seed, stationary_s=20.0), angle_deg)
    p = filters.lc_ekf
    imu = inp.prepare_imu(tables["imu"], p.step)
    fixes = inp.prepare_fixes(tables["gnss"], p.gnss)
    assert sensors.imu_noise is not None
    lever = np.array(sensors.lever_arm_m)
    al = align(imu, imu.segments[0], fixes, None, p.init, sensors.imu_noise, lever, ins.N_LOOSE,
               course_is_heading=False)  # fmt: skip
    assert al is not None
    assert al.method.startswith("motion_heading")
    assert (al.t_ns - t0_ns(tables)) * 1e-9 <= 1.0  # at rest (the first fix with IMU around it)
    assert al.method == "motion_heading+static_gyro_bias"  # the rest that follows the start
    err = _yaw_error_deg(tables["truth"], al.t_ns, float(al.summary()["yaw_rad"]))  # type: ignore[arg-type]
    sigma = math.degrees(math.sqrt(al.P0[ins.E_ATT + 2, ins.E_ATT + 2]))
    assert abs(err) < 3.0
    assert abs(err) < 3.0 * sigma
    # taken for a ground vehicle, the course would start it angle_deg off: the heading from
    # motion, trusted at the course start, overrules it (180 deg: as a car that reverses)
    course = align(imu, imu.segments[0], fixes, None, p.init, sensors.imu_noise, lever,
                   ins.N_LOOSE)  # fmt: skip
    assert course is not None
    off = _yaw_error_deg(tables["truth"], course.t_ns, float(course.summary()["yaw_rad"]))  # type: ignore[arg-type]
    assert abs(off) < 5.0
    sigma = math.degrees(math.sqrt(course.P0[ins.E_ATT + 2, ins.E_ATT + 2]))
    assert abs(off) < 3.0 * sigma


def test_a_multirotor_run_takes_its_heading_from_motion(filters: FiltersParams) -> None:
    """The whole loosely coupled run on the turned IMU of a multirotor platform: ok, started
    at rest, the heading within 2 degrees at the end."""
    tables, sensors = turned(*seoul(120.0, 4, stationary_s=20.0, white_fixes=True), 90.0)
    r = run_filter(tables, sensors, "lc_ekf", filters.lc_ekf)
    assert r.status == "ok"
    assert r.alignments[0].method.startswith("motion_heading")
    yaw = math.atan2(
        2 * (r.x[-1, ins.X_Q] * r.x[-1, ins.X_Q + 3] + r.x[-1, ins.X_Q + 1] * r.x[-1, ins.X_Q + 2]),
        1 - 2 * (r.x[-1, ins.X_Q + 2] ** 2 + r.x[-1, ins.X_Q + 3] ** 2),
    )
    assert abs(_yaw_error_deg(tables["truth"], int(r.t_ns[-1]), yaw)) < 2.0


def test_no_heading_from_motion_without_motion(filters: FiltersParams) -> None:
    """20 s at rest on a multirotor: no heading (the sigma never shrinks), not_aligned, and the
    reason says what a heading from motion needs."""
    tables, sensors = turned(*seoul(120.0, 5, stationary_s=30.0), 90.0)
    t_end = t0_ns(tables) + 20_000_000_000
    still = {k: t.filter(pa.array(t.column("t_ns").to_numpy() < t_end)) for k, t in tables.items()}
    r = run_filter(still, sensors, "lc_ekf", filters.lc_ekf)
    assert r.status == "not_aligned"
    assert r.failure is not None
    assert "heading from motion" in r.failure
    assert "course of this platform is not its heading" in r.failure


def with_compass(tables: Tables, mounting_deg: float = 0.0) -> Tables:
    """A magnetometer on the IMU's axes (or turned ``mounting_deg`` about z from them) reading
    the WMM field of the place and date through the truth attitude, 0.002 G of noise."""
    truth = tables["truth"]
    t = truth.column("t_ns").to_numpy()
    lat = truth.column("lat_deg")[0].as_py()
    lon = truth.column("lon_deg")[0].as_py()
    when = dt.datetime.fromtimestamp(int(gps_to_utc_ns(t[:1])[0]) * 1e-9, tz=dt.UTC)
    wmm = wmm_field(lat, lon, truth.column("alt_m")[0].as_py(), when)
    d = wmm.declination_rad
    m_n = np.array([wmm.horizontal_gauss * math.cos(d), wmm.horizontal_gauss * math.sin(d),
                    wmm.down_gauss])  # fmt: skip
    ypr = np.column_stack([truth.column(c).to_numpy() for c in ("yaw_rad", "pitch_rad",
                                                                "roll_rad")])  # fmt: skip
    body = Rotation.from_euler("ZYX", ypr) * Rotation.from_euler("z", mounting_deg, degrees=True)
    m_b = body.inv().apply(m_n)
    m_b += np.random.default_rng(0).normal(0.0, 0.002, m_b.shape)
    mag = pa.table({"t_ns": t, **{f"mag_{a}_gauss": m_b[:, j] for j, a in enumerate("xyz")}})
    return dict(tables, mag=mag)


def test_a_compass_starts_the_filter_at_rest_and_joins_the_heading_from_motion(
    filters: FiltersParams, caplog: pytest.LogCaptureFixture
) -> None:
    """A multirotor with a calibrated compass: the filter starts at the first fix, the compass
    heading and the one from motion combined (a tighter sigma than either). A compass mounted
    30 deg off the IMU's axes (its field passes the calibration check: strength and inclination
    do not depend on the heading) disagrees with the heading from motion by far more than their
    sigmas: the tighter one is used, and the disagreement said."""
    tables, sensors = turned(*seoul(120.0, 6, stationary_s=20.0), 90.0)
    p = filters.lc_ekf
    imu = inp.prepare_imu(tables["imu"], p.step)
    fixes = inp.prepare_fixes(tables["gnss"], p.gnss)
    assert sensors.imu_noise is not None
    lever = np.array(sensors.lever_arm_m)

    def start(t: Tables) -> Alignment:
        mag = inp.prepare_mag(t["mag"])
        al = align(imu, imu.segments[0], fixes, None, p.init, sensors.imu_noise, lever,  # type: ignore[arg-type]
                   ins.N_LOOSE, course_is_heading=False, mag=mag)  # fmt: skip
        assert al is not None
        return al

    al = start(with_compass(tables))
    assert al.method == "motion_heading+magnetometer+static_gyro_bias"
    assert (al.t_ns - t0_ns(tables)) * 1e-9 <= 1.0
    err = _yaw_error_deg(tables["truth"], al.t_ns, float(al.summary()["yaw_rad"]))  # type: ignore[arg-type]
    sigma = math.degrees(math.sqrt(al.P0[ins.E_ATT + 2, ins.E_ATT + 2]))
    assert abs(err) < 3.0 * sigma
    assert sigma < 3.0  # the compass's floor alone is 3 deg
    bad = start(with_compass(tables, mounting_deg=30.0))
    assert bad.method == "motion_heading+static_gyro_bias"
    assert "disagree" in caplog.text
    err = _yaw_error_deg(tables["truth"], bad.t_ns, float(bad.summary()["yaw_rad"]))  # type: ignore[arg-type]
    assert abs(err) < 3.0


def test_no_start_inside_a_gap_of_the_imu(filters: FiltersParams) -> None:
    """A 2 s gap in the IMU (shorter than a segment break) over the first fixes: the filter
    starts at the first fix with IMU samples around it, its state finite (an ArduCopter 3.3
    log ended in an indefinite covariance when the start fell in such a gap)."""
    tables, sensors = turned(*seoul(120.0, 7, stationary_s=20.0), 90.0)
    tables = with_compass(tables)
    t0 = t0_ns(tables)
    imu = tables["imu"]
    t = imu.column("t_ns").to_numpy()
    keep = (t < t0 + 500_000_000) | (t > t0 + 2_500_000_000)  # over the fixes at 1 and 2 s
    tables = dict(tables, imu=imu.filter(pa.array(keep)))
    r = run_filter(tables, sensors, "lc_ekf", filters.lc_ekf)
    assert r.status == "ok"
    al = r.alignments[0]
    assert (al.t_ns - t0) * 1e-9 == pytest.approx(3.0)
    assert "magnetometer" in al.method
    assert np.isfinite(al.x0).all()
    assert np.isfinite(al.P0).all()


def test_a_car_backing_out_fast_starts_facing_forwards(filters: FiltersParams) -> None:
    """A car that reverses out of its bay at 3 m/s (over align_speed_mps) reaches a course
    start while backing: the heading from motion says so, and the filter starts at the course
    + 180 deg, within 3 deg of the truth (not 180 deg off), and the run is ok."""
    params = load_params(REPO / "params.yaml")
    drive = params.synth.car_drives["car_parking_reverse"]
    legs = list(drive.route)
    legs[0] = replace(legs[0], speed_mps=-3.0, radius_m=12.0)
    drive = replace(drive, route=tuple(legs), duration_s=90.0)
    result = car_drives.simulate("car_parking_reverse", params.synth.seoul_campus, drive, seed=5)
    tables, sensors = dict(result.tables), result.sensors
    r = run_filter(tables, sensors, "lc_ekf", filters.lc_ekf)
    assert r.status == "ok"
    al = r.alignments[0]
    assert al.method.startswith("gnss_velocity")
    truth = tables["truth"]
    k = int(np.searchsorted(truth.column("t_ns").to_numpy(), al.t_ns))
    assert (
        truth.column("vel_n_mps")[k].as_py() ** 2 + truth.column("vel_e_mps")[k].as_py() ** 2 > 4.0
    )
    assert abs(_yaw_error_deg(truth, al.t_ns, float(al.summary()["yaw_rad"]))) < 3.0  # type: ignore[arg-type]
