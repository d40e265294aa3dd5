"""Time bases: leap seconds, GPS week/TOW, and reconciliation of several streams."""

from __future__ import annotations

import datetime as dt

import numpy as np
import pytest

from navreplay.ingest.errors import IngestError
from navreplay.ingest.timebase import (
    GPS_EPOCH_UNIX_NS,
    NS_PER_S,
    TimeBase,
    convert,
    gps_to_utc_ns,
    gps_week_tow_to_ns,
    leap_seconds_at_utc,
    reconcile,
    utc_to_gps_ns,
)


def _utc_ns(*args: int) -> int:
    when = dt.datetime(*args)  # type: ignore[arg-type]
    return int(when.replace(tzinfo=dt.UTC).timestamp()) * NS_PER_S


@pytest.mark.parametrize(
    ("when", "leap"),
    [
        ((1980, 1, 6), 0),
        ((1999, 1, 1), 13),
        ((2015, 5, 21), 16),  # the robot_localization drive
        ((2016, 12, 31, 23, 59, 59), 17),
        ((2017, 1, 1), 18),
        ((2024, 6, 1), 18),
    ],
)
def test_leap_seconds_at_known_dates(when: tuple[int, ...], leap: int) -> None:
    assert int(leap_seconds_at_utc(_utc_ns(*when))) == leap


def test_gps_epoch_and_a_known_week() -> None:
    # 1980-01-06 is GPS time 0; 2018-08-02 08:35 UTC (comma2k19) is GPS week 2012.
    assert int(utc_to_gps_ns(np.array([GPS_EPOCH_UNIX_NS]))[0]) == 0
    t = utc_to_gps_ns(np.array([_utc_ns(2018, 8, 2, 8, 35, 0)]))[0]
    week, tow_ns = divmod(int(t), 604_800 * NS_PER_S)
    assert week == 2012
    assert tow_ns / NS_PER_S == pytest.approx(4 * 86400 + 8 * 3600 + 35 * 60 + 18)
    assert int(gps_week_tow_to_ns(week, tow_ns)) == t


def test_utc_gps_round_trip_across_leap_second_boundaries() -> None:
    utc = np.array([_utc_ns(2016, 12, 31, 23, 59, 50) + k * NS_PER_S for k in range(20)])
    gps = utc_to_gps_ns(utc)
    np.testing.assert_array_equal(gps_to_utc_ns(gps), utc)
    np.testing.assert_array_equal(convert(gps, TimeBase.GPS, TimeBase.UTC), utc)


def test_reconcile_prefers_gps_and_reports_the_leap_count() -> None:
    r = reconcile(
        [("/imu", TimeBase.UTC), ("obs", TimeBase.GPS)], sample_utc_ns=_utc_ns(2024, 1, 1)
    )
    assert r.base == TimeBase.GPS
    assert r.leap_seconds == 18
    assert any("leap-second" in d for d in r.decisions)
    assert reconcile([("/imu", TimeBase.UTC)]).base == TimeBase.UTC


def test_recorder_clock_cannot_merge_with_wall_clock() -> None:
    with pytest.raises(IngestError, match="recorder clock"):
        reconcile([("IMU", TimeBase.RECORDER), ("/fix", TimeBase.UTC)])
    assert reconcile([("IMU", TimeBase.RECORDER)]).base == TimeBase.RECORDER


def test_utc_side_table_agrees_with_gpstime_outside_leap_seconds() -> None:
    from navreplay.ingest import gpstime

    rng = np.random.default_rng(0)
    gps = rng.integers(0, 46 * 365 * 86400, 5000).astype(np.int64) * NS_PER_S + 123
    np.testing.assert_array_equal(utc_to_gps_ns(gpstime.utc_unix_ns_from_gps(gps)), gps)
    utc = gpstime.utc_unix_ns_from_gps(gps)
    np.testing.assert_array_equal(leap_seconds_at_utc(utc), gpstime.leap_seconds(gps))
