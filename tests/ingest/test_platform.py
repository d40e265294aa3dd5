"""The vehicle kind from the log (``ingest.platform``), recorded in ``meta.json``
``sensors.platform``: MAVLink HEARTBEAT type, ArduPilot firmware message, PX4 vehicle_status or
MAV_TYPE parameter, ``dataset.yaml`` ``platform:`` over all of them; and the real logs of
``../shared/data``."""

from __future__ import annotations

import struct
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as apm

from navreplay.ingest.api import ingest, inspect
from navreplay.ingest.config import parse_dataset_config
from navreplay.ingest.errors import ConfigError
from navreplay.ingest.meta import read_meta
from navreplay.ingest.platform import (
    MAV_TYPES,
    Platform,
    from_firmware,
    from_heartbeats,
    from_px4_status,
)

from .mavlogs import ALT_MM, BOOT_US, LAT_E7, LON_E7, UTC0_US, G, Tlog, UlogLog, mav
from .test_vintage_logs import copter33

DATA = Path(__file__).resolve().parents[3] / "shared" / "data"


def platform_of(out: Path) -> Platform:
    return read_meta(out).sensors.platform


# ------------------------------------------------------------------------------ MAVLink tlog
def tlog(
    path: Path,
    vehicle_type: int | None,
    *,
    gcs: bool = True,
    gimbal: bool = False,
    q_enable: float | None = None,
) -> Path:
    """A vehicle at rest for 3 s (RAW_IMU 50 Hz, GPS_RAW_INT 5 Hz, SYSTEM_TIME 1 Hz) sending
    HEARTBEAT of ``vehicle_type`` at 1 Hz (none if None), beside a ground station's heartbeats
    at 2 Hz (MAV_TYPE_GCS, MAV_AUTOPILOT_INVALID) and, with ``gimbal``, a gimbal's at 2 Hz;
    with ``q_enable``, the vehicle sends that PARAM_VALUE once."""
    vehicle, ground, mount = mav(1, 1), mav(255, 190), mav(1, 154)
    log = Tlog()
    for i in range(150):
        boot_us = BOOT_US + i * 20_000
        stamp = UTC0_US + i * 20_000 + 3_000
        if vehicle_type is not None and i % 50 == 0:
            beat = vehicle.heartbeat_encode(
                vehicle_type, apm.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 0, apm.MAV_STATE_ACTIVE
            )
            log.add(stamp, vehicle, beat)
        if gcs and i % 25 == 0:
            log.add(
                stamp,
                ground,
                ground.heartbeat_encode(apm.MAV_TYPE_GCS, apm.MAV_AUTOPILOT_INVALID, 0, 0, 0),
            )
        if gimbal and i % 25 == 0:
            log.add(
                stamp,
                mount,
                mount.heartbeat_encode(apm.MAV_TYPE_GIMBAL, apm.MAV_AUTOPILOT_INVALID, 0, 0, 0),
            )
        if q_enable is not None and i == 7:
            param = vehicle.param_value_encode(
                b"Q_ENABLE", q_enable, apm.MAV_PARAM_TYPE_INT8, 900, 512
            )
            log.add(stamp, vehicle, param)
        log.add(stamp, vehicle, vehicle.raw_imu_encode(boot_us, 0, 0, -1000, 1, -1, 0, 1, 2, 3))
        if i % 10 == 0:
            gps = vehicle.gps_raw_int_encode(
                boot_us, 3, LAT_E7, LON_E7, ALT_MM, 121, 200, 15, 9000, 12
            )
            log.add(stamp, vehicle, gps)
        if i % 50 == 0:
            log.add(
                stamp,
                vehicle,
                vehicle.system_time_encode(UTC0_US + boot_us - BOOT_US, boot_us // 1000),
            )
    return log.write(path)


@pytest.mark.parametrize(
    ("mav_type", "kind", "words"),
    [
        (apm.MAV_TYPE_QUADROTOR, "multirotor", "HEARTBEAT type 2 (MAV_TYPE_QUADROTOR)"),
        (apm.MAV_TYPE_HEXAROTOR, "multirotor", "HEARTBEAT type 13 (MAV_TYPE_HEXAROTOR)"),
        (apm.MAV_TYPE_HELICOPTER, "multirotor", "MAV_TYPE_HELICOPTER: a helicopter"),
        (apm.MAV_TYPE_FIXED_WING, "fixed_wing", "HEARTBEAT type 1 (MAV_TYPE_FIXED_WING)"),
        (apm.MAV_TYPE_GROUND_ROVER, "ground", "HEARTBEAT type 10 (MAV_TYPE_GROUND_ROVER)"),
        (apm.MAV_TYPE_SURFACE_BOAT, "ground", "MAV_TYPE_SURFACE_BOAT"),
        (apm.MAV_TYPE_VTOL_TILTROTOR, "vtol", "HEARTBEAT type 21 (MAV_TYPE_VTOL_TILTROTOR)"),
        (apm.MAV_TYPE_VTOL_QUADROTOR, "vtol", "HEARTBEAT type 20 (MAV_TYPE_VTOL_QUADROTOR)"),
    ],
)
def test_tlog_platform_is_the_vehicles_heartbeat_type_not_the_ground_stations(
    tmp_path: Path, mav_type: int, kind: str, words: str
) -> None:
    path = tlog(tmp_path / "v.tlog", mav_type, gimbal=True)
    ingest([path], tmp_path / "out")
    found = platform_of(tmp_path / "out")
    assert found.kind == kind
    assert words in found.source


@pytest.mark.parametrize(("q_enable", "kind"), [(1.0, "vtol"), (0.0, "fixed_wing")])
def test_tlog_of_a_quadplane_is_a_vtol(tmp_path: Path, q_enable: float, kind: str) -> None:
    path = tlog(tmp_path / "v.tlog", apm.MAV_TYPE_FIXED_WING, q_enable=q_enable)
    (inv,), _ = inspect([path])
    assert inv.platform.kind == kind
    if kind == "vtol":
        assert inv.platform.source == (
            "HEARTBEAT type 1 (MAV_TYPE_FIXED_WING) with parameter Q_ENABLE 1 (a QuadPlane)"
        )


def test_tlog_with_only_ground_station_heartbeats_is_unknown(tmp_path: Path) -> None:
    path = tlog(tmp_path / "v.tlog", None, gimbal=True)
    (inv,), _ = inspect([path])
    assert inv.platform.kind == "unknown"
    ingest([path], tmp_path / "out")
    assert platform_of(tmp_path / "out") == Platform("unknown", "nothing in the log")


def test_tlog_platform_is_said_in_the_inventory_notes(tmp_path: Path) -> None:
    (inv,), _ = inspect([tlog(tmp_path / "v.tlog", apm.MAV_TYPE_OCTOROTOR)])
    assert "platform: multirotor (from HEARTBEAT type 14 (MAV_TYPE_OCTOROTOR))" in inv.notes


def test_mav_type_names_are_the_dialects() -> None:
    names = {v: e.name for v, e in apm.enums["MAV_TYPE"].items()}
    assert {v: entry[0] for v, entry in MAV_TYPES.items()} == {v: names[v] for v in MAV_TYPES}


def test_heartbeats_of_a_generic_or_gcs_type_never_decide() -> None:
    gcs = (apm.MAV_TYPE_GCS, apm.MAV_AUTOPILOT_INVALID, 1000)
    generic = (apm.MAV_TYPE_GENERIC, apm.MAV_AUTOPILOT_ARDUPILOTMEGA, 500)
    assert from_heartbeats([gcs, generic]).kind == "unknown"
    # a companion computer claiming a vehicle type without being an autopilot
    companion = (apm.MAV_TYPE_QUADROTOR, apm.MAV_AUTOPILOT_INVALID, 10)
    assert from_heartbeats([companion]).kind == "unknown"
    plane = (apm.MAV_TYPE_FIXED_WING, apm.MAV_AUTOPILOT_ARDUPILOTMEGA, 3)
    assert from_heartbeats([gcs, generic, plane]).kind == "fixed_wing"


# ------------------------------------------------------------------------ ArduPilot DataFlash
@pytest.mark.parametrize(
    ("firmware", "kind"),
    [
        (b"APM:Copter V3.3 (d6053245)", "multirotor"),
        (b"ArduCopter V4.3.6 (2c8e5f8e)", "multirotor"),
        (b"ArduPlane V4.2.3 (b7e7b6e1)", "fixed_wing"),
        (b"ArduRover V4.4.0 (c1e94d9b)", "ground"),
        (b"APMrover2 V3.1.0 (1f2a3b4c)", "ground"),
        (b"ArduSub V4.1.0 (0a1b2c3d)", "unknown"),
        (b"Frame: QUAD", "unknown"),
    ],
)
def test_dataflash_platform_from_the_firmware_message(
    tmp_path: Path, firmware: bytes, kind: str
) -> None:
    path = copter33(firmware=firmware).save(tmp_path / "log.bin")
    ingest([path], tmp_path / "out")
    found = platform_of(tmp_path / "out")
    assert found.kind == kind
    if kind != "unknown":
        assert found.source == f'firmware "{firmware.decode().rsplit(" ", 1)[0]}"'
    elif firmware.startswith(b"ArduSub"):
        assert found.source == 'firmware "ArduSub V4.1.0" (a submarine)'


@pytest.mark.parametrize(("q_enable", "kind"), [(1.0, "vtol"), (0.0, "fixed_wing")])
def test_dataflash_of_a_quadplane_is_a_vtol(tmp_path: Path, q_enable: float, kind: str) -> None:
    log = copter33(firmware=b"ArduPlane V4.2.3 (b7e7b6e1)")
    log.write("PARM", b"Q_ENABLE".ljust(16, b"\0"), q_enable)
    (inv,), _ = inspect([log.save(tmp_path / "log.bin")])
    assert inv.platform.kind == kind
    if kind == "vtol":
        assert inv.platform.source == (
            'firmware "ArduPlane V4.2.3" with parameter Q_ENABLE 1 (a QuadPlane)'
        )


def test_firmware_found_after_other_messages_and_words() -> None:
    lines = ["PX4: 1a2b3c4d NuttX: 5e6f", "Pixhawk1 002A0023 3236510B", "APM:Plane V3.8.0"]
    assert from_firmware(lines) == Platform("fixed_wing", 'firmware "APM:Plane V3.8.0"')


# ------------------------------------------------------------------------------------ PX4 ULog
STATUS_V19 = ("uint64_t timestamp;uint8_t system_type;bool is_rotary_wing;bool is_vtol;", "QB??")
STATUS_V113 = ("uint64_t timestamp;uint8_t vehicle_type;bool is_vtol;", "QB?")


def ulog(
    path: Path,
    status: tuple[tuple[str, str], tuple[Any, ...]] | None,
    mav_type_param: int | None = None,
) -> Path:
    """sensor_combined at 200 Hz at rest for 2 s, with one ``vehicle_status`` sample of the
    given layout and values, and a ``MAV_TYPE`` parameter if given."""
    rng = np.random.default_rng(7)
    ul = UlogLog()
    ul.info("sys_name", "PX4")
    ul.format(
        "sensor_combined",
        "uint64_t timestamp;float[3] gyro_rad;float[3] accelerometer_m_s2;",
        "Q3f3f",
    )
    if status is not None:
        ul.format("vehicle_status", *status[0])
    if mav_type_param is not None:
        key = b"int32_t MAV_TYPE"
        ul._msg(b"P", bytes([len(key)]) + key + struct.pack("<i", mav_type_param))
    ul.subscribe("sensor_combined")
    if status is not None:
        ul.subscribe("vehicle_status")
    for i in range(400):
        t = 10_000_000 + i * 5_000
        acc = np.array([0.0, 0.0, -G]) + rng.normal(0, 0.02, 3)
        ul.data("sensor_combined", t, *rng.normal(0, 1e-3, 3), *acc)
        if status is not None and i == 10:
            ul.data("vehicle_status", t, *status[1])
    path.write_bytes(ul.bytes())
    return path


@pytest.mark.parametrize(
    ("status", "param", "want"),
    [
        (
            (STATUS_V19, (2, True, False)),
            None,
            Platform("multirotor", "vehicle_status.system_type type 2 (MAV_TYPE_QUADROTOR)"),
        ),
        (
            (STATUS_V19, (1, False, False)),
            None,
            Platform("fixed_wing", "vehicle_status.system_type type 1 (MAV_TYPE_FIXED_WING)"),
        ),
        ((STATUS_V19, (22, True, True)), None, Platform("vtol", "vehicle_status.is_vtol")),
        (
            (STATUS_V113, (3, False)),
            None,
            Platform("ground", "vehicle_status.vehicle_type 3"),
        ),
        (
            None,
            10,
            Platform("ground", "parameter MAV_TYPE type 10 (MAV_TYPE_GROUND_ROVER)"),
        ),
        (None, None, Platform("unknown", "nothing in the log")),
    ],
    ids=["v19_quad", "v19_plane", "v19_vtol", "v113_rover", "param_rover", "nothing"],
)
def test_ulog_platform_from_vehicle_status_or_the_mav_type_parameter(
    tmp_path: Path,
    status: tuple[tuple[str, str], tuple[Any, ...]] | None,
    param: int | None,
    want: Platform,
) -> None:
    path = ulog(tmp_path / "log.ulg", status, param)
    ingest([path], tmp_path / "out")
    assert platform_of(tmp_path / "out") == want


def test_px4_status_without_a_vehicle_says_unknown() -> None:
    assert from_px4_status({"system_type": 0, "is_rotary_wing": 0}).kind == "unknown"
    assert from_px4_status({}).kind == "unknown"


# ------------------------------------------------------------------------------ dataset.yaml
def test_dataset_yaml_platform_overrides_the_log(tmp_path: Path) -> None:
    path = tlog(tmp_path / "v.tlog", apm.MAV_TYPE_QUADROTOR)
    config = parse_dataset_config({"id": "rover", "platform": "ground"})
    ingest([path], tmp_path / "out", config=config)
    assert platform_of(tmp_path / "out") == Platform("ground", "dataset.yaml")


def test_dataset_yaml_platform_of_another_kind_is_refused_naming_the_key() -> None:
    with pytest.raises(ConfigError) as err:
        parse_dataset_config({"id": "boat", "platform": "boat"}, source="dataset.yaml")
    assert "platform" in str(err.value)
    assert "dataset.yaml" in str(err.value)


def test_meta_json_written_before_platforms_reads_as_unknown(tmp_path: Path) -> None:
    path = tlog(tmp_path / "v.tlog", apm.MAV_TYPE_QUADROTOR)
    out = tmp_path / "out"
    ingest([path], out)
    meta = out / "meta.json"
    text = meta.read_text()
    start = text.index('"platform"')
    end = text.index("}", start) + 1
    old = text[:start].rstrip().rstrip(",") + text[end:]
    meta.write_text(old)
    assert platform_of(out) == Platform("unknown", "nothing in the log")


# ------------------------------------------------------------------------ real logs (shared/)
REAL = {
    "uob_flightlab_ardupilot_bin/2023-07-06_10-12-18.bin": (
        "multirotor",
        'firmware "ArduCopter V4.3.6"',
    ),
    "corpus_2026/ap_copter33_2015_log171.bin": ("multirotor", 'firmware "APM:Copter V3.3-dev"'),
    "corpus_2026/ap_copter462_2024_trunc80k.bin": ("multirotor", 'firmware "ArduCopter V4.6.2"'),
    "corpus_2026/ap_plane423_2022_ground_noimu.bin": ("fixed_wing", 'firmware "ArduPlane V4.2.3"'),
    "corpus_2026/ap_copter34_bench_2016_tlog.log": (
        "multirotor",
        "HEARTBEAT type 2 (MAV_TYPE_QUADROTOR)",
    ),
    # ArduPlane's QuadPlane SITL announces itself as a fixed wing, with Q_ENABLE 1
    "uavlogviewer_sitl_tlog/vtol.tlog": (
        "vtol",
        "HEARTBEAT type 1 (MAV_TYPE_FIXED_WING) with parameter Q_ENABLE 1 (a QuadPlane)",
    ),
    "corpus_2026/px4_v190_fmuv3_flight.ulg": (
        "multirotor",
        "vehicle_status.system_type type 2 (MAV_TYPE_QUADROTOR)",
    ),
    "corpus_2026/px4_v190_sitl_truth.ulg": (
        "multirotor",
        "vehicle_status.system_type type 2 (MAV_TYPE_QUADROTOR)",
    ),
    "pyulog_samples/sample.ulg": (
        "multirotor",
        "vehicle_status.system_type type 2 (MAV_TYPE_QUADROTOR)",
    ),
    "pyulog_samples/sample_log_small.ulg": ("vtol", "vehicle_status.is_vtol"),
    "corpus_2026/px4_sdlog2_2015_purdue.px4log": ("unknown", "nothing in the log"),
    "smartloc_berlin_potsdamer_platz/Berlin_Potsdamer_Platz_Input.txt": (
        "ground",
        "libRSF odom3 (wheel speed and yaw rate of a car)",
    ),
    "robot_localization/test1.bag": ("unknown", "nothing in the log"),
}


@pytest.mark.parametrize("rel", sorted(REAL))
def test_real_logs_platform(rel: str) -> None:
    path = DATA / rel
    if not path.exists():
        pytest.skip(f"{path} is absent (../shared/data is not beside the checkout)")
    (inv,), _ = inspect([path])
    kind, source = REAL[rel]
    assert (inv.platform.kind, inv.platform.source) == (kind, source)


def test_comma2k19_segment_is_a_car() -> None:
    seg = DATA / "comma2k19_example_segment" / "original"
    if not seg.exists():
        pytest.skip(f"{seg} is absent (../shared/data is not beside the checkout)")
    (inv,), _ = inspect([seg])
    assert inv.platform == Platform("ground", "comma2k19 (a car dataset)")
