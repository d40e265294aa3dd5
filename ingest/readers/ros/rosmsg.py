"""ROS message definitions decoded straight into column arrays (ROS 1 and CDR encodings).

A message type is flattened once into a list of leaves (``header.stamp.sec``,
``linear_acceleration.x``, ``position_covariance`` ...). A batch of serialized messages of
one type is decoded leaf by leaf with numpy: the position of every leaf in every message is
an int64 array, advanced by the fixed size of primitives and by the lengths read from the
messages for strings and sequences (CDR alignment applied relative to each message's origin),
and the requested leaves are gathered from the buffer with one fancy index each. No Python
runs per message, which is what makes ingest faster than deserializing message objects.

Types the vectorised plan cannot express (sequences of messages or strings, wstring,
float128) fall back to rosbags' generated deserializers, one message at a time.

Definitions come from the log itself (ROS 1 connection headers, MCAP schemas, rosbag2
message_definitions) and are parsed with rosbags' ``get_types_from_msg`` /
``get_types_from_idl``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from enum import Enum
from typing import Any, Literal

import numpy as np
import numpy.typing as npt
from rosbags.interfaces import Nodetype
from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore
from rosbags.typesys.base import TypesysError

from navreplay.ingest.arrays import I64, U8
from navreplay.ingest.errors import IngestError

Encoding = Literal["ros1", "cdr"]

_PRIMS: dict[str, tuple[str, int]] = {
    "bool": ("u1", 1),
    "byte": ("u1", 1),
    "char": ("u1", 1),
    "int8": ("i1", 1),
    "uint8": ("u1", 1),
    "int16": ("i2", 2),
    "uint16": ("u2", 2),
    "int32": ("i4", 4),
    "uint32": ("u4", 4),
    "int64": ("i8", 8),
    "uint64": ("u8", 8),
    "float32": ("f4", 4),
    "float64": ("f8", 8),
}
_TIME_TYPES = ("builtin_interfaces/msg/Time", "builtin_interfaces/msg/Duration")
_AR = {k: np.arange(k, dtype=np.int64) for k in (1, 2, 4, 8)}


class DefinitionError(IngestError):
    """A message definition cannot be parsed, or a payload does not fit its definition."""


class LeafKind(Enum):
    PRIM = "prim"
    STRING = "string"
    SEQ = "seq"


@dataclass(frozen=True)
class Leaf:
    """One flattened field: a primitive (scalar or fixed array), a string or a sequence.

    Attributes:
        path: dotted path, e.g. ``header.stamp.sec`` or ``pose.covariance``.
        kind: PRIM, STRING or SEQ (a sequence of primitives).
        dtype: numpy type code without byte order (``f8``, ``u4`` ...); ``u1`` for strings.
        size: element size in bytes.
        count: elements of a fixed array (1 for a scalar).
    """

    path: str
    kind: LeafKind
    dtype: str
    size: int
    count: int = 1


def normalize_msgtype(name: str) -> str:
    """``sensor_msgs/Imu`` -> ``sensor_msgs/msg/Imu`` (ROS 2 spelling used throughout)."""
    parts = name.strip().split("/")
    if len(parts) == 2:
        return f"{parts[0]}/msg/{parts[1]}"
    return name.strip()


def parse_definition(msgtype: str, text: str, fmt: Literal["msg", "idl"] = "msg") -> dict[str, Any]:
    """Parse a message definition (with its dependencies) into a rosbags typesdict.

    ``msg`` covers ROS 1 connection definitions and ROS 2 ``ros2msg`` schemas (dependencies
    after ``=====`` / ``MSG:`` separators); ``idl`` covers ``ros2idl``.

    Raises:
        DefinitionError: the text does not parse.
    """
    try:
        if fmt == "idl":
            types: dict[str, Any] = {}
            sep = "=" * 80 + "\n"
            parts = text.split(sep)[1:] if text.startswith(f"{sep}IDL: ") else [text]
            for part in parts:
                body = part.split("\n", 1)[1] if part.startswith("IDL: ") else part
                types.update(get_types_from_idl(body))
            return types
        return dict(get_types_from_msg(text, normalize_msgtype(msgtype)))
    except (TypesysError, ValueError, IndexError) as err:
        raise DefinitionError(
            f"cannot parse the definition of {msgtype}: {err}", record=msgtype
        ) from err


def flatten(msgtype: str, types: Mapping[str, Any], encoding: Encoding) -> tuple[list[Leaf], bool]:
    """Flatten ``msgtype`` into leaves; the flag is False when it needs the fallback decoder.

    Raises:
        DefinitionError: a referenced type is not defined.
    """
    leaves: list[Leaf] = []
    ok = _flatten_into(normalize_msgtype(msgtype), types, encoding, "", leaves, 0)
    return leaves, ok


def _time_fields(encoding: Encoding) -> list[tuple[str, Any]]:
    sec = "uint32" if encoding == "ros1" else "int32"
    return [
        ("sec", (Nodetype.BASE, (sec, 0))),
        ("nanosec", (Nodetype.BASE, ("uint32", 0))),
    ]


def _fields_of(name: str, types: Mapping[str, Any], encoding: Encoding) -> list[tuple[str, Any]]:
    if name in types:
        return list(types[name][1])
    if name in _TIME_TYPES:
        return _time_fields(encoding)
    store = _default_store()
    if name in store.fielddefs:
        return list(store.fielddefs[name][1])
    raise DefinitionError(f"message type {name} is used but not defined", record=name)


def _flatten_into(
    name: str,
    types: Mapping[str, Any],
    encoding: Encoding,
    prefix: str,
    out: list[Leaf],
    depth: int,
) -> bool:
    if depth > 32:
        raise DefinitionError(f"message type {name} nests too deeply (recursive?)", record=name)
    ok = True
    for fname, desc in _fields_of(name, types, encoding):
        path = f"{prefix}{fname}"
        node, arg = desc
        if node == Nodetype.BASE:
            ok &= _leaf(path, arg[0], 1, out)
        elif node == Nodetype.NAME:
            ok &= _flatten_into(arg, types, encoding, f"{path}.", out, depth + 1)
        elif node == Nodetype.ARRAY:
            ok &= _flatten_array(path, arg, types, encoding, out, depth)
        else:  # SEQUENCE: of primitives only; of messages or strings needs the fallback
            (sub_node, sub_arg), _bound = arg
            if sub_node != Nodetype.BASE or sub_arg[0] not in _PRIMS:
                ok = False
                continue
            dtype, size = _PRIMS[sub_arg[0]]
            out.append(Leaf(path, LeafKind.SEQ, dtype, size))
    return ok


def _flatten_array(
    path: str,
    arg: Any,
    types: Mapping[str, Any],
    encoding: Encoding,
    out: list[Leaf],
    depth: int,
) -> bool:
    (sub_node, sub_arg), count = arg
    if sub_node == Nodetype.BASE and sub_arg[0] in _PRIMS:
        return _leaf(path, sub_arg[0], count, out)
    ok = True
    for i in range(count):
        if sub_node == Nodetype.BASE:
            ok &= _leaf(f"{path}[{i}]", sub_arg[0], 1, out)
        else:
            ok &= _flatten_into(sub_arg, types, encoding, f"{path}[{i}].", out, depth + 1)
    return ok


def _leaf(path: str, base: str, count: int, out: list[Leaf]) -> bool:
    if base in _PRIMS:
        dtype, size = _PRIMS[base]
        out.append(Leaf(path, LeafKind.PRIM, dtype, size, count))
        return True
    if base == "string":
        out.append(Leaf(path, LeafKind.STRING, "u1", 1))
        return True
    return False  # wstring, float128


_STORE: Any = None


def _default_store() -> Any:
    global _STORE  # noqa: PLW0603 (one shared, immutable standard-type store)
    if _STORE is None:
        _STORE = get_typestore(Stores.LATEST)
    return _STORE


@dataclass(frozen=True)
class Decoded:
    """Decoded leaves of a batch.

    Attributes:
        values: leaf path -> array (n,) or (n, count); rows flagged in ``bad`` hold garbage.
        strings: leaf path -> the value in the first message.
        bad: rows whose payload does not fit the definition (too short, too long, bad
            header); None when every row fits.
        reason: why the first bad row does not fit.
    """

    values: dict[str, np.ndarray]
    strings: dict[str, str]
    bad: npt.NDArray[np.bool_] | None = None
    reason: str = ""


class MessageDecoder:
    """Decode batches of one message type, vectorised when the type allows it.

    Args:
        msgtype: the type name.
        types: typesdict with the type and its dependencies (``parse_definition``).
        encoding: ``ros1`` (little endian, packed) or ``cdr`` (4-byte encapsulation header,
            aligned).
    """

    def __init__(self, msgtype: str, types: Mapping[str, Any], encoding: Encoding) -> None:
        self.msgtype = normalize_msgtype(msgtype)
        self.types = dict(types)
        self.encoding = encoding
        self.leaves, self.vectorised = flatten(self.msgtype, self.types, encoding)
        self._by_path = {leaf.path: leaf for leaf in self.leaves}
        self._store: Any = None

    def leaf(self, path: str) -> Leaf | None:
        return self._by_path.get(path)

    def decode(self, buf: U8, starts: I64, ends: I64, want: Sequence[str]) -> Decoded:
        """Decode the messages ``buf[starts[i]:ends[i]]`` and return the ``want`` leaves.

        Payloads that do not fit the definition are flagged in ``Decoded.bad``, never read
        out of the buffer.
        """
        if len(starts) == 0:
            return Decoded({p: self._empty(p) for p in want}, {})
        if not self.vectorised:
            return self._decode_fallback(buf, starts, ends, want)
        return self._decode_vectorised(buf, starts, ends, set(want))

    def _empty(self, path: str) -> np.ndarray:
        leaf = self._by_path[path]
        shape = (0,) if leaf.count == 1 else (0, leaf.count)
        return np.empty(shape, dtype=np.dtype(leaf.dtype))

    def _decode_vectorised(self, buf: U8, starts: I64, ends: I64, want: set[str]) -> Decoded:
        cdr = self.encoding == "cdr"
        check = _Checker(starts, ends)
        big = _cdr_big_endian(buf, starts, check) if cdr else False
        if not len(buf):
            check.fail(np.ones(len(starts), bool), "payload is empty")
            return check.decoded({p: self._zeros(p, len(starts)) for p in want}, {})
        origin = starts + 4 if cdr else starts
        pos = origin.copy()
        order = ">" if big else "<"
        values: dict[str, np.ndarray] = {}
        strings: dict[str, str] = {}
        for leaf in self.leaves:
            if leaf.kind == LeafKind.PRIM:
                if cdr and leaf.size > 1:
                    pos = _align(pos, origin, leaf.size)
                nbytes = leaf.size * leaf.count
                if leaf.path in want:
                    check.bound(pos + nbytes, f"ends before field {leaf.path}")
                    idx = pos[:, None] + np.arange(nbytes, dtype=np.int64)
                    arr = np.take(buf, idx, mode="clip").view(order + leaf.dtype)
                    values[leaf.path] = arr[:, 0] if leaf.count == 1 else arr
                pos = pos + nbytes
            else:
                pos = self._skip_variable(leaf, buf, pos, origin, check, big, want, strings)
        spare = ends - pos
        check.fail(
            (spare < 0) | (spare > (3 if cdr else 0)),
            f"payload length does not match the definition of {self.msgtype}",
        )
        return check.decoded(values, strings)

    def _zeros(self, path: str, n: int) -> np.ndarray:
        leaf = self._by_path.get(path)
        if leaf is None:
            return np.zeros(n)
        shape = (n,) if leaf.count == 1 else (n, leaf.count)
        return np.zeros(shape, dtype=np.dtype(leaf.dtype))

    def _skip_variable(
        self,
        leaf: Leaf,
        buf: U8,
        pos: I64,
        origin: I64,
        check: _Checker,
        big: bool,
        want: set[str],
        strings: dict[str, str],
    ) -> I64:
        """Advance past a string or sequence (reading its length); sample wanted strings."""
        cdr = self.encoding == "cdr"
        if cdr:
            pos = _align(pos, origin, 4)
        check.bound(pos + 4, f"ends before the length of {leaf.path}")
        pos = check.safe(pos)
        length = _read_u32(buf, pos, big)
        pos = pos + 4
        if leaf.kind == LeafKind.STRING:
            if leaf.path in want and len(pos):
                first = int(pos[0])
                raw_s = bytes(buf[first : first + int(length[0])])
                strings[leaf.path] = raw_s.rstrip(b"\x00").decode("utf-8", "replace")
            pos = pos + length
        else:
            if cdr and leaf.size > 1:
                pos = np.where(length > 0, _align(pos, origin, leaf.size), pos)
            pos = pos + length * leaf.size
        check.bound(pos, f"field {leaf.path} runs past the end of the payload")
        return check.safe(pos)

    def _decode_fallback(self, buf: U8, starts: I64, ends: I64, want: Sequence[str]) -> Decoded:
        store = self._fallback_store()
        check = _Checker(starts, ends)
        rows: list[object | None] = []
        bad = np.zeros(len(starts), bool)
        for i, (s, e) in enumerate(zip(starts.tolist(), ends.tolist(), strict=True)):
            raw = buf[s:e].tobytes()
            try:
                if self.encoding == "cdr":
                    rows.append(store.deserialize_cdr(raw, self.msgtype))
                else:
                    rows.append(store.deserialize_ros1(raw, self.msgtype))
            except Exception as err:
                rows.append(None)
                if not bad.any():
                    check.reason = f"cannot deserialize: {err}"
                bad[i] = True
        check.fail(bad, check.reason)
        values: dict[str, np.ndarray] = {}
        strings: dict[str, str] = {}
        good = [m for m in rows if m is not None]
        for path in want:
            leaf = self._by_path.get(path)
            if leaf is None:
                continue
            if leaf.kind == LeafKind.STRING:
                if good:
                    strings[path] = str(_get_path(good[0], path))
                continue
            filler = self._zeros(path, 1)[0]
            got = [filler if m is None else _get_path(m, path) for m in rows]
            values[path] = np.asarray(got, dtype=np.dtype(leaf.dtype))
        return check.decoded(values, strings)

    def _fallback_store(self) -> Any:
        if self._store is None:
            store = get_typestore(Stores.EMPTY)
            store.register(_with_dependencies(self.types))
            self._store = store
        return self._store


def _with_dependencies(types: Mapping[str, Any]) -> dict[str, Any]:
    """``types`` plus the standard types they reference but do not define."""
    out = dict(types)
    default = _default_store().fielddefs
    todo = list(out)
    while todo:
        for _fname, (node, arg) in out[todo.pop()][1]:
            ref = None
            if node == Nodetype.NAME:
                ref = arg
            elif node in (Nodetype.ARRAY, Nodetype.SEQUENCE) and arg[0][0] == Nodetype.NAME:
                ref = arg[0][1]
            if ref is not None and ref not in out and ref in default:
                out[ref] = default[ref]
                todo.append(ref)
    return out


class _Checker:
    """Per-row validity while decoding: a bad row is flagged, never read out of bounds."""

    def __init__(self, starts: I64, ends: I64) -> None:
        self.starts = starts
        self.ends = ends
        self.bad = np.zeros(len(starts), bool)
        self.reason = ""

    def fail(self, mask: npt.NDArray[np.bool_], reason: str) -> None:
        new = mask & ~self.bad
        if new.any() and not self.bad.any():
            i = int(np.flatnonzero(new)[0])
            self.reason = f"{reason} (payload of {int(self.ends[i] - self.starts[i])} bytes)"
        self.bad |= mask

    def bound(self, need: I64, what: str) -> None:
        self.fail(need > self.ends, f"payload {what}")

    def safe(self, pos: I64) -> I64:
        """Positions of bad rows reset to their start so later reads stay in the buffer."""
        return np.where(self.bad, self.starts, pos) if self.bad.any() else pos

    def decoded(self, values: dict[str, np.ndarray], strings: dict[str, str]) -> Decoded:
        if not self.bad.any():
            return Decoded(values, strings)
        return Decoded(values, strings, self.bad, self.reason)


def _cdr_big_endian(buf: U8, starts: I64, check: _Checker) -> bool:
    """Check the 4-byte CDR encapsulation headers; True for big-endian payloads."""
    check.bound(starts + 4, "shorter than the 4-byte CDR header")
    if not len(buf):
        return False
    head = np.take(buf, starts[:, None] + _AR[2], mode="clip")
    bad = (head[:, 0] != 0) | (head[:, 1] > 1)
    check.fail(bad & ~check.bad, "unsupported CDR encapsulation header")
    flags = head[~check.bad, 1]
    if not flags.size:
        return False
    big = flags[0] == 0
    mixed = np.zeros(len(starts), bool)
    mixed[~check.bad] = flags != flags[0]
    check.fail(mixed, "payload in the other byte order than the first of its batch")
    return bool(big)


def _align(pos: I64, origin: I64, size: int) -> I64:
    rel = pos - origin
    return origin + ((rel + (size - 1)) // size) * size


def _read_u32(buf: U8, pos: I64, big: bool) -> I64:
    raw = np.take(buf, pos[:, None] + _AR[4], mode="clip")
    return np.asarray(raw.view(">u4" if big else "<u4")[:, 0], dtype=np.int64)


def _get_path(obj: object, path: str) -> Any:
    for part in path.split("."):
        if part.endswith("]"):
            name, idx = part[:-1].split("[")
            obj = getattr(obj, name)[int(idx)]
        else:
            obj = getattr(obj, part)
    return obj
