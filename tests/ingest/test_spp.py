"""Single-point positioning (``ingest.gnss.spp``): exact on consistent data, honest when
under-determined, one epoch or a table of them."""

from __future__ import annotations

import numpy as np
import pytest

from navreplay.ingest.ecef import c_ned_ecef, ecef_from_geodetic
from navreplay.ingest.gnss import spp


def _geometry(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    rx = ecef_from_geodetic(37.46, 126.95, 60.0)[0]
    up = rx / np.linalg.norm(rx)
    sats: list[np.ndarray] = []
    while len(sats) < n:
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        if d @ up > 0.2:  # above ~12 deg
            sats.append(rx + 2.2e7 * d)
    return rx, np.array(sats)


@pytest.mark.parametrize("n", [4, 6, 10])
def test_position_and_clock_are_recovered_exactly(n: int) -> None:
    rng = np.random.default_rng(n)
    rx, sats = _geometry(rng, n)
    bias = 12_345.678
    pr = np.linalg.norm(sats - rx, axis=1) + bias
    x, cov, iters, ok = spp.solve_position(sats, pr, np.ones(n), np.zeros(4), 20, 1e-6)
    assert ok
    assert iters < 10
    np.testing.assert_allclose(x[:3], rx, atol=1e-6)
    assert x[3] == pytest.approx(bias, abs=1e-6)
    assert np.all(np.diag(cov) > 0)


def test_velocity_and_drift_are_recovered_exactly() -> None:
    rng = np.random.default_rng(3)
    rx, sats = _geometry(rng, 7)
    sat_vel = rng.normal(0.0, 2000.0, (7, 3))
    v_rx, drift = np.array([3.0, -11.0, 0.4]), 55.5
    e = (sats - rx) / np.linalg.norm(sats - rx, axis=1)[:, None]
    rate = np.einsum("ij,ij->i", e, sat_vel - v_rx) + drift
    x, _ = spp.solve_velocity(sats, sat_vel, rate, np.ones(7), rx)
    np.testing.assert_allclose(x, [*v_rx, drift], atol=1e-9)


def test_fewer_than_four_satellites_give_no_solution() -> None:
    rng = np.random.default_rng(1)
    rx, sats = _geometry(rng, 3)
    pr = np.linalg.norm(sats - rx, axis=1)
    x, _, _, ok = spp.solve_position(sats, pr, np.ones(3), np.zeros(4), 10, 1e-6)
    assert not ok
    assert np.all(np.isnan(x))
    assert np.all(np.isnan(spp.dop_enu(sats, rx, c_ned_ecef(37.46, 126.95)[0])))


def test_dop_matches_the_covariance_of_the_solution() -> None:
    rng = np.random.default_rng(5)
    rx, sats = _geometry(rng, 8)
    pr = np.linalg.norm(sats - rx, axis=1)
    _, cov, _, _ = spp.solve_position(sats, pr, np.ones(8), np.zeros(4), 20, 1e-9)
    c_en = c_ned_ecef(37.46, 126.95)[0]
    q = spp.dop_enu(sats, rx, c_en)
    ned = c_en @ cov[:3, :3] @ c_en.T
    np.testing.assert_allclose(q, [ned[1, 1], ned[0, 0], ned[2, 2], cov[3, 3]], rtol=1e-9)
    assert q[2] > max(q[0], q[1])  # no satellites below: vertical is the weak direction


@pytest.mark.parametrize("x0", ["centre", "given"])
def test_every_epoch_of_a_table_is_solved(x0: str) -> None:
    rng = np.random.default_rng(9)
    rows, truth = [], []
    for k in range(3):
        rx, sats = _geometry(rng, 5 + k)
        rx = rx + k * 100.0
        truth.append(rx)
        rows += [(k, s, np.linalg.norm(s - rx) + 50.0 * k) for s in sats]
    t = np.array([r[0] for r in rows], dtype=np.int64)
    sat = np.array([r[1] for r in rows])
    pr = np.array([r[2] for r in rows])
    assert spp.epoch_starts(t).tolist() == [0, 5, 11, 18]
    epoch, first = spp.epoch_index(t)
    assert first.tolist() == [0, 5, 11]
    start = None if x0 == "centre" else np.column_stack([np.array(truth) + 500.0, np.zeros(3)])
    fix = spp.solve(sat, pr, epoch, first.size, x0=start, tol_m=1e-6)
    assert fix.solved.all()
    assert fix.used.all()
    np.testing.assert_allclose(fix.ecef_m, truth, atol=1e-5)
    np.testing.assert_allclose(fix.clock_m, [0.0, 50.0, 100.0], atol=1e-5)
    assert np.all(fix.rms_m < 1e-5)


def test_an_epoch_with_three_satellites_is_left_unsolved_beside_a_solved_one() -> None:
    rng = np.random.default_rng(11)
    rx, sats = _geometry(rng, 8)
    _, few = _geometry(rng, 3)
    sat = np.concatenate([sats, few])
    pr = np.linalg.norm(sat - rx, axis=1)
    epoch = np.array([0] * 8 + [1] * 3, dtype=np.int64)
    fix = spp.solve(sat, pr, epoch, 2)
    assert fix.solved.tolist() == [True, False]
    assert fix.used.all()  # consistent pseudoranges: nothing rejected
    np.testing.assert_allclose(fix.ecef_m[0], rx, atol=1e-4)
    assert np.all(np.isnan(fix.ecef_m[1]))
    assert np.isnan(fix.clock_m[1])
    assert np.isnan(fix.rms_m[1])
