"""Stream hygiene and audit statistics (catalogue cases 29-33): counts equal what was injected."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from navreplay.ingest.audit import StreamAudit
from navreplay.ingest.errors import CorruptLogError
from navreplay.ingest.hygiene import Rows, StreamCleaner

W_NS = 1_000_000_000  # the reorder window of params.yaml
DT = 10_000_000  # 100 Hz
P = Path("log.mcap")


def _series(n: int) -> tuple[np.ndarray, np.ndarray]:
    t = 10**18 + np.arange(n, dtype=np.int64) * DT
    return t, np.arange(n, dtype=np.float64)


def clean(
    t: np.ndarray, v: np.ndarray, *, seed: int = 0, strict: bool = False
) -> tuple[Rows, StreamCleaner, StreamAudit]:
    """Push in batches of random size (1..300) to exercise every batch boundary."""
    rng = np.random.default_rng(seed)
    cleaner = StreamCleaner("s", W_NS, strict=strict)
    audit = StreamAudit()
    out: list[Rows] = []
    i = 0
    while i < len(t):
        k = min(int(rng.integers(1, 300)), len(t) - i)
        rows = Rows({"t_ns": t[i : i + k].copy(), "v": v[i : i + k].copy()}, np.arange(i, i + k))
        out.append(cleaner.push(rows, P))
        i += k
    out.append(cleaner.finish(P))
    for r in out:
        audit.observe(r.columns, r.offsets)
    return Rows.concat(out), cleaner, audit


def _assert_strictly_increasing(rows: Rows) -> None:
    assert (np.diff(rows.t) > 0).all()


def test_clean_stream_passes_unchanged() -> None:
    t, v = _series(2000)
    rows, cleaner, audit = clean(t, v)
    np.testing.assert_array_equal(rows.t, t)
    np.testing.assert_array_equal(rows.columns["v"], v)
    rep = audit.report(5.0)
    assert rep["rate_hz"] == pytest.approx(100.0)
    assert rep["jitter_ms"] == 0.0
    assert rep["gaps"]["count"] == 0
    assert cleaner.counts.reordered == 0


def test_swapped_neighbours_within_the_window_are_resorted_and_counted() -> None:
    # Case 29: swap 1 % of neighbouring samples.
    t, v = _series(3000)
    swaps = np.arange(50, 3000, 100)  # 30 swaps
    for i in swaps:
        t[[i, i + 1]] = t[[i + 1, i]]
        v[[i, i + 1]] = v[[i + 1, i]]
    rows, cleaner, _ = clean(t, v)
    _assert_strictly_increasing(rows)
    assert len(rows) == 3000
    assert cleaner.counts.reordered == len(swaps)
    np.testing.assert_array_equal(rows.columns["v"], np.arange(3000))


def test_late_samples_inside_the_window_are_kept_older_ones_dropped() -> None:
    # Case 29: 20 samples arrive 0.4 s late (kept), 5 arrive 2 s late (dropped, W = 1 s).
    t, v = _series(4000)
    order = list(range(4000))
    late_ok = list(range(100, 2100, 100))  # 20
    late_bad = [2500, 2800, 3100, 3400, 3700]
    for i, delay in [(i, 40) for i in late_ok] + [(i, 200) for i in late_bad]:
        order.remove(i)
        order.insert(order.index(i + delay), i)
    rows, cleaner, _ = clean(t[order], v[order])
    _assert_strictly_increasing(rows)
    assert cleaner.counts.dropped_late == 5
    assert cleaner.counts.reordered == 20
    assert len(rows) == 4000 - 5
    assert sorted(cleaner.counts.dropped_late_offsets) == sorted(order.index(i) for i in late_bad)


def test_duplicate_stamps_exact_dropped_conflicting_flagged() -> None:
    # Case 30: 10 % of samples share the previous stamp.
    t, v = _series(1000)
    dup_conflicting = np.arange(10, 1000, 20)  # 50: same time, other value
    dup_exact = np.arange(20, 1000, 20)  # 49: same time, same value
    t = t.copy()
    t[dup_conflicting] = t[dup_conflicting - 1]
    t[dup_exact] = t[dup_exact - 1]
    v = v.copy()
    v[dup_exact] = v[dup_exact - 1]
    rows, cleaner, _ = clean(t, v)
    _assert_strictly_increasing(rows)
    assert cleaner.counts.duplicates_conflicting == len(dup_conflicting)
    assert cleaner.counts.duplicates_exact == len(dup_exact)
    assert len(rows) == 1000 - len(dup_conflicting) - len(dup_exact)
    # The first arrival is kept.
    kept = dict(zip(rows.t.tolist(), rows.columns["v"].tolist(), strict=True))
    assert kept[int(t[10])] == 9.0


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_clock_step_backwards_splits_and_rebases_never_negative_dt(seed: int) -> None:
    # Case 31: subtract 5 s from every stamp after index k.
    t, v = _series(3000)
    k = 1234
    t[k:] -= 5 * 10**9
    rows, cleaner, audit = clean(t, v, seed=seed)
    _assert_strictly_increasing(rows)
    assert len(rows) == 3000
    np.testing.assert_array_equal(rows.columns["v"], v)
    (step,) = cleaner.counts.steps
    assert step.offset == k
    assert step.step_ns == -5 * 10**9 + DT  # dt across the step
    assert step.shift_ns == 5 * 10**9
    assert rows.t[k] - rows.t[k - 1] == DT  # re-based: one nominal period after the last
    assert audit.report(5.0)["gaps"]["count"] == 0


def test_clock_step_backwards_under_strict_is_an_error() -> None:
    t, v = _series(500)
    t[300:] -= 5 * 10**9
    with pytest.raises(CorruptLogError) as err:
        clean(t, v, strict=True)
    assert err.value.offset == 300
    assert "backwards" in str(err.value)


def test_forward_jump_is_a_gap_and_a_segment_boundary() -> None:
    # Case 32: +1 h after index k.
    t, v = _series(2000)
    t[800:] += 3600 * 10**9
    rows, _, audit = clean(t, v)
    assert len(rows) == 2000
    rep = audit.report(5.0)
    assert rep["gaps"]["count"] == 1
    (seg,) = rep["segments"]
    assert seg["jump_s"] == pytest.approx(3600.01)
    assert seg["offset"] == 800


def test_two_second_gap_is_reported_once() -> None:
    # Case 33: delete 2 s of samples from a 100 Hz stream.
    t, v = _series(3000)
    keep = np.ones(3000, bool)
    keep[1000:1200] = False
    _, _, audit = clean(t[keep], v[keep])
    rep = audit.report(5.0)
    assert rep["gaps"]["count"] == 1
    assert rep["gaps"]["longest_s"] == pytest.approx(2.01)
    assert rep["gaps"]["first"][0]["offset"] == 1000
    assert rep["segments"] == []
    assert rep["rate_hz"] == pytest.approx(100.0)


def test_nan_and_inf_are_counted_and_inf_becomes_nan() -> None:
    # Case 21: invalid stays NaN (never null), and is counted.
    audit = StreamAudit()
    cols = {"t_ns": np.arange(5, dtype=np.int64), "v": np.array([1.0, np.nan, np.inf, -np.inf, 2])}
    audit.observe(cols, np.arange(5))
    assert audit.nonfinite == {"v": {"nan": 1, "inf": 2}}
    assert np.isnan(cols["v"][1:4]).all()


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.integers(-3_000, 3_000), min_size=1, max_size=400),
    st.integers(0, 2**31),
)
def test_any_input_leaves_strictly_increasing_and_every_row_accounted(
    jitter_ms: list[int], seed: int
) -> None:
    base = 10**18 + np.arange(len(jitter_ms), dtype=np.int64) * 50_000_000
    t = base + np.asarray(jitter_ms, np.int64) * 1_000_000
    v = np.arange(len(t), dtype=np.float64)
    rows, cleaner, _ = clean(t, v, seed=seed)
    _assert_strictly_increasing(rows)
    c = cleaner.counts
    assert c.rows_in == len(t)
    assert c.rows_out == len(rows)
    assert len(t) == len(rows) + c.dropped_late + c.duplicates_exact + c.duplicates_conflicting


def test_decimated_jittery_stream_reports_its_actual_rate_and_jitter() -> None:
    # Case 34: logged at 50 Hz from 400 Hz, with +-2 ms of timing jitter.
    rng = np.random.default_rng(3)
    t, v = _series(8000)
    t = t[::8] + rng.integers(-2_000_000, 2_000_001, 1000)
    _, _, audit = clean(t, v[::8])
    rep = audit.report(5.0)
    assert rep["rate_hz"] == pytest.approx(12.5, rel=0.02)  # 100 Hz base series / 8
    assert 0.5 < rep["jitter_ms"] < 3.0
    assert rep["gaps"]["count"] == 0


def test_a_secondary_key_keeps_every_satellite_of_an_epoch_and_sorts_by_it() -> None:
    # gnss_obs: many rows share t_ns; only a repeated (t_ns, sv) is a duplicate.
    rng = np.random.default_rng(4)
    n_ep, svs = 50, np.array(["G01", "G07", "G12", "R03"])
    t = np.repeat(10**18 + np.arange(n_ep, dtype=np.int64) * DT, svs.size)
    sv = np.tile(svs, n_ep)
    order = np.concatenate([rng.permutation(np.arange(k, k + 4)) for k in range(0, t.size, 4)])
    t, sv = t[order], sv[order]  # satellites of an epoch in any order
    v = np.arange(t.size, dtype=np.float64)
    t = np.concatenate([t, t[[9, 30]]])  # two rows repeated: one exactly, one with a new value
    sv = np.concatenate([sv, sv[[9, 30]]])
    v = np.concatenate([v, [v[9], -1.0]])
    cleaner = StreamCleaner("obs", W_NS, strict=False, secondary="sv")
    parts = [
        cleaner.push(Rows({"t_ns": t[a:b], "sv": sv[a:b], "v": v[a:b]}, np.arange(a, b)), P)
        for a, b in ((0, 77), (77, t.size))
    ]
    rows = Rows.concat([*parts, cleaner.finish(P)])
    assert len(rows) == n_ep * svs.size
    keys = list(zip(rows.t.tolist(), rows.columns["sv"].tolist(), strict=True))
    assert keys == sorted(set(keys))
    assert cleaner.counts.duplicates_exact == 1
    assert cleaner.counts.duplicates_conflicting == 1
    assert cleaner.counts.reordered == 2  # the repeats arrived late; shuffled sats are not
