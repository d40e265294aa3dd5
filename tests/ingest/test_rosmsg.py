"""The column-wise ROS decoder agrees with rosbags' own deserializer, byte for byte."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from navreplay.ingest.readers.ros.rosmsg import MessageDecoder, normalize_msgtype, parse_definition

# Every alignment case of CDR: 1-, 2-, 4- and 8-byte fields after strings and sequences of
# varying length, empty sequences (no alignment padding), fixed arrays.
ALIGN_MSG = """
uint8 a
string name
float64 x
int16[] shorts
float32[3] f3
uint8 b
float64[] doubles
int64 big
string tail
uint16 last
"""
NAME = "test_msgs/msg/Align"


def _store() -> Any:
    store = get_typestore(Stores.EMPTY)
    store.register(get_types_from_msg(ALIGN_MSG, NAME))
    return store


def _messages(store: Any, n: int, seed: int) -> list[Any]:
    rng = np.random.default_rng(seed)
    cls = store.types[NAME]
    out = []
    for _ in range(n):
        out.append(
            cls(
                a=int(rng.integers(0, 255)),
                name="n" * int(rng.integers(0, 8)),
                x=float(rng.normal()),
                shorts=rng.integers(-100, 100, int(rng.integers(0, 4))).astype(np.int16),
                f3=rng.normal(size=3).astype(np.float32),
                b=int(rng.integers(0, 255)),
                doubles=rng.normal(size=int(rng.integers(0, 3))),
                big=int(rng.integers(-(2**40), 2**40)),
                tail="t" * int(rng.integers(0, 5)),
                last=int(rng.integers(0, 65535)),
            )
        )
    return out


def _pack(payloads: list[bytes]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    lens = np.array([len(p) for p in payloads], np.int64)
    ends = np.cumsum(lens)
    return np.frombuffer(b"".join(payloads), np.uint8), ends - lens, ends


@pytest.mark.parametrize("encoding", ["cdr", "cdr-be", "ros1"])
def test_vectorised_decode_equals_rosbags_for_every_alignment_case(encoding: str) -> None:
    store = _store()
    msgs = _messages(store, 300, seed=1)
    if encoding == "ros1":
        payloads = [bytes(store.serialize_ros1(m, NAME)) for m in msgs]
    else:
        little = encoding == "cdr"
        payloads = [bytes(store.serialize_cdr(m, NAME, little_endian=little)) for m in msgs]
    buf, starts, ends = _pack(payloads)
    types = get_types_from_msg(ALIGN_MSG, NAME)
    dec = MessageDecoder(NAME, types, "ros1" if encoding == "ros1" else "cdr")
    assert dec.vectorised
    got = dec.decode(buf, starts, ends, ["a", "x", "f3", "b", "big", "last", "name"])
    assert got.bad is None
    np.testing.assert_array_equal(got.values["a"], [m.a for m in msgs])
    np.testing.assert_array_equal(got.values["x"], [m.x for m in msgs])
    np.testing.assert_array_equal(got.values["f3"], np.stack([m.f3 for m in msgs]))
    np.testing.assert_array_equal(got.values["b"], [m.b for m in msgs])
    np.testing.assert_array_equal(got.values["big"], [m.big for m in msgs])
    np.testing.assert_array_equal(got.values["last"], [m.last for m in msgs])
    assert got.strings["name"] == msgs[0].name


def test_types_the_plan_cannot_express_fall_back_to_rosbags() -> None:
    text = "geometry_msgs/Point[] points\nfloat64 z\n"
    name = "test_msgs/msg/Cloud"
    store = get_typestore(Stores.ROS2_HUMBLE)
    types = get_types_from_msg(text, name)
    store.register(types)
    point = store.types["geometry_msgs/msg/Point"]
    msgs = [
        store.types[name](points=[point(x=1.0 * i, y=0.0, z=0.0)] * (i % 3), z=0.5 * i)
        for i in range(20)
    ]
    buf, starts, ends = _pack([bytes(store.serialize_cdr(m, name)) for m in msgs])
    dec = MessageDecoder(name, types, "cdr")
    assert not dec.vectorised
    got = dec.decode(buf, starts, ends, ["z"])
    np.testing.assert_array_equal(got.values["z"], [m.z for m in msgs])  # type: ignore[attr-defined]


@pytest.mark.parametrize("encoding", ["cdr", "ros1"])
def test_payloads_that_do_not_fit_are_flagged_not_read_out_of_bounds(encoding: str) -> None:
    store = _store()
    msgs = _messages(store, 6, seed=2)
    ser = store.serialize_ros1 if encoding == "ros1" else store.serialize_cdr
    payloads = [bytes(ser(m, NAME)) for m in msgs]
    payloads[1] = b""  # case 22: zero-length payload
    payloads[3] = payloads[3][:-9]  # cut
    payloads[5] = payloads[5] + bytes(8)  # too long (more than CDR's 3 bytes of padding)
    buf, starts, ends = _pack(payloads)
    dec = MessageDecoder(NAME, get_types_from_msg(ALIGN_MSG, NAME), encoding)  # type: ignore[arg-type]
    got = dec.decode(buf, starts, ends, ["x", "big"])
    assert got.bad is not None
    assert got.bad.tolist() == [False, True, False, True, False, True]
    assert got.reason
    ok = ~got.bad
    np.testing.assert_array_equal(
        got.values["x"][ok], [m.x for m, k in zip(msgs, ok, strict=True) if k]
    )


def test_cdr_trailing_padding_up_to_three_bytes_is_accepted() -> None:
    store = _store()
    msgs = _messages(store, 4, seed=3)
    payloads = [bytes(store.serialize_cdr(m, NAME)) + bytes(k) for k, m in enumerate(msgs)]
    buf, starts, ends = _pack(payloads)
    got = MessageDecoder(NAME, get_types_from_msg(ALIGN_MSG, NAME), "cdr").decode(
        buf, starts, ends, ["big"]
    )
    assert got.bad is None


def test_ros1_time_and_header_seq_are_decoded() -> None:
    store = get_typestore(Stores.ROS1_NOETIC)
    text, _ = store.generate_msgdef("sensor_msgs/msg/Imu")
    types = parse_definition("sensor_msgs/Imu", text)
    dec = MessageDecoder("sensor_msgs/Imu", types, "ros1")
    assert dec.msgtype == "sensor_msgs/msg/Imu"
    assert dec.leaf("header.seq") is not None
    assert dec.leaf("header.stamp.sec") is not None


def test_normalize_msgtype() -> None:
    assert normalize_msgtype("sensor_msgs/Imu") == "sensor_msgs/msg/Imu"
    assert normalize_msgtype("sensor_msgs/msg/Imu") == "sensor_msgs/msg/Imu"
