"""The reduction's paired interval: estimate, coverage, and agreement with the delta method."""

from __future__ import annotations

import math

import numpy as np
import pytest

from navreplay.pipeline.outages.stats import (
    delta_reduction,
    mean_interval,
    paired_reduction,
    reduction_pct,
)


def pairs(rng: np.random.Generator, n: int, ratio: float) -> tuple[np.ndarray, np.ndarray]:
    """Window errors of a baseline (log-normal, the spread of outage difficulty) and a
    candidate that removes ``1 - ratio`` of it with its own noise."""
    a = rng.lognormal(2.0, 0.8, n)
    b = ratio * a * rng.lognormal(0.0, 0.3, n) / math.exp(0.3**2 / 2)
    return a, b


def test_reduction_is_one_minus_the_ratio_of_means() -> None:
    a, b = np.array([10.0, 20.0, 30.0]), np.array([5.0, 5.0, 20.0])
    assert reduction_pct(a, b) == pytest.approx(100 * (1 - 30 / 60))


def test_paired_bootstrap_covers_the_true_reduction_about_95_percent_of_the_time() -> None:
    rng = np.random.default_rng(11)
    hits = []
    for i in range(120):
        a, b = pairs(rng, 24, 0.4)
        ci = paired_reduction(a, b, 0.95, 1000, seed=i)
        hits.append(ci.low <= 60.0 <= ci.high)
    assert 0.85 <= np.mean(hits) <= 1.0


def test_bootstrap_and_delta_method_agree_on_a_moderate_sample() -> None:
    a, b = pairs(np.random.default_rng(3), 48, 0.3)
    boot = paired_reduction(a, b, 0.95, 5000, seed=1)
    delta = delta_reduction(a, b, 0.95)
    assert boot.estimate == pytest.approx(delta.estimate)
    assert boot.low < boot.estimate < boot.high
    width = boot.high - boot.low
    assert abs(boot.low - delta.low) < 0.35 * width
    assert abs(boot.high - delta.high) < 0.35 * width


def test_pairing_narrows_the_interval() -> None:
    """The shared window difficulty cancels out: shuffling the pairs widens the interval."""
    rng = np.random.default_rng(5)
    a, b = pairs(rng, 32, 0.5)
    paired = paired_reduction(a, b, 0.95, 3000, seed=0)
    shuffled = paired_reduction(a, rng.permutation(b), 0.95, 3000, seed=0)
    assert paired.high - paired.low < 0.6 * (shuffled.high - shuffled.low)


def test_degenerate_samples_give_nan_bounds_not_errors() -> None:
    same = paired_reduction(np.ones(5), np.ones(5) * 0.5)
    assert same.estimate == pytest.approx(50.0)
    assert math.isnan(same.low)
    assert math.isnan(same.high)
    one = paired_reduction(np.array([2.0]), np.array([1.0]))
    assert math.isnan(one.low)
    m = mean_interval(np.array([1.0, 2.0, np.nan, 3.0, 4.0]), 0.95, 2000)
    assert m.estimate == pytest.approx(2.5)
    assert m.low < 2.5 < m.high
