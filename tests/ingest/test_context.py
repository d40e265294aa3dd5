"""The log's context (``ingest.context``): messages, modes, arming, events, errors and
vibration, from logs written here with the formats' own encoders and from the real logs."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from navreplay.ingest.api import ingest, inspect
from navreplay.ingest.context import EventRows, events_table, forward, vibration_table
from navreplay.ingest.schema import EventKind
from navreplay.ingest.tables import read_table
from tests.ingest.mavlogs import BOOT_US, UTC0_US, df_drive, mav, tlog_drive, ulog_drive

SHARED = Path(__file__).resolve().parents[3] / "shared" / "data"


def _events(out: Path) -> pd.DataFrame:
    frame: pd.DataFrame = read_table(out / "events.parquet", "events").table.to_pandas()
    return frame


def _vibration(out: Path) -> pd.DataFrame:
    frame: pd.DataFrame = read_table(out / "vibration.parquet", "vibration").table.to_pandas()
    return frame


# ------------------------------------------------------------------------------ the table
def test_events_sort_by_time_keep_the_log_order_at_one_instant_and_drop_exact_repeats() -> None:
    rows = EventRows()
    t = np.array([20, 10, 10], np.int64)
    rows.add(t, EventKind.MESSAGE, ["c", "a", "b"], "MSG", [6, None, 4])
    rows.add(np.array([10], np.int64), EventKind.MESSAGE, ["a"], "MSG", [None])  # a repeat
    table = events_table(rows).to_pandas()
    assert table["text"].tolist() == ["a", "b", "c"]
    assert table["seq"].tolist() == [0, 1, 0]
    assert table["severity"].isna().tolist() == [True, False, False]


def test_a_state_series_is_read_forward_only() -> None:
    # a log copied twice into one file repeats its start: those rows are not new changes
    assert forward(np.array([1, 2, 3, 1, 2, 4, 5])).tolist() == [1, 1, 1, 0, 0, 1, 1]


def test_arming_events_give_way_to_the_arm_record() -> None:
    rows = EventRows()
    rows.add(np.array([5], np.int64), EventKind.ARMING, ["disarmed"], "EV")
    rows.add(np.array([5], np.int64), EventKind.ARMING, ["disarmed"], "ARM")
    rows.add(np.array([6], np.int64), EventKind.EVENT, ["land complete"], "EV")
    rows.drop(EventKind.ARMING, "EV")
    assert list(zip(rows.kind, rows.source, strict=True)) == [("arming", "ARM"), ("event", "EV")]


def test_vibration_of_no_file_is_no_table() -> None:
    assert vibration_table([]) is None
    assert vibration_table([{}]) is None


# ------------------------------------------------------------------------------- tlog
SCRIPT = "<script>alert(1)</script>"


def test_tlog_statustext_heartbeat_and_vibration(tmp_path: Path) -> None:
    log = tlog_drive()
    link = mav()
    gcs = mav(255, 190)
    stamp = UTC0_US + 500_000
    beats = (  # (base_mode, custom_mode): copter STABILIZE disarmed, armed, then LOITER
        (81, 0), (81, 0), (81 | 128, 0), (81 | 128, 5), (81 | 128, 5), (81, 5),
    )  # fmt: skip
    for i, (base, custom) in enumerate(beats):
        t = stamp + i * 500_000
        log.add(t, link, link.heartbeat_encode(2, 3, base, custom, 4, 3))
        log.add(t, gcs, gcs.heartbeat_encode(6, 8, 0, 0, 0, 3))  # the ground station's: not ours
    log.add(stamp + 10, link, link.statustext_encode(4, SCRIPT.encode()))
    log.add(stamp + 20, link, link.statustext_encode(6, b"EKF3 IMU0 is using GPS"))
    for i in range(3):
        boot_us = BOOT_US + 1_000_000 + i * 100_000
        vib = link.vibration_encode(boot_us, 3.5 + i, 4.0, 31.0, 0, i, 0)
        log.add(UTC0_US + boot_us - BOOT_US + 3_000, link, vib)
    # the tlog holds records in stamp order
    order = np.argsort(log.stamps_us, kind="stable")
    records = [log.records()[i] for i in order]
    path = log.write(tmp_path / "drive.tlog", records)
    out = tmp_path / "out"
    result = ingest([path], out)
    assert result.tables["events"] == 7
    ev = _events(out)
    assert list(zip(ev["kind"], ev["text"], ev["source"], strict=True)) == [
        ("mode", "STABILIZE", "HEARTBEAT"),
        ("arming", "disarmed", "HEARTBEAT"),
        ("message", SCRIPT, "STATUSTEXT"),  # stored as logged; the page escapes it
        ("message", "EKF3 IMU0 is using GPS", "STATUSTEXT"),
        ("arming", "armed", "HEARTBEAT"),
        ("mode", "LOITER", "HEARTBEAT"),
        ("arming", "disarmed", "HEARTBEAT"),
    ]
    assert ev.loc[ev["source"] == "STATUSTEXT", "severity"].tolist() == [4, 6]
    assert ev.loc[ev["source"] == "HEARTBEAT", "severity"].isna().all()
    beat_s = (ev.loc[ev["source"] == "HEARTBEAT", "t_ns"].diff().dropna() / 1e9).round(3)
    assert beat_s.tolist() == [0.0, 1.0, 0.5, 1.0]  # each at its own heartbeat
    vib = _vibration(out)
    assert len(vib) == 9  # three messages, a row per accelerometer
    imu0 = vib[vib["imu"] == 0]
    np.testing.assert_allclose(imu0["vibe_x_mps2"], [3.5, 4.5, 5.5], rtol=1e-6)
    np.testing.assert_allclose(imu0["vibe_z_mps2"], 31.0, rtol=1e-6)
    assert vib.loc[vib["imu"] == 1, "clip_count"].tolist() == [0.0, 1.0, 2.0]
    assert vib.loc[vib["imu"] == 1, "vibe_x_mps2"].isna().all()  # levels are IMU 0's
    assert np.all(np.diff(vib["t_ns"]) >= 0)
    # --list says where these messages went
    (inventory,), _ = inspect([path])
    detail = {s.key: s.detail for s in inventory.streams}
    assert detail["STATUSTEXT"] == "events table (context)"
    assert detail["VIBRATION"] == "vibration table (context)"


# -------------------------------------------------------------------------------- DataFlash
_DF_CONTEXT = {
    "MSG": (91, "QZ", "TimeUS,Message"),
    "MODE": (92, "QMBB", "TimeUS,Mode,ModeNum,Rsn"),
    "ARM": (93, "QBIBB", "TimeUS,ArmState,ArmChecks,Forced,Method"),
    "EV": (94, "QB", "TimeUS,Id"),
    "ERR": (95, "QBB", "TimeUS,Subsys,ECode"),
}
_VIBE_NEW = (96, "QBfffI", "TimeUS,IMU,VibeX,VibeY,VibeZ,Clip")
_VIBE_OLD = (96, "QfffIII", "TimeUS,VibeX,VibeY,VibeZ,Clip0,Clip1,Clip2")


def _df_with_context(path: Path, vibe: tuple[int, str, str]) -> Path:
    log = df_drive()  # at rest from TimeUS 50 s for 4 s
    for name, spec in _DF_CONTEXT.items():
        log.fmt(name, spec)
    log.fmt("VIBE", vibe)
    t = 50_500_000
    log.write("MSG", t, b"ArduCopter V4.3.6 (0c5e999c)".ljust(64, b"\0"))
    log.write("MODE", t + 1, 0, 0, 1)  # STABILIZE
    log.write("ARM", t + 2, 1, 0, 0, 2)
    log.write("EV", t + 3, 10)  # armed: the ARM record says it already
    log.write("MODE", t + 1_000_000, 5, 5, 2)  # LOITER
    log.write("MODE", t + 1_100_000, 5, 5, 2)  # re-entered: no change
    log.write("ERR", t + 1_500_000, 11, 2)  # GPS glitch
    log.write("ERR", t + 1_600_000, 11, 0)
    log.write("EV", t + 2_000_000, 62)
    log.write("EV", t + 2_100_000, 200)  # an id this navreplay does not name
    log.write("ARM", t + 3_000_000, 0, 0, 0, 17)
    log.write("EV", t + 3_000_001, 11)
    for i in range(3):
        ti = t + i * 100_000
        if vibe is _VIBE_NEW:
            for imu in (0, 1):
                log.write("VIBE", ti, imu, 1.0 + imu, 2.0, 35.0 + i, i * imu)
        else:
            log.write("VIBE", ti, 1.0, 2.0, 35.0 + i, 0, i, 2 * i)
    return log.save(path)


def test_dataflash_messages_modes_arming_events_and_errors(tmp_path: Path) -> None:
    out = tmp_path / "out"
    path = _df_with_context(tmp_path / "f.bin", _VIBE_NEW)
    ingest([path], out)
    (inventory,), _ = inspect([path])
    detail = {s.key: s.detail for s in inventory.streams}
    assert detail["MODE"] == "events table (context)"
    assert detail["VIBE"] == "vibration table (context)"
    ev = _events(out)
    assert list(zip(ev["kind"], ev["text"], ev["source"], strict=True)) == [
        ("message", "ArduCopter V4.3.6 (0c5e999c)", "MSG"),
        ("mode", "STABILIZE", "MODE"),  # named from the copter's table (the MSG banner)
        ("arming", "armed", "ARM"),
        ("mode", "LOITER", "MODE"),
        ("error", "GPS: error 2", "ERR"),
        ("event", "GPS: cleared", "ERR"),  # the clearing of an error is no error
        ("event", "EKF yaw reset", "EV"),
        ("event", "event 200", "EV"),
        ("arming", "disarmed", "ARM"),
    ]
    assert ev["severity"].isna().all()  # DataFlash MSG carries none
    gnss = read_table(out / "gnss.parquet", "gnss").table.column("t_ns").to_numpy()
    # on the dataset's GPS time: the first GPS record is at TimeUS 50.000010 s
    assert ev["t_ns"].iloc[0] - gnss[0] == pytest.approx(0.5e9 - 10_000, abs=1)
    vib = _vibration(out)
    assert vib["imu"].tolist() == [0, 1] * 3
    assert vib.loc[vib["imu"] == 1, "clip_count"].tolist() == [0.0, 1.0, 2.0]
    np.testing.assert_allclose(vib.loc[vib["imu"] == 1, "vibe_x_mps2"], 2.0)


def test_dataflash_vibration_before_2019_gives_each_imu_its_clipping(tmp_path: Path) -> None:
    out = tmp_path / "out"
    ingest([_df_with_context(tmp_path / "f.bin", _VIBE_OLD)], out)
    vib = _vibration(out)
    assert vib["imu"].tolist() == [0, 1, 2] * 3
    assert vib.loc[vib["imu"] == 2, "clip_count"].tolist() == [0.0, 2.0, 4.0]
    assert vib.loc[vib["imu"] > 0, "vibe_z_mps2"].isna().all()
    np.testing.assert_allclose(vib.loc[vib["imu"] == 0, "vibe_z_mps2"], [35, 36, 37])


# ------------------------------------------------------------------------------- real logs
def _real(rel: str) -> Path:
    path = SHARED / rel
    if not path.is_file():
        pytest.skip(f"real data not present: {path} (../shared/data is read in place)")
    return path


@pytest.mark.parametrize(
    ("rel", "modes", "arming", "vibration_rows"),
    [
        # logging started armed: only the disarm after landing; EV 11 repeats the ARM record
        ("uob_flightlab_ardupilot_bin/2023-07-06_10-12-18.bin", ["LOITER", "RTL"], ["disarmed"],
         2940),
        # 2015: no ARM record, EV 10 is the arming; MODE re-entered LOITER once (one change)
        ("corpus_2026/ap_copter33_2015_log171.bin", ["LOITER", "ACRO"], ["armed"], None),
        ("uavlogviewer_sitl_tlog/vtol.tlog",
         ["QLOITER", "CIRCLE", "GUIDED", "QLAND"], ["armed", "disarmed"], 2436),
        ("corpus_2026/px4_v190_fmuv3_flight.ulg", ["AUTO_MISSION", "AUTO_RTL"],
         ["armed", "disarmed"], 107),
    ],
)  # fmt: skip
def test_real_logs_give_their_modes_arming_and_vibration(
    tmp_path: Path, rel: str, modes: list[str], arming: list[str], vibration_rows: int | None
) -> None:
    result = ingest([_real(rel)], tmp_path / "out")
    ev = _events(tmp_path / "out")
    assert ev.loc[ev["kind"] == "mode", "text"].tolist()[: len(modes)] == modes
    assert ev.loc[ev["kind"] == "arming", "text"].tolist() == arming
    assert result.tables.get("vibration") == vibration_rows
    assert "events" in result.report["context"]


# ------------------------------------------------------------------------------------ ULog
def test_ulog_messages_status_and_imu_vibration(tmp_path: Path) -> None:
    status = ("vehicle_status", "uint64_t timestamp;uint8_t nav_state;uint8_t arming_state;", "QBB")
    imu_status = (
        "vehicle_imu_status",
        "uint64_t timestamp;float accel_vibration_metric;float gyro_vibration_metric;"
        "uint32_t[3] accel_clipping;",
        "Qff3I",
    )
    log = ulog_drive(seconds=3.0, formats=(status, imu_status))  # from timestamp 10 s
    log.subscribe("vehicle_status")
    for imu in (0, 1):
        log.subscribe("vehicle_imu_status", multi_id=imu)
    for i, (nav, arming) in enumerate(((2, 1), (2, 2), (3, 2), (3, 2), (5, 1))):
        log.data("vehicle_status", 10_200_000 + i * 500_000, nav, arming)
    for i in range(3):
        for imu in (0, 1):
            log.data("vehicle_imu_status", 10_100_000 + i * 500_000, 0.5 + imu, 0.01, 0, i, imu,
                     multi_id=imu)  # fmt: skip
    body = struct.pack("<BQ", ord("4"), 10_300_000) + SCRIPT.encode()
    log._msg(b"L", body)
    path = tmp_path / "f.ulg"
    path.write_bytes(log.bytes())
    ingest([path], tmp_path / "out")
    ev = _events(tmp_path / "out")
    assert list(zip(ev["kind"], ev["text"], strict=True)) == [
        ("mode", "POSCTL"),
        ("arming", "disarmed"),
        ("message", SCRIPT),
        ("arming", "armed"),
        ("mode", "AUTO_MISSION"),
        ("mode", "AUTO_RTL"),
        ("arming", "disarmed"),
    ]
    assert ev.loc[ev["kind"] == "message", "severity"].tolist() == [4]  # '4': warning
    vib = _vibration(tmp_path / "out")
    assert vib["imu"].tolist() == [0, 1] * 3
    np.testing.assert_allclose(vib.loc[vib["imu"] == 1, "accel_vibe_mps2"], 1.5)
    assert vib.loc[vib["imu"] == 0, "clip_count"].tolist() == [0.0, 1.0, 2.0]  # axes summed
    assert vib.loc[vib["imu"] == 1, "clip_count"].tolist() == [1.0, 2.0, 3.0]
    assert vib["vibe_x_mps2"].isna().all()  # PX4 logs a magnitude, not per-axis levels


def test_a_context_that_cannot_be_read_is_a_warning_not_a_failed_ingest(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from navreplay.ingest.readers.mavlink.tlog import TlogReader

    def broken(self: TlogReader) -> None:
        raise IndexError("index 7 is out of bounds")

    monkeypatch.setattr(TlogReader, "context", broken)
    path = tlog_drive().write(tmp_path / "f.tlog")
    result = ingest([path], tmp_path / "out")
    assert {"imu", "gnss"} <= set(result.tables)
    assert "events" not in result.tables
    assert not (tmp_path / "out" / "events.parquet").exists()
    assert any(
        "f.tlog: its messages, modes and vibration cannot be read (IndexError: index 7" in w
        for w in result.report["warnings"]
    )
