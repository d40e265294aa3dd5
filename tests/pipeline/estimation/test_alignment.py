"""Initialization and coarse alignment: heading from GNSS velocity, level from the accelerometer."""

from __future__ import annotations

import math

import numpy as np
import pyarrow as pa
import pytest

from navreplay.ingest.meta import SensorMeta
from navreplay.pipeline.estimation.config import FiltersParams
from navreplay.pipeline.estimation.ins import inputs as inp
from navreplay.pipeline.estimation.ins.alignment import align
from navreplay.pipeline.estimation.ins.models import ins
from navreplay.pipeline.estimation.ins.replay import run_filter
from navreplay.pipeline.synth import car_drives
from navreplay.pipeline.synth.car_drives import CarDriveParams
from navreplay.pipeline.synth.trajectory import Leg
from tests.pipeline.estimation.conftest import Tables, seoul, t0_ns, truth_state
from tests.pipeline.scenarios.drives import params as drive_params


def aligned(
    tables: Tables, sensors: SensorMeta, filters: FiltersParams, with_fixes: bool
) -> tuple[np.ndarray, np.ndarray, str, float]:
    p = filters.tc_ekf
    imu = inp.prepare_imu(tables["imu"], p.step)
    fixes = inp.prepare_fixes(tables["gnss"], p.gnss) if with_fixes else None
    obs = inp.prepare_obs(tables["gnss_obs"], p.gnss)
    assert sensors.imu_noise is not None
    lever = np.array(sensors.lever_arm_m)
    al = align(imu, imu.segments[0], fixes, obs, p.init, sensors.imu_noise, lever, ins.N_TIGHT)
    assert al is not None
    truth = tables["truth"]
    k = int(np.searchsorted(truth.column("t_ns").to_numpy(), al.t_ns))
    err = ins.difference(truth_state(truth, k), al.x0, ins.N_TIGHT)
    return err, np.sqrt(np.diag(al.P0)), al.method, (al.t_ns - t0_ns(tables)) * 1e-9


def test_alignment_from_fixes_is_within_its_initial_covariance(
    filters: FiltersParams, drive60: tuple[Tables, SensorMeta]
) -> None:
    err, sig, method, t_s = aligned(*drive60, filters, with_fixes=True)
    assert method == "gnss_velocity+static_gyro_bias"  # 10 s at rest before the start
    assert 10.0 < t_s < 16.0  # the first fix at 2 m/s after moving off at 10 s
    nav = slice(0, ins.E_BG + 3)
    assert np.all(np.abs(err[nav]) <= 3.0 * sig[nav])
    assert np.degrees(np.abs(err[ins.E_ATT : ins.E_ATT + 3])).max() < 2.0
    # the static window estimates the gyro bias far better than its prior (5e-4 rad/s)
    assert np.abs(err[ins.E_BG : ins.E_BG + 3]).max() < 1e-4


def test_without_fixes_the_pseudoranges_give_position_velocity_and_clock(
    filters: FiltersParams, drive60: tuple[Tables, SensorMeta]
) -> None:
    err, sig, _, _ = aligned(*drive60, filters, with_fixes=False)
    assert np.all(np.abs(err) <= 3.0 * sig)
    assert np.abs(err[ins.E_POS : ins.E_POS + 3]).max() < 10.0  # single-point solution
    assert abs(err[ins.E_CB]) < 10.0  # clock bias from the pseudorange residuals
    tables, sensors = drive60
    r = run_filter(dict(tables, gnss=tables["gnss"].slice(0, 0)), sensors, "tc_ukf",
                   filters.tc_ukf)  # fmt: skip
    assert r.status == "ok"
    assert r.t_ns.size > 500


def test_a_vehicle_that_never_moves_is_not_aligned(
    filters: FiltersParams, drive60: tuple[Tables, SensorMeta]
) -> None:
    tables, sensors = drive60
    t0 = t0_ns(tables)

    def first_9_s(t: pa.Table) -> pa.Table:
        return t.filter(pa.array(t.column("t_ns").to_numpy() < t0 + 9_000_000_000))

    still = {k: first_9_s(t) for k, t in tables.items()}
    r = run_filter(still, sensors, "lc_ekf", filters.lc_ekf)
    assert r.t_ns.size == 0
    assert [e.kind for e in r.events] == ["no_alignment"]
    # never "ok" with nothing estimated: the status and its reason say why
    assert r.status == "not_aligned"
    assert r.failure is not None
    assert "never aligned" in r.failure


