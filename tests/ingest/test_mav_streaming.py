"""The block-wise helpers of the autopilot readers give the same answer however a log is cut
into blocks: boot segments, median clock offsets, the nearest-time join."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from navreplay.ingest.readers.asof import AsofJoin, Left
from navreplay.ingest.readers.mavlink.mavclock import (
    RESET_DROP_NS,
    ROLLOVER_WEEKS,
    BootTracker,
    OffsetAccumulator,
    unroll_gps_week,
)
from navreplay.ingest.timebase import NS_PER_S, SECONDS_PER_WEEK


def _cuts(n: int, rng: np.random.Generator, parts: int) -> list[int]:
    return [0, *sorted(rng.choice(np.arange(1, n), parts - 1, replace=False).tolist()), n]


@pytest.mark.parametrize("seed", range(5))
def test_boot_segments_do_not_depend_on_block_boundaries(seed: int) -> None:
    rng = np.random.default_rng(seed)
    boots = [np.arange(300) * 20_000_000 + 600 * NS_PER_S, np.arange(1000) * 20_000_000]
    boots.append(np.arange(100) * 20_000_000 + NS_PER_S // 2)  # a third boot, 0.5 s in
    clock = np.concatenate(boots)
    clock[50] -= 2 * NS_PER_S  # a late packet: not a reboot
    offsets = np.arange(len(clock), dtype=np.int64) * 40
    whole = BootTracker()
    whole.push(offsets, clock)
    split = BootTracker()
    cuts = _cuts(len(clock), rng, 7)
    for a, b in itertools.pairwise(cuts):
        split.push(offsets[a:b], clock[a:b])
    assert whole.starts == split.starts == [0, 300 * 40, 1300 * 40]
    assert whole.resets == split.resets
    assert (whole.segment_of(offsets) == np.repeat([0, 1, 2], [300, 1000, 100])).all()
    assert RESET_DROP_NS > 2 * NS_PER_S


def test_offset_median_is_the_weighted_median_of_block_medians() -> None:
    rng = np.random.default_rng(1)
    acc = OffsetAccumulator()
    values = rng.normal(1000, 10, 9000).astype(np.int64)
    values[::97] += 10**9  # outliers the median ignores
    for part in np.array_split(values, 9):
        acc.add(np.zeros(len(part), np.int64), part)
    assert acc.count(0) == 9000
    med = acc.median(0)
    assert med is not None
    assert abs(med - 1000) < 5
    assert acc.median(1) is None


def test_week_rollover_snaps_to_the_nearest_epoch() -> None:
    week = np.array([2269 - 1024, 2269 - 1024])
    tow = np.array([0, 200_000_000])
    ref = 2270 * SECONDS_PER_WEEK * NS_PER_S
    fixed, added = unroll_gps_week(week, tow, ref)
    assert added == ROLLOVER_WEEKS
    assert (fixed == 2269).all()
    same, none = unroll_gps_week(np.array([2269]), np.array([0]), ref)
    assert none == 0
    assert same[0] == 2269


@pytest.mark.parametrize("seed", range(4))
def test_streaming_join_equals_a_join_of_everything(seed: int) -> None:
    rng = np.random.default_rng(seed)
    t_left = np.cumsum(rng.integers(50, 150, 400)) * 1_000_000
    t_right = np.sort(rng.choice(t_left.max() + 200_000_000, 600, replace=False)).astype(np.int64)
    right = {"roll_rad": rng.normal(size=600)}

    def left(idx: slice) -> Left:
        cols = {"x": np.arange(400, dtype=float)[idx]}
        return Left(t_left[idx], cols, {}, np.arange(400, dtype=np.int64)[idx])

    once = AsofJoin(("roll_rad",), 30_000_000)
    once.push_right(t_right, right)
    once.push_left(left(slice(None)))
    ref = once.pop(final=True)
    assert ref is not None
    streamed = AsofJoin(("roll_rad",), 30_000_000)
    out: list[Left] = []
    lc, rc = _cuts(400, rng, 6), _cuts(600, rng, 6)
    for (a, b), (c, d) in zip(itertools.pairwise(lc), itertools.pairwise(rc), strict=True):
        streamed.push_right(t_right[c:d], {"roll_rad": right["roll_rad"][c:d]})
        streamed.push_left(left(slice(a, b)))
        if (got := streamed.pop()) is not None:
            out.append(got)
    if (got := streamed.pop(final=True)) is not None:
        out.append(got)
    t = np.concatenate([o.t for o in out])
    np.testing.assert_array_equal(t, ref.t)
    np.testing.assert_array_equal(
        np.concatenate([o.columns["roll_rad"] for o in out]), ref.columns["roll_rad"]
    )
    np.testing.assert_array_equal(
        np.concatenate([o.nulls["roll_rad"] for o in out]), ref.nulls["roll_rad"]
    )
    assert streamed.matched == once.matched > 0
    assert once.unmatched > 0  # some left rows have no partner within 30 ms: null
