"""Timeout resets (bad-inputs F2): a stream counts as accepted when half its blocks pass."""

from __future__ import annotations

import numpy as np

from navreplay.pipeline.estimation.core.gating import (
    stream_health,
    streams_to_reset,
    update_reject_since,
)
from navreplay.pipeline.estimation.ins.models.measurement import S_OBS

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
