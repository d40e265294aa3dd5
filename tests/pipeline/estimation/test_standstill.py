"""Standstill detection and the zero-velocity / zero-angular-rate updates (issue 21)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pyarrow as pa
import pytest

from navreplay.ingest.meta import SensorMeta
from navreplay.pipeline.estimation.config import FiltersParams
from navreplay.pipeline.estimation.core.contract import Backend
from navreplay.pipeline.estimation.ins import inputs as inp
from navreplay.pipeline.estimation.ins import standstill
from navreplay.pipeline.estimation.ins.config import InsFilterParams
from navreplay.pipeline.estimation.ins.models import ins
from navreplay.pipeline.estimation.ins.models import measurement as me
from navreplay.pipeline.estimation.ins.replay import RunResult, run_filter
from tests.pipeline.estimation.conftest import (
    ALL_FILTERS,
    Tables,
    assert_backends_agree,
    drawn_start,
    seoul,
    t0_ns,
)

REST_S = 40.0


def _speed(truth: pa.Table, t_ns: np.ndarray) -> np.ndarray:
    tt = truth.column("t_ns").to_numpy()
    v = np.hypot(truth.column("vel_n_mps").to_numpy(), truth.column("vel_e_mps").to_numpy())
    speed: np.ndarray = np.interp(t_ns, tt, v)
    return speed


def _detect(
    tables: Tables, sensors: SensorMeta, p: InsFilterParams, *, gnss: bool = True
) -> np.ndarray:
    imu = inp.prepare_imu(tables["imu"], p.step)
    fixes = inp.prepare_fixes(tables["gnss"], p.gnss) if gnss else None
    assert sensors.imu_noise is not None
    return standstill.detect(imu, sensors.imu_noise, fixes, p.standstill, p.init, 0.65, 60.0)


def test_the_rest_before_the_drive_is_found_and_nothing_while_driving(
    filters: FiltersParams,
) -> None:
    """One interval, from the start to within a window of the drive-off, at a true speed of
    zero throughout; a gyro bias of 1 deg/s on every axis changes nothing (the spread is
    tested, not the level)."""
    tables, sensors = seoul(90.0, 11, stationary_s=REST_S)
    p = filters.lc_ekf
    t0 = t0_ns(tables)
    for bias in (0.0, math.radians(1.0)):
        imu = tables["imu"]
        if bias:
            for axis in "xyz":
                col = f"gyro_{axis}_radps"
                i = imu.column_names.index(col)
                imu = imu.set_column(i, col, pa.array(imu.column(col).to_numpy() + bias))
        still = _detect(dict(tables, imu=imu), sensors, p)
        assert still.shape == (1, 2)
        start_s, end_s = (still[0] - t0) * 1e-9
        assert start_s < 1.0
        assert REST_S - 2.0 < end_s <= REST_S
        t = tables["imu"].column("t_ns").to_numpy()
        inside = (t >= still[0, 0]) & (t <= still[0, 1])
        assert _speed(tables["truth"], t[inside]).max() < 1e-6


def test_gnss_vetoes_a_quiet_imu_at_cruise(filters: FiltersParams) -> None:
    """A simulated car cruising straight at constant speed has an IMU as quiet as at rest (no
    vibration): without GNSS its cruise is taken for rest, with the receiver's velocity (or,
    without one, the fixes' displacement) it is not."""
    tables, sensors = seoul(60.0, 12, stationary_s=5.0)
    p = filters.lc_ekf
    t = tables["imu"].column("t_ns").to_numpy()

    def moving_rest_s(still: np.ndarray) -> float:
        inside = np.zeros(t.size, dtype=bool)
        for a, b in still:
            inside |= (t >= a) & (t <= b)
        moving = _speed(tables["truth"], t) > 0.5
        return float((inside & moving).sum()) * 0.01

    assert moving_rest_s(_detect(tables, sensors, p, gnss=False)) > 5.0  # why kernels check speed
    assert moving_rest_s(_detect(tables, sensors, p)) == 0.0
    gnss = tables["gnss"]
    no_vel = gnss.drop([c for c in gnss.column_names if c.startswith("vel_")])
    assert moving_rest_s(_detect(dict(tables, gnss=no_vel), sensors, p)) == 0.0


def with_vibration(tables: Tables, accel_mps2: float = 0.1, gyro_radps: float = 0.005) -> Tables:
    """White vibration on the IMU while the vehicle moves (a road, an engine under load): what
    lets the IMU alone tell rest from a steady cruise."""
    imu = tables["imu"]
    t = imu.column("t_ns").to_numpy()
    moving = _speed(tables["truth"], t) > 0.2
    rng = np.random.default_rng(1)
    for col in imu.column_names[1:]:
        sd = accel_mps2 if col.startswith("acc") else gyro_radps
        v = imu.column(col).to_numpy() + np.where(moving, rng.normal(0.0, sd, t.size), 0.0)
        imu = imu.set_column(imu.column_names.index(col), col, pa.array(v))
    return dict(tables, imu=imu)


