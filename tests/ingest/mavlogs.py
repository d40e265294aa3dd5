"""Small MAVLink tlogs, ArduPilot DataFlash and PX4 ULog logs for tests, written with the
formats' own encoders: pymavlink's ``MAVLink(...).<msg>_encode().pack()`` for tlog packets, and
raw ``struct`` packing (pymavlink's format-character table) for DataFlash FMT and data records
and for ULog messages. ``write_tlog_drive`` and ``write_dataflash_drive`` write large drives
for the memory test and the benchmark.

``TlogDrive`` is a vehicle standing still for a few seconds: RAW_IMU and SCALED_IMU2 (mG,
mrad/s), HIGHRES_IMU, GPS_RAW_INT at 5 Hz (MAVLink 2, with the extensions), ATTITUDE +
GLOBAL_POSITION_INT at 10 Hz, SIMSTATE after each ATTITUDE, SYSTEM_TIME at 1 Hz. Packet
stamps are the vehicle's UTC plus a link latency; ``time_boot_ms`` counts from ``BOOT_US``.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from pymavlink.DFReader import FORMAT_TO_STRUCT
from pymavlink.dialects.v20 import ardupilotmega as apm
from pymavlink.generator.mavcrc import x25crc

from navreplay.ingest.readers.mavlink.dfformat import make_format

G = 9.80665
UTC0_US = 1_700_000_000 * 10**6  # 2023-11-14T22:13:20Z: the vehicle's UTC at boot + BOOT_US
BOOT_US = 100_000_000  # the vehicle has been up 100 s when the log starts
LATENCY_US = 3_000
LAT_E7, LON_E7 = 523_456_789, -41_234_567
ALT_MM, ALT_ELL_MM = 120_000, 170_500


GPS_RAW_INT_V1_LEN = 30  # the payload without the MAVLink 2 extension fields


def mavlink1(packet_v2: bytes, msg: Any, payload_len: int) -> bytes:
    """The MAVLink 1 form of a packed MAVLink 2 packet: 6-byte header, the first
    ``payload_len`` payload bytes (no extensions), X.25 CRC with the message's crc_extra."""
    payload = packet_v2[10 : 10 + packet_v2[1]].ljust(payload_len, b"\0")[:payload_len]
    seq, sysid, compid = packet_v2[4], packet_v2[5], packet_v2[6]
    header = bytes([0xFE, payload_len, seq, sysid, compid, msg.get_msgId()])
    crc = x25crc(header[1:] + payload)
    crc.accumulate(bytes([msg.crc_extra]))
    return header + payload + struct.pack("<H", crc.crc)


def mav(src: int = 1, comp: int = 1) -> Any:
    return apm.MAVLink(None, srcSystem=src, srcComponent=comp)


@dataclass
class Tlog:
    """Records ``[stamp][packet]`` in order; ``packets[i]`` is the packet of record i."""

    stamps_us: list[int] = field(default_factory=list)
    packets: list[bytes] = field(default_factory=list)
    names: list[str] = field(default_factory=list)

    def add(self, stamp_us: int, link: Any, msg: Any, *, v1_len: int | None = None) -> None:
        """Append ``msg``; with ``v1_len``, as a MAVLink 1 packet of that payload length."""
        self.stamps_us.append(stamp_us)
        packet = msg.pack(link)
        self.packets.append(packet if v1_len is None else mavlink1(packet, msg, v1_len))
        link.seq = (link.seq + 1) % 256
        self.names.append(msg.get_type())

    def records(self) -> list[bytes]:
        return [struct.pack(">Q", t) + p for t, p in zip(self.stamps_us, self.packets, strict=True)]

    def write(self, path: Path, records: list[bytes] | None = None) -> Path:
        path.write_bytes(b"".join(records if records is not None else self.records()))
        return path

    def count(self, name: str) -> int:
        return self.names.count(name)


@dataclass(frozen=True)
class DriveSpec:
    seconds: float = 4.0
    imu_hz: int = 50
    seed: int = 0
    mavlink1_gps: bool = False


