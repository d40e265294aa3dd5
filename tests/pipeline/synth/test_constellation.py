"""The nominal 24-slot constellation as broadcast ephemerides."""

from __future__ import annotations

import math

import numpy as np
import pytest

from navreplay.ingest.gnss import ephemeris
from navreplay.ingest.gpstime import NS_PER_S, gps_from_calendar
from navreplay.pipeline.nav import earth
from navreplay.pipeline.synth import constellation as cst
from navreplay.pipeline.synth.seoul_params import ConstellationParams

PARAMS = ConstellationParams(0.01, 0.0, 7200, 2e-4, 3e-12, 5e-9)
T0 = gps_from_calendar("2026-11-18T00:00:00")


@pytest.fixture(scope="module")
def day() -> ephemeris.Ephemeris:
    return cst.nominal_gps(T0, T0 + 86_400 * NS_PER_S, PARAMS, np.random.default_rng(1))


def test_one_record_per_slot_per_upload(day: ephemeris.Ephemeris) -> None:
    assert len(day) == 24 * 13  # toe every 2 h from 00:00 to 24:00
    assert sorted(set(day.prn.tolist())) == list(range(1, 25))
    assert np.all(day.health == 0)
    assert np.all(np.diff(day.toe_ns) >= 0)


def test_orbits_have_the_reference_shape(day: ephemeris.Ephemeris) -> None:
    idx = np.arange(24)
    t = np.full(24, T0 + 3600 * NS_PER_S)
    st = ephemeris.orbit(day, idx, t)
    r = np.linalg.norm(st.pos_m, axis=1)
    assert np.all(np.abs(r - cst.SEMI_MAJOR_AXIS_M) < 0.011 * cst.SEMI_MAJOR_AXIS_M)
    # inclination from the angular momentum (ECEF velocity plus the earth's rotation)
    v_inertial = st.vel_mps + np.cross([0.0, 0.0, ephemeris.OMEGA_E_GPS], st.pos_m)
    h = np.cross(st.pos_m, v_inertial)
    incl = np.degrees(np.arccos(h[:, 2] / np.linalg.norm(h, axis=1)))
    np.testing.assert_allclose(incl, 55.0, atol=0.01)  # the node regresses: ~0.003 deg
    # six planes of four, 60 deg apart in node
    node = np.degrees(np.arctan2(h[:, 0], -h[:, 1])) % 360.0
    planes = np.sort(np.round(node).reshape(6, 4)[:, 0] % 360)
    np.testing.assert_allclose(np.diff(planes), 60.0, atol=1.0)
    # about two revolutions per sidereal day
    period = 2 * math.pi * math.sqrt(cst.SEMI_MAJOR_AXIS_M**3 / ephemeris.MU_GPS)
    assert period == pytest.approx(86_164.09 / 2, rel=1e-3)
    assert cst.nodal_rate_radps(cst.SEMI_MAJOR_AXIS_M, 0.0, math.radians(55.0)) == pytest.approx(
        math.radians(-4.4874e-7),
        rel=0.01,  # SPS PS 2001, Table A-2-1
    )


def test_positions_are_continuous_across_uploads(day: ephemeris.Ephemeris) -> None:
    boundary = T0 + 3 * 3600 * NS_PER_S  # halfway between toe 02:00 and toe 04:00
    for prn in (1, 13, 24):
        (before,) = np.flatnonzero((day.prn == prn) & (day.toe_ns == T0 + 2 * 3600 * NS_PER_S))
        (after,) = np.flatnonzero((day.prn == prn) & (day.toe_ns == T0 + 4 * 3600 * NS_PER_S))
        a, b = ephemeris.orbit(day, before, boundary), ephemeris.orbit(day, after, boundary)
        np.testing.assert_allclose(a.pos_m, b.pos_m, atol=1e-3)
        assert abs(a.clock_s[0] - b.clock_s[0]) * ephemeris.C_MPS < 1e-3


def test_enough_satellites_are_visible_in_seoul_all_day(day: ephemeris.Ephemeris) -> None:
    rx = earth.geodetic_to_ecef(math.radians(37.46), math.radians(126.95), 60.0)
    counts = []
    for minute in range(0, 24 * 60, 10):
        t = T0 + minute * 60 * NS_PER_S
        idx = ephemeris.select(day, np.arange(1, 25), t)
        el, _ = ephemeris.elevation_azimuth(rx, ephemeris.transmit_state(day, idx, t, rx).sat.pos_m)
        counts.append(int(np.sum(np.degrees(el) > 10.0)))
    assert min(counts) >= 4
    assert 6.5 < np.mean(counts) < 10.0


def test_broadcast_values_survive_rinex_formatting(day: ephemeris.Ephemeris) -> None:
    for name in ("m0_rad", "omega0_rad", "af0_s", "omega_dot_radps", "tgd_s"):
        values = getattr(day, name)
        np.testing.assert_array_equal(cst.rinex_round(values), values)
