"""Outage scenarios fitted to the log at hand (``pipeline.scenarios.fit``), and ``--outage``."""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pytest

from navreplay.pipeline.estimation.core.windows import NS
from navreplay.pipeline.params import load_params
from navreplay.pipeline.scenarios.apply import apply_scenario
from navreplay.pipeline.scenarios.config import FitParams, ScenarioSpec, WindowsSpec
from navreplay.pipeline.scenarios.fit import (
    aided_span,
    fit_scenarios,
    fit_windows,
    parse_outage,
    with_outages,
)

FIT = FitParams()
T0 = 1_700_000_000 * NS
SIXTY = WindowsSpec(
    placement="random", length_s=60.0, count=5, seed=1, earliest_s=120.0, min_gap_s=60.0,
    tail_s=30.0,
)  # fmt: skip


def tables(
    span_s: float, fix_from_s: float = 0.0, fix_to_s: float | None = None
) -> dict[str, pa.Table]:
    """An IMU of ``span_s`` at 100 Hz and 3-D fixes at 5 Hz over ``[fix_from_s, fix_to_s]``."""
    t_imu = T0 + np.arange(0, round(span_s * 100) + 1) * (NS // 100)
    t_fix = T0 + np.arange(0, round(span_s * 5) + 1) * (NS // 5)
    s = (t_fix - T0) / NS
    fix_type = np.where(
        (s >= fix_from_s) & (s <= (fix_to_s if fix_to_s is not None else span_s)), 3, 1
    )
    return {
        "imu": pa.table({"t_ns": pa.array(t_imu, pa.int64())}),
        "gnss": pa.table(
            {"t_ns": pa.array(t_fix, pa.int64()), "fix_type": pa.array(fix_type, pa.int8())}
        ),
    }


def test_parse_outage_reads_lengths_and_starts() -> None:
    name, spec = parse_outage("30s", FIT)
    assert name == "outage_30s"
    assert spec.windows is not None
    assert spec.windows.placement == "random"
    assert (spec.windows.length_s, spec.windows.count) == (30.0, FIT.max_windows)
    name, spec = parse_outage("20s@45s", FIT)
    assert name == "outage_20s_at_45s"
    assert spec.windows == WindowsSpec(placement="explicit", length_s=20.0, starts_s=(45.0,))
    name, spec = parse_outage(" 2min @ 1.5min ", FIT)
    assert name == "outage_120s_at_90s"
    assert parse_outage("12.5", FIT)[0] == "outage_12.5s"


@pytest.mark.parametrize("bad", ["", "s", "-5s", "0s", "30 s@", "30h", "@45s", "thirty"])
def test_parse_outage_says_what_it_accepts(bad: str) -> None:
    with pytest.raises(ValueError, match=r"30s@45s"):
        parse_outage(bad, FIT)


def test_windows_that_fit_are_left_as_they_are() -> None:
    assert fit_windows(SIXTY, 900.0, (0.0, 900.0), FIT) == (SIXTY, None)
    explicit = WindowsSpec(placement="explicit", length_s=60.0, starts_s=(500.0,))
    assert fit_windows(explicit, 100.0, (0.0, 100.0), FIT) == (explicit, None)


def test_a_short_log_gets_fewer_windows_with_shorter_margins() -> None:
    fitted, note = fit_windows(SIXTY, 300.0, (0.0, 300.0), FIT)
    assert fitted is not None
    assert note is not None
    # settle 30 s after the first fix, end 10 s before the last: [30, 290] holds 2 x (60 + 60)
    assert (fitted.length_s, fitted.count, fitted.earliest_s, fitted.latest_s) == (
        60.0,
        2,
        30.0,
        290.0,
    )
    assert "placed 2 window(s) between 30.0 and 290.0 s" in note


def test_a_log_too_short_for_the_length_gets_the_longest_that_fits() -> None:
    fitted, note = fit_windows(SIXTY, 104.0, (5.0, 104.0), FIT)
    assert fitted is not None
    assert note is not None
    assert (fitted.length_s, fitted.count) == (30.0, 1)  # [35, 94]: 59 s of room
    assert "shortened to 30 s" in note
    fitted, _ = fit_windows(SIXTY, 60.0, (0.0, 60.0), FIT)
    assert fitted is not None
    assert fitted.length_s == 10.0  # [30, 50]


def test_no_window_fits_a_log_without_room_or_gnss() -> None:
    windows, why = fit_windows(SIXTY, 40.0, (0.0, 40.0), FIT)
    assert windows is None
    assert why is not None
    assert "even 10 s needs 30 s of settling" in why
    assert fit_windows(SIXTY, 900.0, None, FIT) == (None, "the log has no GNSS fix to take away")


def test_windows_lie_where_the_log_has_fixes() -> None:
    t = tables(600.0, fix_from_s=200.0, fix_to_s=400.0)
    assert aided_span(t, T0) == pytest.approx((200.0, 400.0))
    fitted, _ = fit_windows(SIXTY, 600.0, aided_span(t, T0), FIT)
    assert fitted is not None
    applied = apply_scenario(t, "x", ScenarioSpec(windows=fitted))
    for w in applied.outage_windows:
        assert (w.start_ns - T0) / NS >= 230.0
        assert (w.end_ns - T0) / NS <= 390.0


def test_fit_scenarios_adapts_names_the_changes_once_and_drops_what_cannot_fit() -> None:
    params = load_params()
    scenarios, extra = with_outages(params.scenarios, ["20s", "5s@2s"])
    names = ["nominal", "outage_60s", "sats_2", *extra]
    fitted = fit_scenarios(tables(104.0), scenarios, names, as_many_as_fit=extra)
    (note,) = fitted.notes  # outage_60s and sats_2 changed alike: one line for both
    assert note.startswith("outage_60s, sats_2: 5 window(s) of 60 s need 120 s of settling")
    assert "--outage LEN[@START]" in note
    assert fitted.scenarios.named["nominal"] == scenarios.named["nominal"]
    sixty = fitted.scenarios.named["outage_60s"].windows
    assert sixty is not None
    assert (sixty.length_s, sixty.count) == (60.0, 1)  # [30, 94]
    twenty = fitted.scenarios.named["outage_20s"].windows
    assert twenty is not None
    assert (twenty.length_s, twenty.count) == (20.0, 1)  # [30, 94]
    assert fitted.scenarios.named["outage_5s_at_2s"] == scenarios.named["outage_5s_at_2s"]
    assert dict(fitted.unfit) == {}
    short = fit_scenarios(tables(30.0), scenarios, names)
    assert set(short.unfit) == {"outage_60s", "sats_2", "outage_20s"}
