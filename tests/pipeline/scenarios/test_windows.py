"""Outage window placement: explicit, periodic and seeded random windows inside the log."""

from __future__ import annotations

import itertools
import logging

import numpy as np
import pytest
from scipy.stats import kstest

from navreplay.pipeline.estimation.core.windows import NS
from navreplay.pipeline.scenarios.config import WindowsSpec
from navreplay.pipeline.scenarios.windows import in_any, place_windows

T0 = 1_000 * NS
END = T0 + 900 * NS


def seconds(windows: list[tuple[int, int]]) -> list[tuple[float, float]]:
    return [((a - T0) / NS, (b - T0) / NS) for a, b in windows]


def test_explicit_windows_are_placed_and_those_past_the_end_skipped(
    caplog: pytest.LogCaptureFixture,
) -> None:
    spec = WindowsSpec("explicit", 60.0, starts_s=(100.0, 500.0, 880.0))
    with caplog.at_level(logging.WARNING):
        got = seconds(place_windows(spec, T0, END))
    assert got == [(100.0, 160.0), (500.0, 560.0)]
    assert "1 of 3 explicit windows" in caplog.text


def test_periodic_windows_start_at_earliest_and_end_before_the_tail() -> None:
    spec = WindowsSpec("periodic", 30.0, period_s=100.0, earliest_s=120.0, tail_s=50.0)
    got = seconds(place_windows(spec, T0, END))
    assert got[0] == (120.0, 150.0)
    assert all(b - a == 30.0 for a, b in got)
    assert np.allclose(np.diff([a for a, _ in got]), 100.0)
    assert got[-1][1] <= 850.0 < got[-1][0] + 100.0 + 30.0


def test_random_windows_are_reproducible_separated_and_inside_the_log() -> None:
    spec = WindowsSpec("random", 60.0, count=5, seed=3, earliest_s=120.0, tail_s=30.0)
    first = place_windows(spec, T0, END)
    assert first == place_windows(spec, T0, END)
    other = place_windows(WindowsSpec("random", 60.0, count=5, seed=4), T0, END)
    assert other != first
    s = seconds(first)
    assert len(s) == 5
    assert s[0][0] >= 120.0
    assert s[-1][1] <= 870.0
    gaps = [b0 - a1 for (_, a1), (b0, _) in itertools.pairwise(s)]
    assert min(gaps) >= 60.0


def test_random_placement_is_uniform_over_the_drive() -> None:
    """One window per draw: its start is uniform over [earliest, end - tail - length]."""
    starts = [
        seconds(place_windows(WindowsSpec("random", 60.0, seed=s), T0, END))[0][0]
        for s in range(400)
    ]
    assert kstest(starts, "uniform", args=(120.0, 870.0 - 60.0 - 120.0)).pvalue > 1e-3


def test_random_placement_places_only_the_windows_that_fit(
    caplog: pytest.LogCaptureFixture,
) -> None:
    spec = WindowsSpec("random", 60.0, count=50, seed=1, earliest_s=120.0, min_gap_s=60.0)
    with caplog.at_level(logging.WARNING):
        got = place_windows(spec, T0, END)
    assert len(got) == 6  # 6 x 60 s + 5 x 60 s gaps = 660 s fit in [120, 870]; 7 need 780
    assert "only 6 of 50" in caplog.text
    assert "shorten the scenario's windows" in caplog.text  # and what to do
    short = place_windows(spec, T0, T0 + 100 * NS)
    assert short == []


def test_in_any_marks_half_open_windows() -> None:
    t = np.array([0, 5, 10, 15, 20], dtype=np.int64)
    assert in_any(t, [(5, 15)]).tolist() == [False, True, True, False, False]