def parked(duration_s: float = REST_S + 20.0) -> tuple[Tables, SensorMeta]:
    """A drive that starts with ``REST_S + 5`` s at rest, vibrating while it moves."""
    tables, sensors = seoul(duration_s, 13, stationary_s=REST_S + 5.0)
    return with_vibration(tables), sensors


def _parked_without_gnss(
    filters: FiltersParams, name: str, enabled: bool, backend: Backend = "numba"
) -> RunResult:
    """Started from the truth (drawn errors) at rest; no GNSS for the first ``REST_S`` s."""
    tables, sensors = parked()
    t0 = t0_ns(tables)
    for key in ("gnss", "gnss_obs"):
        t = tables[key].column("t_ns").to_numpy()
        tables[key] = tables[key].filter(pa.array(t > t0 + int(REST_S * 1e9)))
    p = filters.get(name)
    p = replace(p, standstill=replace(p.standstill, enabled=enabled))
    n = ins.N_TIGHT if "tc_" in name else ins.N_LOOSE
    sig = np.array([1.0] * 3 + [0.05] * 3 + [0.01, 0.01, 0.02] + [0.05] * 3 + [5e-4] * 3)
    sig = np.r_[sig, 10.0, 1.0]
    start = drawn_start(tables["truth"], 10, n, sig, np.random.default_rng(0))
    return run_filter(tables, sensors, name, p, backend=backend, initial=start)


def _errors_at(r: RunResult, truth: pa.Table, t_ns: int) -> tuple[float, float, float]:
    """Horizontal position (m), speed (m/s) and yaw (deg) errors at ``t_ns``."""
    k = int(np.searchsorted(r.t_ns, t_ns))
    tt = truth.column("t_ns").to_numpy()
    j = int(np.searchsorted(tt, r.t_ns[k]))
    lat, lon = math.radians(truth.column("lat_deg")[j].as_py()), truth.column("lon_deg")[j]
    dn = (r.x[k, ins.X_LAT] - lat) * 6.378e6
    de = (r.x[k, ins.X_LON] - math.radians(lon.as_py())) * 6.378e6 * math.cos(lat)
    q = r.x[k, ins.X_Q : ins.X_Q + 4]
    yaw = math.atan2(2 * (q[0] * q[3] + q[1] * q[2]), 1 - 2 * (q[2] ** 2 + q[3] ** 2))
    dyaw = math.remainder(yaw - truth.column("yaw_rad")[j].as_py(), 2 * math.pi)
    return math.hypot(dn, de), float(np.linalg.norm(r.x[k, ins.X_VEL : ins.X_VEL + 3])), dyaw


@pytest.mark.parametrize("name", [*ALL_FILTERS, "fwekf"])
def test_parked_without_gnss_the_filter_holds_still(filters: FiltersParams, name: str) -> None:
    """Parked for 40 s without GNSS (a garage), every INS filter: with the standstill
    updates its position stays within 0.5 m and its speed under 0.05 m/s, and its yaw drifts
    less than without them (the gyro biases held by the zero-rate update); without them the
    free inertial solution drifts metres."""
    tables, _ = parked()
    t_start = t0_ns(tables) + 1_000_000_000
    t_end = t0_ns(tables) + int((REST_S - 1.0) * 1e9)
    on = _parked_without_gnss(filters, name, True)
    off = _parked_without_gnss(filters, name, False)
    assert on.status == off.status == "ok"
    pos_on, speed_on, yaw_on = _errors_at(on, tables["truth"], t_end)
    pos_off, _, yaw_off = _errors_at(off, tables["truth"], t_end)
    drift_on = abs(yaw_on - _errors_at(on, tables["truth"], t_start)[2])
    drift_off = abs(yaw_off - _errors_at(off, tables["truth"], t_start)[2])
    assert pos_on < 0.5
    assert speed_on < 0.05
    assert pos_off > 5.0
    assert drift_on < drift_off
    streams = on.inn_i[:, 1]
    assert (streams == me.S_STILL).sum() > 300  # ~10 Hz for 39 s, two blocks per epoch
    assert not (off.inn_i[:, 1] == me.S_STILL).any()


@pytest.mark.parametrize("name", ["lc_ekf", "tc_ukf_nhc", "fwekf"])
def test_numba_and_filterpy_agree_on_the_standstill_updates(
    filters: FiltersParams, name: str
) -> None:
    """The parked run on both backends: the same standstill rows, gating and states."""
    fast = _parked_without_gnss(filters, name, True)
    ref = _parked_without_gnss(filters, name, True, backend="filterpy")
    assert (fast.inn_i[:, 1] == me.S_STILL).sum() > 300
    assert_backends_agree(fast, ref)
