"""Timeout resets (bad-inputs F2): a stream counts as accepted when half its blocks pass."""

from __future__ import annotations

import numpy as np

from navreplay.pipeline.estimation.core.gating import (
    new_stream_clock,
    returning_to_reset,
    stream_health,
    streams_to_reset,
    update_reject_since,
    update_stream_clock,
)
from navreplay.pipeline.estimation.ins.models.measurement import S_NHC, S_OBS, S_POS

NS = 1_000_000_000


def _blocks(n: int) -> np.ndarray:
    blocks = np.zeros((n, 4), dtype=np.int64)
    blocks[:, 2] = S_OBS
    return blocks


def test_a_few_satellites_passing_do_not_make_the_epoch_accepted() -> None:
    blocks = _blocks(8)
    accepted = np.array([1, 1, 0, 0, 0, 0, 0, 0], dtype=np.int64)
    seen, ok = stream_health(blocks, 8, accepted)
    assert seen[S_OBS] == 1
    assert ok[S_OBS] == 0
    accepted[:4] = 1
    _, ok = stream_health(blocks, 8, accepted)
    assert ok[S_OBS] == 1


def test_a_step_rejected_on_most_satellites_resets_after_the_timeout() -> None:
    blocks = _blocks(8)
    accepted = np.array([1, 0, 0, 0, 0, 0, 0, 1], dtype=np.int64)
    since = np.full(len(stream_health(blocks, 8, accepted)[0]), -1, dtype=np.int64)
    for k in range(6):  # 1 Hz epochs, timeout 5 s
        t = k * NS
        reset = streams_to_reset(t, blocks, 8, accepted, since, 5.0, -1)
        assert reset[S_OBS] == (1 if k == 5 else 0)
        update_reject_since(t, blocks, 8, accepted, since)


def _epochs(accepted_at: dict[float, int], epochs: int = 2) -> list[float]:
    """Feed one position block per epoch (time s -> accepted); the times a returning reset
    fires (a reset leaves the epoch accepted, as the filter's second gating does)."""
    blocks = np.zeros((1, 4), dtype=np.int64)
    blocks[0, 1], blocks[0, 2] = 3, S_POS
    clock = new_stream_clock(0)
    fired = []
    for t_s, ok in accepted_at.items():
        acc = np.array([ok], dtype=np.int64)
        t = round(t_s * NS)
        if returning_to_reset(t, blocks, 1, acc, clock, 5.0, epochs, 5.0, S_NHC)[S_POS]:
            fired.append(t_s)
            clock[2, S_POS] = 0
            acc[0] = 1
        update_stream_clock(t, blocks, 1, acc, clock, 5.0, 5.0)
    return fired


def test_a_stream_back_from_an_outage_resets_at_its_second_rejected_epoch() -> None:
    before = {float(k): 1 for k in range(10)}
    assert _epochs(before | {40.0: 0, 41.0: 0, 42.0: 1}) == [41.0]
    assert _epochs(before | {40.0: 0, 41.0: 1}, epochs=1) == [40.0]
    assert _epochs(before | {40.0: 0, 41.0: 1}) == []  # one rejection: not a run
    # accepted once on its return, then rejected: still within the timeout of the return
    assert _epochs(before | {40.0: 1, 41.0: 0, 42.0: 0}) == [42.0]
    assert _epochs(before | {40.0: 1, 41.0: 1, 42.0: 1, 43.0: 1, 44.0: 1, 46.0: 0}) == []


def test_outliers_without_an_outage_keep_the_timeout() -> None:
    epochs = {float(k): 1 for k in range(20)} | {20.0: 0, 21.0: 0, 22.0: 0, 23.0: 1}
    assert _epochs(epochs) == []
    # a gap shorter than return_gap_s (intermittent fixes, F6) is no outage
    assert _epochs({float(k): 1 for k in range(11)} | {13.0: 0, 14.0: 0}) == []
