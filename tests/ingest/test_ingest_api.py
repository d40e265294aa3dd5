"""``ingest()`` end to end: outputs, atomicity (case 40), empty/missing topics (case 38),
several files of one drive, truth topics."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from rosbags.typesys import get_types_from_msg

from navreplay.ingest.api import REPORT_NAME, IngestOptions, IngestResult, ingest
from navreplay.ingest.config import parse_dataset_config
from navreplay.ingest.errors import ConfigError, IngestError
from navreplay.ingest.meta import read_meta
from navreplay.ingest.schema import spec
from navreplay.ingest.tables import TableWriter, read_table
from navreplay.ingest.timebase import GPS_EPOCH_UNIX_NS, NS_PER_S

from .roslogs import (
    ROS2,
    Stream,
    fix_stream,
    header,
    imu_data,
    imu_stream,
    odom_stream,
    write_mcap,
)


def _drive(tmp_path: Path, n: int = 1000, name: str = "drive.mcap") -> Path:
    return write_mcap(
        tmp_path / name, [imu_stream(imu_data(n)), fix_stream(n // 20), odom_stream(n // 10)]
    )


def test_outputs_are_canonical_tables_meta_and_report(tmp_path: Path) -> None:
    log = _drive(tmp_path)
    out = tmp_path / "tables"
    result = ingest([log], out)
    assert sorted(p.name for p in out.iterdir()) == [
        "gnss.parquet",
        "imu.parquet",
        REPORT_NAME,
        "meta.json",
        "vehicle.parquet",
    ]
    imu = read_table(out / "imu.parquet", "imu")
    assert imu.table.num_rows == 1000
    assert imu.provenance.sources[0].name == "drive.mcap"
    assert imu.provenance.extra["stream"] == "/imu/data"
    assert imu.provenance.extra["frame_conversions"] == "imu: FLU -> FRD"
    meta = read_meta(out)
    assert meta.tables == {"imu": 1000, "gnss": 50, "vehicle": 100}
    assert meta.time_base == "utc"
    assert meta.sources[0].format == "mcap"
    assert "vehicle: FLU -> FRD" in meta.frame_conversions
    report = json.loads((out / REPORT_NAME).read_text())
    assert report == json.loads(json.dumps(result.report))
    assert report["tables"]["imu"]["stats"]["rate_hz"] == pytest.approx(100.0)
    # A level IMU at rest: specific force (0, 0, -g) in FRD, no mounting applied.
    acc_z = imu.table["acc_z_mps2"].to_numpy()
    assert acc_z.mean() == pytest.approx(-9.80665, abs=0.01)
    veh = read_table(out / "vehicle.parquet", "vehicle").table
    assert veh["yaw_rate_radps"].to_numpy()[0] == pytest.approx(-0.1)  # FLU left -> FRD


def test_same_input_gives_identical_bytes(tmp_path: Path) -> None:
    log = _drive(tmp_path)
    cfg = parse_dataset_config({"id": "drive"})
    ingest([log], tmp_path / "a" / "tables", config=cfg)
    ingest([log], tmp_path / "b" / "tables", config=cfg)
    for f in sorted((tmp_path / "a" / "tables").iterdir()):
        assert f.read_bytes() == (tmp_path / "b" / "tables" / f.name).read_bytes(), f.name


def test_exception_mid_write_leaves_nothing_and_keeps_the_previous_output(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # Case 40: inject an exception after the 2nd row group.
    log = _drive(tmp_path, n=3000)
    out = tmp_path / "tables"
    ingest([log], out)
    before = {f.name: f.read_bytes() for f in out.iterdir()}
    calls = {"n": 0}
    real = TableWriter.write

    def failing(self: TableWriter, table: object) -> None:
        calls["n"] += 1
        if calls["n"] == 3:
            raise RuntimeError("injected failure after the 2nd row group")
        real(self, table)

    monkeypatch.setattr(TableWriter, "write", failing)
    with pytest.raises(RuntimeError, match="injected"):
        ingest([log], out, options=IngestOptions(block_rows=500))
    assert {f.name: f.read_bytes() for f in out.iterdir()} == before
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def test_sigkill_mid_write_leaves_no_partial_output_and_a_rerun_is_identical(
    tmp_path: Path,
) -> None:
    # Case 40: the process is killed at row group 10; nothing appears at the final path.
    log = _drive(tmp_path, n=6000)
    out = tmp_path / "tables"
    script = textwrap.dedent(
        f"""
        import os, signal
        from pathlib import Path
        from navreplay.ingest.api import IngestOptions, ingest
        from navreplay.ingest.tables import TableWriter
        real = TableWriter.write
        calls = [0]
        def write(self, table):
            calls[0] += 1
            if calls[0] == 10:
                os.kill(os.getpid(), signal.SIGKILL)
            real(self, table)
        TableWriter.write = write
        ingest([Path({str(log)!r})], Path({str(out)!r}), options=IngestOptions(block_rows=500))
        """
    )
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, timeout=300, check=False
    )
    assert done.returncode == -9, done.stderr.decode()
    assert not out.exists()
    cfg = parse_dataset_config({"id": "drive"})
    opts = IngestOptions(block_rows=500)
    ingest([log], out, config=cfg, options=opts)  # also removes the dead process's temp dir
    clean = tmp_path / "clean" / "tables"
    ingest([log], clean, config=cfg, options=opts)
    for f in sorted(out.iterdir()):
        assert f.read_bytes() == (clean / f.name).read_bytes(), f.name
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def test_empty_topic_gives_an_empty_table_with_the_full_schema(tmp_path: Path) -> None:
    # Case 38: a channel registered with 0 messages.
    log = write_mcap(
        tmp_path / "a.mcap",
        [imu_stream(imu_data(200)), Stream("/fix", "sensor_msgs/msg/NavSatFix")],
    )
    result = ingest([log], tmp_path / "out")
    assert result.tables == {"imu": 200, "gnss": 0}
    table = pq.read_table(tmp_path / "out" / "gnss.parquet")
    assert table.num_rows == 0
    assert table.schema.names == spec("gnss").arrow_schema().names
    assert result.report["warnings"] == ["table gnss (/fix) is empty"]


def test_missing_required_topic_is_fatal_naming_it(tmp_path: Path) -> None:
    # Case 38: /gps omitted entirely.
    log = write_mcap(tmp_path / "a.mcap", [imu_stream(imu_data(100))])
    cfg = parse_dataset_config({"id": "x", "required": ["imu", "gnss"]})
    with pytest.raises(IngestError, match="required table 'gnss'"):
        ingest([log], tmp_path / "out", config=cfg)
    cfg = parse_dataset_config({"id": "x", "gnss": {"topic": "/gps"}})
    with pytest.raises(ConfigError, match="'/gps' is not in the logs"):
        ingest([log], tmp_path / "out", config=cfg)
    assert not (tmp_path / "out").exists()


def test_split_files_of_one_drive_merge_in_time_order(tmp_path: Path) -> None:
    data = imu_data(2000)
    first = imu_stream(data)
    second = Stream(first.topic, first.msgtype, first.messages[1000:])
    first.messages = first.messages[:1000]
    a = write_mcap(tmp_path / "part_0.mcap", [first])
    b = write_mcap(tmp_path / "part_1.mcap", [second])
    result = ingest([b, a], tmp_path / "out")  # given out of order on purpose
    assert result.tables == {"imu": 2000}
    t = pq.read_table(tmp_path / "out" / "imu.parquet")["t_ns"].to_numpy()
    np.testing.assert_array_equal(t, data.t_ns)
    assert result.report["tables"]["imu"]["files"] == ["part_0.mcap", "part_1.mcap"]


def _imu_with_gps_fixes(tmp_path: Path, n: int, *, time_base: str) -> IngestResult:
    """Ingest ``n`` IMU messages (an MCAP on UTC) with a receiver's fixes every 50th IMU stamp
    on GPS time, in ``fix.csv`` whose dataset.yaml mapping claims ``time_base``."""
    data = imu_data(n)
    log = write_mcap(tmp_path / "a.mcap", [imu_stream(data)])
    t_gps = data.t_ns[::50] - GPS_EPOCH_UNIX_NS + 18 * NS_PER_S
    csv = tmp_path / "fix.csv"
    csv.write_text("t,lat,lon,h\n" + "".join(f"{t},37.5,127.0,50.0\n" for t in t_gps.tolist()))
    mapping = {
        "path": "fix.csv",
        "table": "gnss",
        "time_column": "t",
        "time_unit": "ns",
        "time_base": time_base,
        "constants": {"fix_type": 3},
        "columns": {"lat_deg": "lat", "lon_deg": "lon", "alt_m": "h"},
    }
    cfg = parse_dataset_config({"id": "x", "csv": [mapping]})
    return ingest([log, csv], tmp_path / "out", config=cfg, config_dir=tmp_path)


def test_utc_and_gps_time_streams_are_reconciled_with_leap_seconds(tmp_path: Path) -> None:
    # ROS stamps are UTC; a receiver log on GPS time joins them: the dataset is on GPS time.
    result = _imu_with_gps_fixes(tmp_path, 500, time_base="gps")
    tb = result.report["time_base"]
    assert tb["base"] == "gps"
    assert tb["leap_seconds"] == 18
    imu_t = pq.read_table(tmp_path / "out" / "imu.parquet")["t_ns"].to_numpy()
    gnss_t = pq.read_table(tmp_path / "out" / "gnss.parquet")["t_ns"].to_numpy()
    np.testing.assert_array_equal(imu_t[::50], gnss_t)
    assert tb["checks"] == ["imu and gnss (different files) overlap for 4.5 s"]
    assert result.report["warnings"] == []


def test_files_on_mismatched_clocks_are_flagged(tmp_path: Path) -> None:
    # The receiver file claims UTC but is stamped on GPS time since 1980: far apart.
    result = _imu_with_gps_fixes(tmp_path, 200, time_base="utc")
    (warning,) = result.report["warnings"]
    assert "do not overlap" in warning
    assert "fix.csv" in warning


NAV_TRUTH = """std_msgs/Header header
float64 lat_deg
float64 lon_deg
float64 alt_m
float64 vel_n_mps
float64 vel_e_mps
float64 vel_d_mps
float64 roll_rad
float64 pitch_rad
float64 yaw_rad
float64 acc_bias_x_mps2
float64 clock_drift_mps
"""


def test_truth_messages_fill_the_truth_table_by_field_name(tmp_path: Path) -> None:
    name = "navreplay_msgs/msg/NavTruth"
    types = get_types_from_msg(NAV_TRUTH, name)
    ROS2.register(types)
    cls = ROS2.types[name]
    stream = Stream("/truth", name, definition=NAV_TRUTH)
    for i in range(50):
        t = 10**18 + i * 10**8
        msg = cls(
            header(False, t, "map"),
            37.5 + i * 1e-6,
            127.0,
            50.0,
            1.0,
            2.0,
            0.1,
            0.01,
            0.02,
            0.5 + i * 0.001,
            0.003,
            -0.4,
        )
        stream.messages.append((t, bytes(ROS2.serialize_cdr(msg, name))))
    log = write_mcap(tmp_path / "a.mcap", [stream])
    result = ingest([log], tmp_path / "out")
    assert result.tables == {"truth": 50}
    truth = pq.read_table(tmp_path / "out" / "truth.parquet")
    assert truth["yaw_rad"].to_numpy()[10] == pytest.approx(0.51)
    assert truth["acc_bias_x_mps2"].to_numpy()[0] == 0.003
    assert truth["clock_drift_mps"].to_numpy()[0] == -0.4
    assert truth["t_ns"].to_numpy()[1] - truth["t_ns"].to_numpy()[0] == 10**8


def _twist_cov(t_ns: int, lin: tuple[float, float, float], var: float) -> bytes:
    t = ROS2.types
    cov = np.zeros(36)
    cov[0] = cov[7] = cov[14] = var
    msg = t["geometry_msgs/msg/TwistWithCovarianceStamped"](
        header=header(False, t_ns, "gps"),
        twist=t["geometry_msgs/msg/TwistWithCovariance"](
            twist=t["geometry_msgs/msg/Twist"](
                linear=t["geometry_msgs/msg/Vector3"](x=lin[0], y=lin[1], z=lin[2]),
                angular=t["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.25),
            ),
            covariance=cov,
        ),
    )
    return bytes(ROS2.serialize_cdr(msg, msg.__msgtype__))


def test_gnss_velocity_topic_is_joined_to_the_fixes_in_ned(tmp_path: Path) -> None:
    fixes = fix_stream(20)
    stamps = [t for t, _ in fixes.messages]
    vel = Stream("/gps/vel", "geometry_msgs/msg/TwistWithCovarianceStamped")
    for i, t in enumerate(stamps):
        if i == 5:
            continue  # a fix without velocity
        jitter = 2_000_000 if i % 2 else 0  # stamped 2 ms apart: still the same epoch
        vel.messages.append((t + jitter, _twist_cov(t + jitter, (1.0, 2.0, 0.5), 0.04)))
    vel.messages.append(
        (stamps[-1] + 100_000_000, _twist_cov(stamps[-1] + 100_000_000, (0, 0, 0), 0))
    )
    wheel = Stream("/wheel/twist", "geometry_msgs/msg/TwistWithCovarianceStamped")
    wheel.messages = [(t, _twist_cov(t, (3.0, 0.0, 0.0), 0.0)) for t in stamps]
    log = write_mcap(tmp_path / "a.mcap", [fixes, vel, wheel])
    result = ingest([log], tmp_path / "out")
    assert result.tables == {"gnss": 20, "vehicle": 20}
    comp = result.report["tables"]["gnss"]["companion"]
    assert (comp["stream"], comp["joined"], comp["rows_without_companion"]) == ("/gps/vel", 19, 1)
    assert comp["companion_rows_without_row_dropped"] == 1
    gnss = pq.read_table(tmp_path / "out" / "gnss.parquet")
    # ENU (east 1, north 2, up 0.5) -> NED (2, 1, -0.5); sigma 0.2 m/s.
    assert gnss["vel_n_mps"].to_pylist()[:2] == [2.0, 2.0]
    assert gnss["vel_e_mps"].to_pylist()[0] == 1.0
    assert gnss["vel_d_mps"].to_pylist()[0] == -0.5
    assert gnss["speed_acc_mps"].to_pylist()[0] == pytest.approx(0.2)
    assert gnss["vel_n_mps"].to_pylist()[5] is None  # not provided, not invalid
    veh = pq.read_table(tmp_path / "out" / "vehicle.parquet")
    assert veh["speed_mps"].to_pylist()[0] == 3.0
    assert veh["yaw_rate_radps"].to_pylist()[0] == -0.25  # FLU -> FRD
