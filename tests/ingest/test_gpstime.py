"""GPS time: leap seconds, UTC stamps, weeks."""

from __future__ import annotations

import numpy as np

from navreplay.ingest import gpstime as gt


def test_leap_seconds_follow_the_iers_table() -> None:
    assert int(gt.leap_seconds(0)) == 0
    assert int(gt.leap_seconds(gt.gps_from_calendar("2016-08-22T23:50:00"))) == 17
    assert int(gt.leap_seconds(gt.gps_from_calendar("2026-11-18T02:30:00"))) == 18
    # 2017-01-01T00:00:00 UTC is 2017-01-01T00:00:18 GPS: the 18th second starts there
    edge = gt.gps_from_calendar("2017-01-01T00:00:18")
    assert gt.leap_seconds(np.array([edge - 1, edge])).tolist() == [17, 18]


def test_utc_stamps_are_gps_minus_leap_seconds() -> None:
    t = gt.gps_from_calendar("2026-11-18T02:30:00")
    utc = int(gt.utc_unix_ns_from_gps(t))
    assert np.datetime64(utc, "ns") == np.datetime64("2026-11-18T02:29:42", "ns")
    assert np.datetime64("1980-01-06", "ns").astype(np.int64) == gt.GPS_EPOCH_UNIX_NS


def test_week_and_seconds_and_calendar_round_trip() -> None:
    t = gt.gps_from_calendar("2026-11-18T02:30:00")
    week, sow = gt.week_and_seconds(t)
    assert week == 2445  # continuous GPS week (Sunday 2026-11-15)
    assert sow == 3 * 86400 + 2.5 * 3600
    assert str(gt.calendar_from_gps(t)) == "2026-11-18T02:30:00.000000000"
