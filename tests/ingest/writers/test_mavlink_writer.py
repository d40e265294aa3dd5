"""MAVLink tlog writer: framing, integer scaling, decoding with pymavlink."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest
from pymavlink import mavutil

from navreplay.ingest.errors import IngestError
from navreplay.ingest.schema import FixType, from_columns
from navreplay.ingest.writers.mavlink import (
    UINT16_MAX,
    TlogWriter,
    as_logged_gnss,
    as_logged_imu,
    write_tlog,
)

T0_NS = 1_795_338_000 * 10**9


def gnss_table(vel_n: list[float | None], vel_e: list[float | None]) -> pa.Table:
    n = len(vel_n)
    return from_columns(
        "gnss",
        {
            "t_ns": T0_NS + np.arange(n, dtype=np.int64) * 200_000_000,
            "lat_deg": np.full(n, 37.123456789),
            "lon_deg": np.full(n, -122.98765432),
            "alt_m": np.full(n, 61.2345),
            "vel_n_mps": pa.array(vel_n, pa.float64()),
            "vel_e_mps": pa.array(vel_e, pa.float64()),
            "h_acc_m": np.full(n, 1.5),
            "fix_type": np.full(n, FixType.FIX_3D, dtype=np.int8),
            "num_sats": pa.array([9] * n, pa.int16()),
        },
    )


def messages(path: Path) -> list[tuple[float, dict[str, object]]]:
    conn = mavutil.mavlink_connection(str(path))
    out = []
    try:
        while (m := conn.recv_match()) is not None:
            out.append((m._timestamp, m.to_dict()))
    finally:
        conn.close()
    return out


def test_gps_raw_int_scaling_and_unknown_course(tmp_path: Path) -> None:
    gnss = gnss_table([3.0, 0.001, None], [-4.0, 0.0, None])
    path = tmp_path / "gps.tlog"
    write_tlog(path, gnss=gnss)
    gps = [m for _, m in messages(path) if m["mavpackettype"] == "GPS_RAW_INT"]
    assert [g["lat"] for g in gps] == [371234568] * 3
    assert [g["lon"] for g in gps] == [-1229876543] * 3
    assert [g["alt_ellipsoid"] for g in gps] == [61234] * 3  # mm, round half to even
    assert [g["vel"] for g in gps] == [500, 0, UINT16_MAX]
    assert gps[0]["cog"] == round((360 - 53.13010235415598) * 100)  # cdeg clockwise from north
    assert gps[1]["cog"] == gps[2]["cog"] == UINT16_MAX
    assert [(g["h_acc"], g["satellites_visible"], g["fix_type"]) for g in gps] == [(1500, 9, 3)] * 3
    assert [g["time_usec"] for g in gps] == [T0_NS // 1000 + k * 200_000 for k in range(3)]
    logged = as_logged_gnss(gnss)
    assert logged["lat_deg"].to_pylist() == [37.1234568] * 3
    assert logged["vel_n_mps"].to_pylist()[1:] == [0.0, None]
    assert logged["vel_n_mps"][0].as_py() == pytest.approx(3.0, abs=1e-4)
    assert logged["vel_d_mps"].null_count == 3
    assert logged["num_sats"].to_pylist() == [9] * 3


def test_framing_is_stamp_then_mavlink2_packet_with_running_sequence(tmp_path: Path) -> None:
    path = tmp_path / "hb.tlog"
    with TlogWriter(path) as w:
        for k in range(300):
            w.write(1_000_000 + k, w.mav.heartbeat_encode(1, 3, 0, 0, 4))
    data = path.read_bytes()
    size = 8 + 12 + 9  # stamp + MAVLink 2 header/checksum + HEARTBEAT payload
    assert len(data) == 300 * size
    stamps = [struct.unpack(">Q", data[i * size : i * size + 8])[0] for i in range(300)]
    assert stamps == list(range(1_000_000, 1_000_300))
    assert data[8] == 0xFD
    seqs = [data[i * size + 8 + 4] for i in range(300)]
    assert seqs == [k % 256 for k in range(300)]
    assert [t for t, _ in messages(path)][:2] == [1.0, 1.000001]


def test_stamps_must_not_go_backwards_and_times_must_be_whole_microseconds(tmp_path: Path) -> None:
    path = tmp_path / "bad.tlog"

    def backwards() -> None:
        with TlogWriter(path) as w:
            w.write(10, w.mav.heartbeat_encode(1, 3, 0, 0, 4))
            w.write(9, w.mav.heartbeat_encode(1, 3, 0, 0, 4))

    with pytest.raises(IngestError, match="precedes"):
        backwards()
    assert not path.exists()  # the atomic write left nothing behind
    imu = from_columns(
        "imu",
        {"t_ns": np.array([T0_NS + 500], dtype=np.int64)}
        | {
            f"{k}_{a}_{u}": np.zeros(1)
            for k, u in (("acc", "mps2"), ("gyro", "radps"))
            for a in "xyz"
        },
    )
    with pytest.raises(IngestError, match="whole number of microseconds"):
        write_tlog(path, imu=imu)


def test_imu_is_logged_as_float32_and_merged_in_time_order(tmp_path: Path) -> None:
    t = T0_NS + np.arange(5, dtype=np.int64) * 10_000_000
    cols = {f"acc_{a}_mps2": np.full(5, 0.1) for a in "xyz"} | {
        f"gyro_{a}_radps": np.full(5, 1e-5) for a in "xyz"
    }
    imu = from_columns("imu", {"t_ns": t, **cols})
    gnss = gnss_table([1.0], [0.0])
    path = tmp_path / "mix.tlog"
    write_tlog(path, imu=imu, gnss=gnss)
    types = [m["mavpackettype"] for _, m in messages(path)]
    assert types == ["HEARTBEAT", "SYSTEM_TIME", "HIGHRES_IMU", "GPS_RAW_INT"] + ["HIGHRES_IMU"] * 4
    logged = as_logged_imu(imu)
    decoded = [m["xacc"] for _, m in messages(path) if m["mavpackettype"] == "HIGHRES_IMU"]
    assert decoded == logged["acc_x_mps2"].to_pylist() != cols["acc_x_mps2"].tolist()


def truth_table(n: int) -> pa.Table:
    t = T0_NS + np.arange(n, dtype=np.int64) * 10_000_000
    return from_columns(
        "truth",
        {
            "t_ns": t,
            "lat_deg": np.full(n, 47.4),
            "lon_deg": np.full(n, 8.5),
            "alt_m": np.full(n, 500.0),
            "vel_n_mps": np.full(n, 1.0),
            "vel_e_mps": np.zeros(n),
            "vel_d_mps": np.zeros(n),
            "roll_rad": np.zeros(n),
            "pitch_rad": np.zeros(n),
            "yaw_rad": np.full(n, 0.5),
        },
    )


def test_magnetometer_truth_messages_and_armed_heartbeat(tmp_path: Path) -> None:
    n = 3
    t = T0_NS + np.arange(n, dtype=np.int64) * 10_000_000
    cols = {f"acc_{a}_mps2": np.zeros(n) for a in "xyz"} | {
        f"gyro_{a}_radps": np.zeros(n) for a in "xyz"
    }
    imu = from_columns("imu", {"t_ns": t, **cols})
    mag = np.array([[0.2, 0.01, 0.43], [0.21, -0.02, 0.44], [0.0, 0.5, -0.1]])
    path = tmp_path / "mag.tlog"
    write_tlog(
        path,
        imu=imu,
        truth=truth_table(n),
        mav_type=mavutil.mavlink.MAV_TYPE_QUADROTOR,
        mag_gauss=mag,
        truth_messages=("SIM_STATE",),
        armed=True,
    )
    msgs = [m for _, m in messages(path)]
    hi = [m for m in msgs if m["mavpackettype"] == "HIGHRES_IMU"]
    got = np.array([[m["xmag"], m["ymag"], m["zmag"]] for m in hi])
    np.testing.assert_array_equal(got, mag.astype(np.float32))
    assert {m["fields_updated"] for m in hi} == {0x1FF}
    types = {m["mavpackettype"] for m in msgs}
    assert "SIM_STATE" in types
    assert "SIMSTATE" not in types
    beat = next(m for m in msgs if m["mavpackettype"] == "HEARTBEAT")
    assert beat["type"] == mavutil.mavlink.MAV_TYPE_QUADROTOR
    assert beat["base_mode"] & mavutil.mavlink.MAV_MODE_FLAG_SAFETY_ARMED
    # without them: no magnetometer, both truth messages, disarmed
    plain = tmp_path / "plain.tlog"
    write_tlog(plain, imu=imu, truth=truth_table(n))
    msgs = [m for _, m in messages(plain)]
    assert {m["fields_updated"] for m in msgs if m["mavpackettype"] == "HIGHRES_IMU"} == {0x3F}
    assert {"SIMSTATE", "SIM_STATE"} <= {m["mavpackettype"] for m in msgs}
    assert next(m for m in msgs if m["mavpackettype"] == "HEARTBEAT")["base_mode"] == 0
    with pytest.raises(IngestError, match=r"mag_gauss has shape \(2, 3\)"):
        write_tlog(tmp_path / "bad.tlog", imu=imu, mag_gauss=mag[:2])
    with pytest.raises(ValueError, match="SIM_STAT"):
        write_tlog(tmp_path / "bad.tlog", truth=truth_table(n), truth_messages=("SIM_STAT",))
