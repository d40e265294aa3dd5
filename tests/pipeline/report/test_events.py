"""The log's own account as report rows and as the line ``analyze`` prints."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from navreplay.ingest.context import EventRows, events_table, vibration_table
from navreplay.ingest.schema import EventKind
from navreplay.pipeline.report import events
from navreplay.pipeline.report.inputs import DatasetInputs

T0 = 1_000_000_000_000


def _inputs() -> DatasetInputs:
    rows = EventRows()
    t = T0 + np.arange(6, dtype=np.int64) * 1_000_000_000
    rows.add(t[:2], EventKind.MODE, ["STABILIZE", "LOITER"], "MODE")
    rows.add(t[2:3], EventKind.MESSAGE, ["PreArm: Need 3D Fix"], "STATUSTEXT", [2])
    rows.add(t[3:4], EventKind.MESSAGE, ["Low battery"], "STATUSTEXT", [4])
    rows.add(t[4:5], EventKind.ERROR, ["GPS: error 2"], "ERR")
    rows.add(t[5:6], EventKind.EVENT, ["GPS: cleared"], "ERR")
    vib = {
        "t_ns": np.repeat(t[:3], 2),
        "imu": np.tile([0, 1], 3),
        "vibe_x_mps2": np.array([10.0, 5.0, 35.0, 5.0, 20.0, 5.0]),
        "vibe_y_mps2": np.full(6, 1.0),
        "vibe_z_mps2": np.full(6, 2.0),
        "clip_count": np.array([0.0, 3.0, 1.0, 3.0, 4.0, 7.0]),
    }
    return DatasetInputs("d", Path(), None, None, None, None, [],
                         events=events_table(rows), vibration=vibration_table([vib]))  # fmt: skip


def test_rows_keep_the_log_order_with_severity_names() -> None:
    rows = events.event_rows(_inputs())
    assert [r["kind"] for r in rows] == ["mode", "mode", "message", "message", "error", "event"]
    assert [r["severity"] for r in rows][2:4] == ["critical", "warning"]
    assert rows[1]["time_s"] == 1.0  # from the first row: no run gives another origin


def test_vibration_per_imu() -> None:
    by_imu = {r["imu"]: r for r in events.vibration_rows(_inputs())}
    assert by_imu[0]["vibe_max_mps2"] == 35.0
    assert by_imu[0]["above_30_frac"] == 1 / 3
    assert by_imu[0]["clips"] == 4.0  # the cumulative count rose from 0 to 4
    assert by_imu[1]["clips"] == 4.0


def test_the_summary_line_names_modes_errors_warnings_and_the_worst_vibration() -> None:
    data = _inputs()
    line = events.summary(events.event_rows(data), events.vibration_rows(data))
    assert line == (
        "modes STABILIZE > LOITER; 2 errors (PreArm: Need 3D Fix; GPS: error 2); "
        "1 warning (Low battery); vibration up to 35 m/s^2 (IMU 0); 8 clipping events"
    )
    assert events.summary([], []) is None
