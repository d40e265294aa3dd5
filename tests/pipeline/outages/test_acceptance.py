"""Issue 6 acceptance on a seoul_campus drive: 60 s windows at three places of a 300 s drive.

- With 3 satellites (the default policy, highest elevation) the tightly coupled filters keep
  the error bounded while the loosely coupled one, which gets no fix below four satellites,
  drifts exactly as in a complete outage (a free INS).
- With 2 satellites the pseudoranges still hold the drift down when the pair has some
  horizontal spread (best_dop); the two highest satellites (the default policy) are nearly
  overhead and help far less, which the Monte Carlo's reduction table shows per k.
- The non-holonomic constraint reduces the drift of complete outages, for loose and tight
  coupling.

Each window is replayed from the nominal run's state at its start (``outages.montecarlo``,
equal to a full replay, see test_montecarlo.py), so the whole file costs a few seconds.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from navreplay.pipeline.outages.montecarlo import Case
from navreplay.pipeline.scenarios.config import Policy
from tests.pipeline.scenarios.drives import montecarlo_rows

STARTS_S = (60.0, 130.0, 200.0)
LENGTH_S = 60.0

Rows = dict[int, list[dict[str, Any]]]


def windows(name: str, sats: tuple[int, ...], policy: Policy = "highest_elevation") -> Rows:
    """sats -> the window metrics of the three windows, for filter ``name``."""
    cases = [Case(LENGTH_S, k) for k in sats]
    rows = montecarlo_rows(name, 300.0, STARTS_S, cases, tail_s=20.0, policy=policy)
    assert all(r["status"] == "ok" for r in rows)
    return {k: [r for r in rows if r["sats"] == k] for k in sats}


def end(rows: list[dict[str, Any]]) -> np.ndarray:
    return np.array([r["err_end_m"] for r in rows])


def peak(rows: list[dict[str, Any]]) -> np.ndarray:
    return np.array([r["err_max_m"] for r in rows])


@pytest.fixture(scope="module")
def loose() -> Rows:
    return windows("lc_ekf", (0, 2, 3))


def test_loose_coupling_below_four_satellites_drifts_exactly_as_a_free_ins(loose: Rows) -> None:
    for k in (2, 3):
        np.testing.assert_array_equal(end(loose[k]), end(loose[0]))
        np.testing.assert_array_equal(peak(loose[k]), peak(loose[0]))
    assert np.mean(end(loose[0])) > 10.0  # 60 s of free inertial drift on a MEMS IMU


@pytest.mark.parametrize("name", ["tc_ekf", "tc_ukf"])
def test_three_satellites_keep_tight_coupling_bounded(name: str, loose: Rows) -> None:
    tight = windows(name, (3,))[3]
    assert np.all(peak(tight) < 5.0)  # bounded: no window's error grows past a few metres
    assert np.mean(end(tight)) < 0.2 * np.mean(end(loose[0]))
    assert all(r["kept_svs"].count(",") == 2 for r in tight)


@pytest.mark.parametrize("name", ["tc_ekf", "tc_ukf"])
def test_two_spread_satellites_hold_tight_coupling_well_below_the_free_ins(
    name: str, loose: Rows
) -> None:
    tight = windows(name, (2,), policy="best_dop")[2]
    assert np.all(peak(tight) < 25.0)
    assert np.mean(end(tight)) < 0.5 * np.mean(end(loose[0]))


@pytest.mark.parametrize(("base", "nhc"), [("lc_ekf", "lc_ekf_nhc"), ("tc_ukf", "tc_ukf_nhc")])
def test_non_holonomic_constraint_reduces_drift_in_complete_outages(base: str, nhc: str) -> None:
    a, b = windows(base, (0,))[0], windows(nhc, (0,))[0]
    mean_a = np.mean([r["err_mean_m"] for r in a])
    mean_b = np.mean([r["err_mean_m"] for r in b])
    assert mean_b < 0.5 * mean_a
    assert np.mean(end(b)) < 0.5 * np.mean(end(a))
