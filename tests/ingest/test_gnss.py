"""Broadcast orbits: IS-GPS-200 positions and clocks against RTKLIB, velocities against finite
differences, light time and Sagnac against their definitions."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from navreplay.ingest.gnss import ephemeris
from navreplay.ingest.gpstime import NS_PER_S, NS_PER_WEEK
from tests.ingest.navfile import read_gps_nav

SHARED = Path(__file__).resolve().parents[3] / "shared" / "data"
NAV_2016 = SHARED / "gps_measurement_tools" / "android_raw_2016" / "hour2350.16n"


@pytest.fixture(scope="module")
def real_eph() -> ephemeris.Ephemeris:
    if not NAV_2016.is_file():
        pytest.skip(f"shared data absent: {NAV_2016}")
    return read_gps_nav(NAV_2016)


def test_positions_and_clocks_match_rtklib_on_a_real_navigation_file(
    real_eph: ephemeris.Ephemeris,
) -> None:
    rtk = pytest.importorskip("pyrtklib")
    nav, obs, sta = rtk.nav_t(), rtk.obs_t(), rtk.sta_t()
    assert rtk.readrnx(str(NAV_2016), 1, "", obs, nav, sta) == 1
    assert nav.n == len(real_eph) == 419
    checked = 0
    worst_pos, worst_clk = 0.0, 0.0
    for k in range(0, nav.n, 7):
        e = nav.eph[k]
        week = rtk.Arr1Dint(1)
        toe_sow = rtk.time2gpst(e.toe, week)
        toe_ns = week[0] * NS_PER_WEEK + round(toe_sow * NS_PER_S)
        (j,) = np.flatnonzero(
            (real_eph.prn == e.sat) & (real_eph.toe_ns == toe_ns) & (real_eph.iode == e.iode)
        )
        for dt in (-5400.0, -1.5, 0.0, 3333.3, 7200.0):
            rs, dts, var = rtk.Arr1Ddouble(6), rtk.Arr1Ddouble(2), rtk.Arr1Ddouble(1)
            rtk.eph2pos(rtk.timeadd(e.toe, dt), e, rs, dts, var)
            st = ephemeris.orbit(real_eph, j, toe_ns, dt)
            worst_pos = max(worst_pos, float(np.abs(st.pos_m[0] - [rs[0], rs[1], rs[2]]).max()))
            worst_clk = max(worst_clk, abs(st.clock_s[0] - dts[0]) * ephemeris.C_MPS)
            checked += 1
    assert checked > 250
    assert worst_pos < 1e-6  # metres: same algorithm, same constants
    assert worst_clk < 1e-6  # metres of clock (relativistic term included by both)


def test_velocity_and_clock_drift_are_the_derivatives_of_position_and_clock(
    real_eph: ephemeris.Ephemeris,
) -> None:
    idx = np.arange(0, len(real_eph), 5)
    t = real_eph.toe_ns[idx] + 1234 * NS_PER_S
    h = 0.01
    st = ephemeris.orbit(real_eph, idx, t)
    up, dn = ephemeris.orbit(real_eph, idx, t, h), ephemeris.orbit(real_eph, idx, t, -h)
    fd_vel = (up.pos_m - dn.pos_m) / (2 * h)
    fd_drift = (up.clock_s - dn.clock_s) / (2 * h)
    np.testing.assert_allclose(st.vel_mps, fd_vel, atol=2e-5)  # m/s; the h^2 term is ~1e-6
    np.testing.assert_allclose(st.clock_drift_sps, fd_drift, atol=1e-15)
    speed = np.linalg.norm(st.vel_mps, axis=1)
    assert np.all((speed > 2500) & (speed < 4000))  # ECEF speed of a GPS satellite


def test_transmit_state_closes_the_light_time_equation(real_eph: ephemeris.Ephemeris) -> None:
    rx = np.array([-2_694_685.473, -4_293_642.366, 3_857_878.924])  # Mountain View, CA
    t_rx = int(real_eph.toe_ns[0]) + 600 * NS_PER_S
    prn = np.unique(real_eph.prn)
    idx = ephemeris.select(real_eph, prn, t_rx)
    idx = idx[idx >= 0]
    ts = ephemeris.transmit_state(real_eph, idx, t_rx, rx)
    np.testing.assert_allclose(ts.range_m, ephemeris.C_MPS * ts.tau_s, rtol=0, atol=1e-4)
    # the state is the orbit at t_rx - tau, rotated by the earth's turn during the flight
    raw = ephemeris.orbit(real_eph, idx, t_rx, -ts.tau_s)
    th = ephemeris.OMEGA_E_GPS * ts.tau_s
    expect_x = np.cos(th) * raw.pos_m[:, 0] + np.sin(th) * raw.pos_m[:, 1]
    np.testing.assert_allclose(ts.sat.pos_m[:, 0], expect_x, atol=1e-6)
    np.testing.assert_allclose(ts.sat.pos_m[:, 2], raw.pos_m[:, 2], atol=1e-9)
    # the earth turns by ~w_e * 75 ms: a satellite moves by about a hundred metres
    shift = np.linalg.norm(ts.sat.pos_m - raw.pos_m, axis=1)
    assert np.all((shift > 50.0) & (shift < 260.0))
    assert np.all((ts.tau_s > 0.064) & (ts.tau_s < 0.110))  # all satellites, also far side


def test_select_picks_the_nearest_healthy_valid_record(real_eph: ephemeris.Ephemeris) -> None:
    healthy = np.flatnonzero(real_eph.health == 0)
    for k in healthy[[0, 50, 200]]:
        prn, toe = int(real_eph.prn[k]), int(real_eph.toe_ns[k])
        (got,) = ephemeris.select(real_eph, prn, toe + 60 * NS_PER_S)
        assert real_eph.prn[got] == prn
        assert abs(int(real_eph.toe_ns[got]) - toe) <= 7200 * NS_PER_S
        assert real_eph.health[got] == 0
    # a week later nothing is valid
    (none,) = ephemeris.select(
        real_eph, int(real_eph.prn[0]), int(real_eph.toe_ns[0]) + NS_PER_WEEK
    )
    assert none == -1
    # PRN 4 was flagged unhealthy (63) all day in this file: never selected
    sick = np.flatnonzero(real_eph.prn == 4)
    assert np.all(real_eph.health[sick] == 63)
    assert np.all(ephemeris.select(real_eph, 4, real_eph.toe_ns[sick]) == -1)


def test_elevation_and_azimuth_of_known_directions() -> None:
    lat, lon = math.radians(37.46), math.radians(126.95)
    up = np.array([math.cos(lat) * math.cos(lon), math.cos(lat) * math.sin(lon), math.sin(lat)])
    east = np.array([-math.sin(lon), math.cos(lon), 0.0])
    north = np.cross(up, east)
    rx = 6_371_000.0 * up
    # a geocentric "up" is not the ellipsoid normal at 37 deg: the difference is ~0.19 deg
    el, _ = ephemeris.elevation_azimuth(rx, rx + 2e7 * up)
    assert abs(math.degrees(el[0]) - 90.0) < 0.2
    sats = rx + 2e7 * np.array([east + 0.01 * up, north + 0.01 * up, -north + up])
    el, az = ephemeris.elevation_azimuth(rx, sats)
    np.testing.assert_allclose(np.degrees(az[:2]), [90.0, 0.0], atol=0.3)
    assert math.degrees(az[2]) == pytest.approx(180.0, abs=0.3)
    assert math.degrees(el[2]) == pytest.approx(45.0, abs=0.3)


def test_ephemeris_columns_are_checked() -> None:
    with pytest.raises(ValueError, match="missing"):
        ephemeris.Ephemeris.from_columns(prn=[1])
