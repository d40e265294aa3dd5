"""MAVLink message definitions from pymavlink's generated dialects, as numpy-ready tables.

pymavlink generates one module per dialect (``pymavlink.dialects.v20.<name>``) whose message
classes carry everything needed to frame, check and decode a packet: the CRC seed
``crc_extra``, the wire order of the fields (``ordered_fieldnames``: largest type first, then
MAVLink 2 extensions), their C types and array lengths. ``Dialect`` turns those into

- per-msgid lookup arrays for the compiled framing scan (``crc_extra``, known ids), and
- a numpy structured dtype per message, so a block of payloads (MAVLink 2 zero-trimmed
  payloads padded back to full length) is decoded with one ``view`` instead of a
  ``struct.unpack`` per packet.

The dtype of every message is checked against pymavlink's own ``struct`` format size.
"""

from __future__ import annotations

import importlib
from collections.abc import Mapping
from dataclasses import dataclass
from functools import cache
from types import ModuleType
from typing import Any

import numpy as np
import numpy.typing as npt

from navreplay.ingest.errors import ConfigError

DEFAULT_DIALECT = "ardupilotmega"
MAX_MSGID = 1 << 24  # MAVLink 2 message ids are 24-bit

_CTYPES = {
    "uint8_t": "u1",
    "uint8_t_mavlink_version": "u1",
    "int8_t": "i1",
    "uint16_t": "<u2",
    "int16_t": "<i2",
    "uint32_t": "<u4",
    "int32_t": "<i4",
    "uint64_t": "<u8",
    "int64_t": "<i8",
    "float": "<f4",
    "double": "<f8",
}


@dataclass(frozen=True)
class MessageDef:
    """One message of a dialect.

    Attributes:
        msgid: the MAVLink message id.
        name: its name (``RAW_IMU``).
        crc_extra: the CRC seed byte derived from the definition.
        dtype: packed little-endian structured dtype of the full (MAVLink 2) payload, fields
            in wire order; ``char[n]`` fields are ``S{n}``, other arrays sub-arrays.
        offsets: field name -> byte offset in the payload.
    """

    msgid: int
    name: str
    crc_extra: int
    dtype: np.dtype[Any]
    offsets: dict[str, int]

    @property
    def length(self) -> int:
        return int(self.dtype.itemsize)


def _message_def(cls: Any) -> MessageDef:
    types = dict(zip(cls.fieldnames, cls.fieldtypes, strict=True))
    arrays = dict(zip(cls.ordered_fieldnames, cls.array_lengths, strict=True))  # wire order
    fields: list[tuple[str, str] | tuple[str, str, tuple[int]]] = []
    for name in cls.ordered_fieldnames:
        ctype, n = types[name], int(arrays[name])
        if ctype == "char":
            fields.append((name, f"S{max(n, 1)}"))
        elif n:
            fields.append((name, _CTYPES[ctype], (n,)))
        else:
            fields.append((name, _CTYPES[ctype]))
    dtype = np.dtype(fields)  # numpy packs structured dtypes (align=False)
    if dtype.itemsize != cls.unpacker.size:
        raise AssertionError(
            f"{cls.msgname}: dtype of {dtype.itemsize} bytes, pymavlink packs {cls.unpacker.size}"
        )
    placed: Mapping[str, Any] = dtype.fields or {}
    offsets = {name: int(placed[name][1]) for name in cls.ordered_fieldnames}
    return MessageDef(int(cls.id), str(cls.msgname), int(cls.crc_extra), dtype, offsets)


class Dialect:
    """The messages of one pymavlink dialect, indexed for the compiled scan and the decoder.

    Args:
        name: dialect module name under ``pymavlink.dialects.v20`` (``ardupilotmega``,
            ``common``, ...).

    Raises:
        ConfigError: pymavlink has no such dialect.
    """

    def __init__(self, name: str = DEFAULT_DIALECT) -> None:
        self.name = name
        module = _module(name)
        self._classes: dict[int, Any] = dict(module.mavlink_map)
        self._defs: dict[int, MessageDef] = {}
        top = max(self._classes) + 1
        #: crc_extra per msgid; -1 where the dialect does not define the id.
        self.crc_extra: npt.NDArray[np.int16] = np.full(top, -1, dtype=np.int16)
        for msgid, cls in self._classes.items():
            self.crc_extra[msgid] = int(cls.crc_extra)
        self.ids = {str(cls.msgname): msgid for msgid, cls in self._classes.items()}

    def __contains__(self, msgid: int) -> bool:
        return msgid in self._classes

    def message(self, msgid: int) -> MessageDef:
        """The definition of ``msgid`` (KeyError when the dialect lacks it)."""
        found = self._defs.get(msgid)
        if found is None:
            found = self._defs[msgid] = _message_def(self._classes[msgid])
        return found

    def by_name(self, name: str) -> MessageDef | None:
        msgid = self.ids.get(name)
        return None if msgid is None else self.message(msgid)

    def msg_name(self, msgid: int) -> str:
        cls = self._classes.get(msgid)
        return str(cls.msgname) if cls is not None else f"MSGID_{msgid}"


@cache
def _module(name: str) -> ModuleType:
    if not name.isidentifier():
        raise ConfigError(f"mavlink dialect {name!r} is not a module name")
    try:
        return importlib.import_module(f"pymavlink.dialects.v20.{name}")
    except ImportError as err:
        raise ConfigError(
            f"pymavlink has no MAVLink 2 dialect {name!r}",
            hint="use a module name from pymavlink/dialects/v20 (ardupilotmega, common, ...)",
        ) from err


@cache
def load_dialect(name: str = DEFAULT_DIALECT) -> Dialect:
    """The (cached) ``Dialect`` named ``name``."""
    return Dialect(name)
