"""Heading from motion: an IMU whose x axis is not along the course (a multirotor flying
sideways; here a seoul_campus drive with the IMU turned about its z axis)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pyarrow as pa
import pytest
from scipy.spatial.transform import Rotation

from navreplay.ingest.meta import SensorMeta
from navreplay.ingest.platform import Platform
from navreplay.pipeline.estimation.config import FiltersParams
from navreplay.pipeline.estimation.ins import inputs as inp
from navreplay.pipeline.estimation.ins.alignment import align
from navreplay.pipeline.estimation.ins.models import ins
from navreplay.pipeline.estimation.ins.replay import run_filter
from tests.pipeline.estimation.conftest import Tables, seoul, t0_ns


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
    first fix, within 3 degrees and within 3 of its own sigma."""
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
    # the course would have started it angle_deg off
    course = align(imu, imu.segments[0], fixes, None, p.init, sensors.imu_noise, lever,
                   ins.N_LOOSE)  # fmt: skip
    assert course is not None
    off = _yaw_error_deg(tables["truth"], course.t_ns, float(course.summary()["yaw_rad"]))  # type: ignore[arg-type]
    assert abs(math.remainder(math.radians(off + angle_deg), 2 * math.pi)) < math.radians(5)


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
