"""The Monte Carlo replays each window from the nominal run's state at its start; its window
metrics must equal those of a full replay of the same scenario."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from navreplay.pipeline.estimation.core.windows import NS
from navreplay.pipeline.estimation.ins.inputs import prepare_fixes, prepare_obs
from navreplay.pipeline.estimation.ins.metrics import compute_metrics
from navreplay.pipeline.estimation.ins.replay import run_filter
from navreplay.pipeline.outages.montecarlo import (
    Case,
    cases_for,
    draw_starts,
)
from navreplay.pipeline.scenarios.apply import apply_scenario
from navreplay.pipeline.scenarios.config import SatellitesSpec, ScenarioSpec, WindowsSpec
from tests.pipeline.scenarios.drives import drive, montecarlo_rows, params

DURATION_S, START_S, LENGTH_S = 150.0, 60.5, 30.0


def full_replay(name: str, sats: int) -> dict[str, Any]:
    """The window metrics of a full replay of a one-window scenario, with the fix-error model
    learned from the whole log (as the scenario runs of the pipeline take it)."""
    tables, sensors = drive(DURATION_S)
    spec = ScenarioSpec(
        windows=WindowsSpec("explicit", LENGTH_S, starts_s=(START_S,)),
        satellites=SatellitesSpec(sats) if sats else None,
    )
    applied = apply_scenario(tables, "one", spec)
    section = params().filters.get(name)
    noise = prepare_fixes(tables["gnss"], section.gnss).noise
    obs_noise = prepare_obs(tables["gnss_obs"], section.gnss).noise
    r = run_filter(applied.tables, sensors, name, section, fix_noise=noise, obs_noise=obs_noise)
    m = compute_metrics(
        r,
        tables["truth"],
        windows=applied.outage_windows,
        t0_ns=applied.t0_ns,
        window_params=params().scenarios.metrics,
    )
    (w,) = m["outage_windows"]
    return dict(w)


def montecarlo(name: str, cases: list[Case], workers: int = 1) -> list[dict[str, Any]]:
    tables, _ = drive(DURATION_S)
    t0 = int(tables["imu"].column("t_ns")[0].as_py())
    t_end = int(tables["imu"].column("t_ns")[-1].as_py())
    tail_s = (t_end - t0) / NS - START_S - LENGTH_S  # to the end of the log, as a full run
    starts_s = (START_S, 90.0)
    return montecarlo_rows(
        name, DURATION_S, starts_s, cases, tail_s=tail_s, mask_deg=10.0, workers=workers
    )


@pytest.mark.parametrize(("name", "sats"), [("lc_ekf", 0), ("tc_ukf", 0), ("tc_ukf", 3)])
def test_checkpointed_window_replay_equals_the_full_replay(name: str, sats: int) -> None:
    full = full_replay(name, sats)
    row = next(r for r in montecarlo(name, [Case(LENGTH_S, sats)]) if r["window"] == 0)
    assert row["status"] == "ok"
    for key, value in full.items():
        if isinstance(value, float):
            assert row[key] == pytest.approx(value, rel=1e-6, abs=1e-6), key
        else:
            assert row[key] == value, key
    assert row["replayed_s"] < DURATION_S - START_S + 1.0  # the prefix was not replayed


def test_process_pool_gives_the_same_rows_as_one_process() -> None:
    cases = [Case(10.0, 0), Case(10.0, 2)]
    one = montecarlo("tc_ekf", cases, workers=1)
    two = montecarlo("tc_ekf", cases, workers=2)
    drop = {"replay_s"}
    assert [{k: v for k, v in r.items() if k not in drop} for r in one] == [
        {k: v for k, v in r.items() if k not in drop} for r in two
    ]
    assert len(one) == 4


def test_window_starts_are_seeded_uniform_draws_inside_the_drive() -> None:
    a = draw_starts([1, 2], 50, 0, 900 * NS, 120.0, 120.0, 30.0)
    assert a == draw_starts([1, 2], 50, 0, 900 * NS, 120.0, 120.0, 30.0)
    s = np.array([x.start_ns for x in a]) / NS
    assert s.min() >= 120.0
    assert s.max() <= 750.0
    assert {x.seed for x in a} == {1, 2}
    assert len(a) == 100
    assert len(set(s[:50]) & set(s[50:])) == 0
    with pytest.raises(ValueError, match="too short"):
        draw_starts([1], 5, 0, 200 * NS, 120.0, 120.0, 30.0)


def test_a_complete_outage_serves_both_experiments() -> None:
    cases = cases_for((0, 1, 4), 60.0, (10.0, 60.0))
    assert cases == [Case(10.0, 0), Case(60.0, 0), Case(60.0, 1), Case(60.0, 4)]