def _without_receiver_velocity(tables: Tables) -> Tables:
    """The fixes as a receiver that reports no velocity gives them (alignment then differences
    neighbouring fixes)."""
    g = tables["gnss"]
    for c in ("vel_n_mps", "vel_e_mps", "vel_d_mps", "speed_acc_mps"):
        if c in g.column_names:
            g = g.set_column(g.column_names.index(c), c, pa.nulls(g.num_rows, pa.float64()))
    return dict(tables, gnss=g)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_no_heading_from_noise_at_standstill(filters: FiltersParams, seed: int) -> None:
    """60 s at rest with white 1.5 m fixes at 1 Hz and no receiver velocity: the speed
    differenced from two fixes is ~2 m/s of noise, which once gave a random heading with a
    tight sigma (seed 2: tightly coupled runs 2.6 km off and 'ok'). The filter starts within
    a few seconds of the motion instead, on a heading within 3 degrees."""
    tables, sensors = seoul(180.0, seed, stationary_s=60.0, white_fixes=True)
    tables = _without_receiver_velocity(tables)
    p = filters.lc_ekf
    imu = inp.prepare_imu(tables["imu"], p.step)
    fixes = inp.prepare_fixes(tables["gnss"], p.gnss)
    assert sensors.imu_noise is not None
    lever = np.array(sensors.lever_arm_m)
    al = align(imu, imu.segments[0], fixes, None, p.init, sensors.imu_noise, lever, ins.N_LOOSE)
    assert al is not None
    t_s = (al.t_ns - t0_ns(tables)) * 1e-9
    assert 60.0 < t_s < 67.0  # moving off at 60 s (1.5 m/s^2): past 5 sigma of ~1 m/s by ~64 s
    truth = tables["truth"]
    k = int(np.searchsorted(truth.column("t_ns").to_numpy(), al.t_ns))
    err = ins.difference(truth_state(truth, k), al.x0, ins.N_LOOSE)
    yaw_err, yaw_sigma = abs(err[ins.E_ATT + 2]), math.sqrt(al.P0[ins.E_ATT + 2, ins.E_ATT + 2])
    assert yaw_err < 3.0 * yaw_sigma  # ~11 deg 1-sigma from 1 m/s of speed noise at ~5 m/s
    assert yaw_sigma > p.init.yaw_sigma_rad  # wider than a heading from a receiver velocity
    r = run_filter(tables, sensors, "lc_ekf", p)
    assert r.status == "ok"
    assert r.alignments[0].t_ns == al.t_ns
    final = ins.difference(truth_state(truth, truth.num_rows - 1), r.x[-1], ins.N_LOOSE)
    assert math.degrees(abs(final[ins.E_ATT + 2])) < 3.0  # after 2 minutes of motion


@pytest.mark.parametrize("seed", [1, 2])
def test_a_vehicle_too_slow_for_a_course_starts_from_distant_fixes(
    filters: FiltersParams, seed: int
) -> None:
    """A robot at 1 m/s whose receiver gives no velocity (the Husky of ../shared/data):
    neighbouring fixes difference to more noise than speed, and its accelerations are too
    gentle for a heading from motion. It starts from the course of fixes differenced over a
    long enough baseline, within 3 sigma of the truth (before, it never aligned)."""
    slow = CarDriveParams(
        duration_s=240.0,
        stationary_s=10.0,
        start_speed_mps=0.0,
        yaw_deg=40.0,
        route=(
            Leg("straight", speed_mps=1.0, duration_s=60.0),
            Leg("turn", speed_mps=1.0, angle_deg=90.0, radius_m=8.0),
            Leg("straight", speed_mps=1.0, duration_s=60.0),
            Leg("turn", speed_mps=1.0, angle_deg=-120.0, radius_m=8.0),
            Leg("straight", speed_mps=1.0, duration_s=60.0),
        ),
    )
    result = car_drives.simulate("slow_robot", drive_params().synth.seoul_campus, slow, seed=seed)
    tables = _without_receiver_velocity(dict(result.tables))
    p = filters.lc_ekf
    imu = inp.prepare_imu(tables["imu"], p.step)
    fixes = inp.prepare_fixes(tables["gnss"], p.gnss)
    assert result.sensors.imu_noise is not None
    lever = np.array(result.sensors.lever_arm_m)
    al = align(imu, imu.segments[0], fixes, None, p.init, result.sensors.imu_noise, lever,
               ins.N_LOOSE)  # fmt: skip
    assert al is not None
    assert al.method.startswith("slow_course")
    truth = tables["truth"]
    k = int(np.searchsorted(truth.column("t_ns").to_numpy(), al.t_ns))
    err = ins.difference(truth_state(truth, k), al.x0, ins.N_LOOSE)
    vel_sigma = np.sqrt(np.diag(al.P0))[ins.E_VEL : ins.E_VEL + 3]
    assert np.all(np.abs(err[ins.E_VEL : ins.E_VEL + 3]) < 3.0 * vel_sigma)
    yaw_sigma = math.sqrt(al.P0[ins.E_ATT + 2, ins.E_ATT + 2])
    assert abs(err[ins.E_ATT + 2]) < 3.0 * yaw_sigma
    assert yaw_sigma <= p.init.motion_yaw_sigma_max_rad + 1e-9
    r = run_filter(tables, result.sensors, "lc_ekf", p)
    assert r.status == "ok"
    final = ins.difference(truth_state(truth, truth.num_rows - 1), r.x[-1], ins.N_LOOSE)
    # at 1 m/s with fixes alone (variance x60 for their 30 s correlation) the yaw is weakly
    # observed: seeds 1-3 end 12.0, 4.1 and 6.5 deg off at a 2.8-3.4 deg sigma (seed 1 is
    # overconfident: the loosely coupled NEES gap of issue 22)
    assert math.degrees(abs(final[ins.E_ATT + 2])) < 15.0
