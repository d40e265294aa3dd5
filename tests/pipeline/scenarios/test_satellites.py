"""Partial outages: the selection policies and the single-point re-fixes of loose coupling."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from navreplay.pipeline.estimation.core.windows import NS
from navreplay.pipeline.scenarios.apply import apply_scenario
from navreplay.pipeline.scenarios.config import SatellitesSpec, ScenarioSpec, WindowsSpec
from navreplay.pipeline.scenarios.faults import column
from navreplay.pipeline.scenarios.satellites import gdop, los_rows, policy_order, select
from tests.pipeline.scenarios.drives import drive

EL = np.array([15.0, 80.0, 45.0, 30.0, 60.0, 25.0, 70.0])
AZ = np.array([10.0, 200.0, 95.0, 300.0, 160.0, 240.0, 30.0])


def test_elevation_policies_rank_by_elevation() -> None:
    rng = np.random.default_rng(0)
    assert policy_order(EL, AZ, 3, "highest_elevation", rng)[:3] == [1, 6, 4]
    assert policy_order(EL, AZ, 3, "lowest_elevation", rng)[:3] == [0, 5, 3]


def test_random_policy_is_seeded() -> None:
    a = policy_order(EL, AZ, 3, "random", np.random.default_rng(5))
    assert a == policy_order(EL, AZ, 3, "random", np.random.default_rng(5))
    draws = {
        tuple(policy_order(EL, AZ, 3, "random", np.random.default_rng(s))[:3]) for s in range(20)
    }
    assert len(draws) > 5


@pytest.mark.parametrize("k", [4, 5])
def test_dop_policies_find_the_best_and_worst_geometry(k: int) -> None:
    rng = np.random.default_rng(0)
    G = los_rows(EL, AZ)
    all_gdop = {s: gdop(G[list(s)]) for s in itertools.combinations(range(EL.size), k)}
    finite = [v for v in all_gdop.values() if math.isfinite(v)]
    best = policy_order(EL, AZ, k, "best_dop", rng)[:k]
    worst = policy_order(EL, AZ, k, "worst_dop", rng)[:k]
    assert gdop(G[best]) == pytest.approx(min(finite))
    assert gdop(G[worst]) == pytest.approx(max(finite))


def test_dop_policies_below_four_satellites_use_the_spanned_volume() -> None:
    rng = np.random.default_rng(0)
    G = los_rows(EL, AZ)

    def volume(s: list[int]) -> float:
        return float(np.linalg.det(G[s] @ G[s].T))

    vols = [volume(list(s)) for s in itertools.combinations(range(EL.size), 3)]
    assert volume(policy_order(EL, AZ, 3, "best_dop", rng)[:3]) == pytest.approx(max(vols))
    assert volume(policy_order(EL, AZ, 3, "worst_dop", rng)[:3]) == pytest.approx(min(vols))


def test_select_keeps_k_satellites_per_epoch_inside_windows_only() -> None:
    tables, _ = drive()
    obs = tables["gnss_obs"]
    t = obs.column("t_ns").to_numpy()
    sv = np.asarray(obs.column("sv").to_pylist(), dtype=object)
    el, az = column(obs, "elevation_deg"), column(obs, "azimuth_deg")
    win = [(int(t[0]) + 20 * NS, int(t[0]) + 40 * NS)]
    keep, sel = select(t, sv, el, az, win, 3, "highest_elevation", 0, 10.0)
    inside = (t >= win[0][0]) & (t < win[0][1])
    assert keep[~inside].all()
    per_epoch = np.bincount(np.unique(t[inside], return_inverse=True)[1], weights=keep[inside])
    assert (per_epoch == 3).all()
    first = inside & (t == t[inside][0])
    top3 = sv[first][np.argsort(-el[first])[:3]]
    assert set(sel[0].svs) == set(top3)
    assert sel[0].gdop is None
    # a chosen satellite missing at an epoch is replaced by the next one in the order
    drop = inside & (sv == sel[0].svs[0]) & (t == t[inside][5])
    keep2, _ = select(
        t[~drop], sv[~drop], el[~drop], az[~drop], win, 3, "highest_elevation", 0, 10.0
    )
    epoch = t[~drop] == t[inside][5]
    assert keep2[epoch].sum() == 3


def test_refixed_fixes_follow_the_kept_satellites() -> None:
    """With 4+ satellites the loosely coupled filter gets the fix a receiver tracking only
    those would compute: close to the truth, with an accuracy from its geometry."""
    tables, _ = drive()
    t0 = int(tables["imu"].column("t_ns")[0].as_py())
    truth = tables["truth"]
    visible = int(
        np.min(np.unique(tables["gnss_obs"].column("t_ns").to_numpy(), return_counts=True)[1])
    )
    assert visible > 4
    for k in (4, visible):
        spec = ScenarioSpec(
            windows=WindowsSpec("explicit", 30.0, starts_s=(20.0,)),
            satellites=SatellitesSpec(keep=k),
        )
        out = apply_scenario(tables, "s", spec).tables["gnss"]
        t = out.column("t_ns").to_numpy()
        inside = (t >= t0 + 20 * NS) & (t < t0 + 50 * NS)
        assert inside.sum() == 30
        assert (out.column("num_sats").to_numpy()[inside] == k).all()
        ti = np.searchsorted(truth.column("t_ns").to_numpy(), t[inside])
        dlat = (column(out, "lat_deg")[inside] - truth.column("lat_deg").to_numpy()[ti]) * 111e3
        h_acc = column(out, "h_acc_m")[inside]
        assert np.sqrt(np.mean(dlat**2)) < 4.0 * np.mean(h_acc)  # pseudorange noise
        assert 0.3 < np.mean(h_acc) < 20.0
        if k == 4:
            h4 = np.mean(h_acc)
        else:
            assert np.mean(h_acc) < h4  # more satellites, better geometry
    none = apply_scenario(
        tables,
        "s",
        ScenarioSpec(
            windows=WindowsSpec("explicit", 30.0, starts_s=(20.0,)), satellites=SatellitesSpec(3)
        ),
    ).tables["gnss"]
    assert none.num_rows == tables["gnss"].num_rows - 30