def tlog_drive(spec: DriveSpec = DriveSpec()) -> Tlog:
    """A vehicle at rest (see the module docstring), records in time order."""
    rng = np.random.default_rng(spec.seed)
    link = mav()
    log = Tlog()
    n = round(spec.seconds * spec.imu_hz)
    step_us = 1_000_000 // spec.imu_hz
    for i in range(n):
        boot_us = BOOT_US + i * step_us
        stamp = UTC0_US + (boot_us - BOOT_US) + LATENCY_US
        boot_ms = boot_us // 1000
        acc_mg = np.rint(np.array([0.0, 0.0, -1000.0]) + rng.normal(0, 2, 3)).astype(int)
        gyro_mrad = np.rint(rng.normal(0, 1, 3)).astype(int)
        log.add(stamp, link, link.raw_imu_encode(boot_us, *acc_mg, *gyro_mrad, 10, 20, 30, 0))
        log.add(stamp, link, link.scaled_imu2_encode(boot_ms, *acc_mg, *gyro_mrad, 10, 20, 30))
        acc = np.array([0.0, 0.0, -G]) + rng.normal(0, 0.01, 3)
        gyro = rng.normal(0, 1e-3, 3)
        log.add(
            stamp,
            link,
            link.highres_imu_encode(boot_us, *acc, *gyro, 0, 0, 0, 0, 0, 0, 20.0, 0x3F, 0),
        )
        if i % (spec.imu_hz // 10) == 0:
            log.add(stamp, link, link.attitude_encode(boot_ms, 0.01, -0.02, 1.5, 0, 0, 0))
            log.add(
                stamp,
                link,
                link.simstate_encode(0.01, -0.02, 1.5, 0, 0, -G, 0, 0, 0, LAT_E7, LON_E7),
            )
            log.add(
                stamp,
                link,
                link.global_position_int_encode(
                    boot_ms, LAT_E7, LON_E7, ALT_MM, 5000, 10, -20, 30, 8594
                ),
            )
        if i % (spec.imu_hz // 5) == 0:
            gps = link.gps_raw_int_encode(
                boot_us,
                3,
                LAT_E7,
                LON_E7,
                ALT_MM,
                121,
                200,
                15,
                9000,
                12,
                alt_ellipsoid=ALT_ELL_MM,
                h_acc=1500,
                v_acc=2500,
                vel_acc=300,
            )
            log.add(stamp, link, gps, v1_len=GPS_RAW_INT_V1_LEN if spec.mavlink1_gps else None)
        if i % spec.imu_hz == 0:
            log.add(stamp, link, link.system_time_encode(UTC0_US + boot_us - BOOT_US, boot_ms))
    return log


# --------------------------------------------------------------------------------- DataFlash
FMT_TYPE = 128
DF_FORMATS: dict[str, tuple[int, str, str]] = {
    "IMU": (162, "QBffffffIIfBBHH", "TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,EG,EA,T,GH,AH,GHz,AHz"),
    "GPS": (
        87,
        "QBBIHBcLLeffffB",
        "TimeUS,I,Status,GMS,GWk,NSats,HDop,Lat,Lng,Alt,Spd,GCrs,VZ,Yaw,U",
    ),
    "GPA": (88, "QBCCCCfBIHf", "TimeUS,I,VDop,HAcc,VAcc,SAcc,YAcc,VV,SMS,Delta,Und"),
    "XKF1": (44, "QBccCfffffffccce", "TimeUS,C,Roll,Pitch,Yaw,VN,VE,VD,dPD,PN,PE,PD,GX,GY,GZ,OH"),
    "ORGN": (69, "QBLLe", "TimeUS,Type,Lat,Lng,Alt"),
    "PARM": (32, "QNff", "TimeUS,Name,Value,Default"),
}


def _codes(fmt: str) -> str:
    return "<" + "".join(FORMAT_TO_STRUCT[c][0] for c in fmt)


class DfLog:
    """DataFlash records packed with ``struct`` (values raw: cdeg ints for ``c``, ...)."""

    def __init__(self) -> None:
        self.records: list[bytes] = []
        self.names: list[str] = []
        self.formats: dict[str, tuple[int, str, str]] = {}

    def fmt(self, name: str, spec: tuple[int, str, str] | None = None) -> None:
        type_, fmt, cols = spec or DF_FORMATS.get(name, (FMT_TYPE, "BBnNZ", ""))
        if name == "FMT":
            type_, fmt, cols = FMT_TYPE, "BBnNZ", "Type,Length,Name,Format,Columns"
        length = 3 + struct.calcsize(_codes(fmt))
        body = struct.pack("<BB4s16s64s", type_, length, name.encode(), fmt.encode(), cols.encode())
        self.records.append(b"\xa3\x95\x80" + body)
        self.names.append("FMT")
        self.formats[name] = (type_, fmt, cols)

    def write(self, name: str, *values: Any) -> None:
        type_, fmt, _ = self.formats[name]
        self.records.append(bytes([0xA3, 0x95, type_]) + struct.pack(_codes(fmt), *values))
        self.names.append(name)

    def data(self) -> bytes:
        return b"".join(self.records)

    def save(self, path: Path, data: bytes | None = None) -> Path:
        path.write_bytes(self.data() if data is None else data)
        return path


GWK, GMS0 = 2269, 378_756_400  # 2023-07-06


def df_drive(seconds: float = 4.0, imu_hz: int = 50, *, week: int = GWK) -> DfLog:
    """A vehicle at rest: IMU I=0,1 at ``imu_hz``, GPS+GPA 5 Hz, XKF1 C=0,1 10 Hz, ORGN."""
    rng = np.random.default_rng(1)
    log = DfLog()
    log.fmt("FMT")
    for name in DF_FORMATS:
        log.fmt(name)
    log.write("PARM", 1_000, b"FORMAT_VERSION".ljust(16, b"\0"), 120.0, 120.0)
    n = round(seconds * imu_hz)
    step = 1_000_000 // imu_hz
    t0 = 50_000_000
    log.write("ORGN", t0, 0, 528_070_002, -41_222_271, 1753)
    for i in range(n):
        t = t0 + i * step
        for inst in (0, 1):
            gyro = rng.normal(0, 1e-3, 3)
            acc = np.array([0.0, 0.0, -G]) + rng.normal(0, 0.01, 3)
            log.write("IMU", t + inst, inst, *gyro, *acc, 0, 0, 40.0, 1, 1, 8000, 4000)
        if i % (imu_hz // 5) == 0:
            gms = GMS0 + (i * step) // 1000
            log.write(
                "GPS",
                t + 10,
                0,
                3,
                gms,
                week,
                21,
                59,
                528_069_428,
                -41_224_417,
                1772,
                0.5,
                90.0,
                -0.1,
                0.0,
                1,
            )
            log.write("GPA", t + 20, 0, 85, 27, 36, 8, 0.0, 1, t // 1000, 200, -50.507)
        if i % (imu_hz // 10) == 0:
            for core in (0, 1):
                log.write(
                    "XKF1",
                    t + 30 + core,
                    core,
                    -42,
                    38,
                    33008,
                    0.1,
                    0.2,
                    -0.05,
                    0.0,
                    2.0,
                    -3.0,
                    0.5,
                    4,
                    4,
                    0,
                    1968,
                )
    return log


# -------------------------------------------------------------------------------------- ULog
ULOG_MAGIC = b"ULog\x01\x12\x35"


class UlogLog:
    """A minimal ULog file (header, formats, subscriptions, data) packed with ``struct``."""

    def __init__(self) -> None:
        self.parts: list[bytes] = [ULOG_MAGIC + bytes([1]) + struct.pack("<Q", 0)]
        self.ids: dict[tuple[str, int], tuple[int, str]] = {}

    def _msg(self, kind: bytes, body: bytes) -> None:
        self.parts.append(struct.pack("<H", len(body)) + kind + body)

    def info(self, key: str, value: str) -> None:
        k = f"char[{len(value)}] {key}".encode()
        self._msg(b"I", bytes([len(k)]) + k + value.encode())

    def format(self, name: str, fields: str, codes: str) -> None:
        """``fields`` as ULog declares them; ``codes`` the struct codes of one sample."""
        self._msg(b"F", f"{name}:{fields}".encode())
        self.ids[(name, -1)] = (-1, codes)

    def subscribe(self, name: str, multi_id: int = 0) -> None:
        msg_id = len([k for k in self.ids if k[1] >= 0])
        self._msg(b"A", struct.pack("<BH", multi_id, msg_id) + name.encode())
        self.ids[(name, multi_id)] = (msg_id, self.ids[(name, -1)][1])

    def data(self, name: str, *values: Any, multi_id: int = 0) -> None:
        msg_id, codes = self.ids[(name, multi_id)]
        self._msg(b"D", struct.pack("<H", msg_id) + struct.pack("<" + codes, *values))

    def bytes(self) -> bytes:
        return b"".join(self.parts)


def ulog_drive(
    seconds: float = 2.0,
    imu_hz: int = 200,
    *,
    gps: bool = True,
    formats: tuple[tuple[str, str, str], ...] = (),
) -> UlogLog:
    """sensor_combined at ``imu_hz`` at rest, vehicle_gps_position at 5 Hz with UTC time;
    ``formats`` (name, fields, struct codes) are declared too, for a test's own topics."""
    rng = np.random.default_rng(3)
    ulog = UlogLog()
    ulog.info("sys_name", "PX4")
    ulog.format(
        "sensor_combined",
        "uint64_t timestamp;float[3] gyro_rad;float[3] accelerometer_m_s2;",
        "Q3f3f",
    )
    gps_fields = (
        "uint64_t timestamp;uint64_t time_utc_usec;int32_t lat;int32_t lon;int32_t alt;"
        "int32_t alt_ellipsoid;float s_variance_m_s;float eph;float epv;float vel_n_m_s;"
        "float vel_e_m_s;float vel_d_m_s;uint8_t fix_type;bool vel_ned_valid;"
        "uint8_t satellites_used;"
    )
    ulog.format("vehicle_gps_position", gps_fields, "QQiiiiffffffB?B")
    for fmt in formats:
        ulog.format(*fmt)
    ulog.subscribe("sensor_combined")
    if gps:
        ulog.subscribe("vehicle_gps_position")
    n = round(seconds * imu_hz)
    for i in range(n):
        t = 10_000_000 + i * (1_000_000 // imu_hz)
        gyro = rng.normal(0, 1e-3, 3)
        acc = np.array([0.0, 0.0, -G]) + rng.normal(0, 0.02, 3)
        ulog.data("sensor_combined", t, *gyro, *acc)
        if gps and i % (imu_hz // 5) == 0:
            ulog.data(
                "vehicle_gps_position",
                t,
                UTC0_US + t,
                634_170_622,
                104_082_151,
                66_814,
                106_766,
                0.3,
                1.2,
                2.1,
                0.1,
                -0.2,
                0.05,
                3,
                True,
                15,
            )
    return ulog


# --------------------------------------------------------------------- large generated drives
def write_tlog_drive(path: Path, seconds: float) -> Path:
    link = apm.MAVLink(None, srcSystem=1, srcComponent=1)
    rng = np.random.default_rng(0)
    utc0, boot0 = 1_700_000_000 * 10**6, 50_000_000
    chunks: list[bytes] = []

    def add(t_us: int, msg: object) -> None:
        packet = msg.pack(link)  # type: ignore[attr-defined]
        link.seq = (link.seq + 1) % 256
        chunks.append(struct.pack(">Q", t_us) + packet)

    n = round(seconds * 200)
    acc = np.array([0.0, 0.0, -9.80665]) + rng.normal(0, 0.02, (n, 3))
    gyro = rng.normal(0, 1e-3, (n, 3))
    for i in range(n):
        boot = boot0 + i * 5_000
        stamp = utc0 + i * 5_000 + 2_000
        a, g = acc[i].tolist(), gyro[i].tolist()
        add(stamp, link.highres_imu_encode(boot, *a, *g, 0, 0, 0, 0, 0, 0, 20.0, 0x3F, 0))
        mg = [round(v * 1000 / 9.80665) for v in a]
        add(stamp, link.raw_imu_encode(boot, *mg, *(round(v * 1000) for v in g), 0, 0, 0))
        if i % 20 == 0:
            ms = boot // 1000
            add(stamp, link.attitude_encode(ms, 0.01, 0.02, 1.0, 0.0, 0.0, 0.0))
            add(
                stamp,
                link.global_position_int_encode(
                    ms, 523_456_789, -41_234_567, 120_000, 5_000, 10, 20, 0, 9000
                ),
            )
        if i % 40 == 0:
            add(
                stamp,
                link.gps_raw_int_encode(
                    boot,
                    3,
                    523_456_789,
                    -41_234_567,
                    120_000,
                    90,
                    150,
                    10,
                    9000,
                    14,
                    alt_ellipsoid=170_000,
                    h_acc=900,
                    v_acc=1500,
                    vel_acc=200,
                ),
            )
        if i % 200 == 0:
            add(stamp, link.system_time_encode(utc0 + boot - boot0, boot // 1000))
    path.write_bytes(b"".join(chunks))
    return path


def _df_length(fmt: str) -> int:
    return 3 + struct.calcsize(_codes(fmt))


def _df_block(name: str, n: int, values: dict[str, Any]) -> np.ndarray:
    """``n`` DataFlash records of ``name`` (header + payload) as one structured array."""
    type_, fmt, cols = DF_FORMATS[name]
    payload = make_format(type_, _df_length(fmt), name, fmt, tuple(cols.split(",")))
    dtype = np.dtype([("h1", "u1"), ("h2", "u1"), ("type", "u1"), ("p", payload.dtype)])
    out = np.zeros(n, dtype)
    out["h1"], out["h2"], out["type"] = 0xA3, 0x95, type_
    for key, v in values.items():
        out["p"][key] = v
    return out


def write_dataflash_drive(path: Path, seconds: float) -> Path:
    """Three IMUs at 400 Hz, GPS+GPA at 5 Hz, three EKF cores at 10 Hz, in time order."""
    rng = np.random.default_rng(1)
    head = b""
    fmt_fmt = {"FMT": (128, "BBnNZ", "Type,Length,Name,Format,Columns")}
    for name, (type_, fmt, cols) in (fmt_fmt | DF_FORMATS).items():
        length = _df_length(fmt)
        head += b"\xa3\x95\x80" + struct.pack(
            "<BB4s16s64s", type_, length, name.encode(), fmt.encode(), cols.encode()
        )
    t0, n, m, k = 30_000_000, round(seconds * 400), round(seconds * 5), round(seconds * 10)
    t_imu = t0 + np.arange(n, dtype=np.int64) * 2_500
    t_gps = t0 + np.arange(m, dtype=np.int64) * 200_000
    t_ekf = t0 + np.arange(k, dtype=np.int64) * 100_000
    parts: list[tuple[np.ndarray, np.ndarray]] = []
    for inst in range(3):
        imu = {"TimeUS": t_imu + inst, "I": inst, "GyrX": rng.normal(0, 1e-3, n)}
        imu |= {"AccZ": -9.80665 + rng.normal(0, 0.02, n), "GHz": 8000, "AHz": 4000}
        parts.append((t_imu + inst, _df_block("IMU", n, imu)))
    gps: dict[str, Any] = {"TimeUS": t_gps, "Status": 3, "GWk": 2269, "NSats": 20, "HDop": 60}
    gps |= {"GMS": 378_756_400 + np.arange(m) * 200, "Lat": 528_069_428, "Lng": -41_224_417}
    gps |= {"Alt": 1772, "Spd": 0.1, "U": 1}
    parts.append((t_gps, _df_block("GPS", m, gps)))
    gpa = {"TimeUS": t_gps + 10, "HAcc": 30, "VAcc": 40, "SAcc": 8, "VV": 1, "Und": -50.5}
    parts.append((t_gps + 10, _df_block("GPA", m, gpa)))
    for core in range(3):
        ekf = {"TimeUS": t_ekf + 20 + core, "C": core, "Yaw": 9000, "PN": 1.0, "PE": 2.0}
        parts.append((t_ekf + 20 + core, _df_block("XKF1", k, ekf)))
    orgn = {"TimeUS": t0, "Type": 0, "Lat": 528_069_428, "Lng": -41_224_417, "Alt": 1772}
    parts.append((np.array([t0]), _df_block("ORGN", 1, orgn)))
    times = np.concatenate([t for t, _ in parts])
    records = [r[i : i + 1].tobytes() for _, rec in parts for r in (rec,) for i in range(len(r))]
    order = np.argsort(times, kind="stable").tolist()
    path.write_bytes(head + b"".join(records[i] for i in order))
    return path
