"""Log readers, one module per format, looked up by detected format.

``REGISTRY`` maps a ``Format`` to ``"module:Class"`` of its ``LogReader`` subclass (imported
lazily, so ``navreplay --help`` does not load numba or rosbags). A later reader adds one line
here and its module; see ``ingest.readers.base`` for the contract.
"""

from __future__ import annotations

import importlib

from navreplay.ingest.detect import Detected, Format
from navreplay.ingest.errors import UnsupportedFormatError
from navreplay.ingest.readers.base import LogReader, ReadContext

REGISTRY: dict[Format, str] = {
    Format.MCAP: "navreplay.ingest.readers.ros.mcap:McapReader",
    Format.ROS1BAG: "navreplay.ingest.readers.ros.ros1bag:Ros1BagReader",
    Format.ROS2BAG: "navreplay.ingest.readers.ros.ros2bag:Ros2BagReader",
    Format.CSV: "navreplay.ingest.readers.tabular.csv:CsvReader",
    Format.RINEX: "navreplay.ingest.readers.gnss.rinex:RinexReader",
    Format.GNSSLOGGER: "navreplay.ingest.readers.gnss.gnsslogger:GnssLoggerReader",
    Format.GSDC: "navreplay.ingest.readers.gnss.gsdc:GsdcReader",
    Format.TLOG: "navreplay.ingest.readers.mavlink.tlog:TlogReader",
    Format.DATAFLASH: "navreplay.ingest.readers.mavlink.dataflash:DataFlashReader",
    Format.ULOG: "navreplay.ingest.readers.ulog.ulog:UlogReader",
    Format.COMMA2K19: "navreplay.ingest.readers.tabular.comma2k19:Comma2k19Reader",
    Format.LIBRSF: "navreplay.ingest.readers.gnss.librsf:LibrsfReader",
    Format.NMEA: "navreplay.ingest.readers.gnss.nmea:NmeaReader",
}


def open_reader(detected: Detected, ctx: ReadContext) -> LogReader:
    """The reader for ``detected.format``.

    Raises:
        UnsupportedFormatError: the format is recognised but no reader is registered yet.
    """
    target = REGISTRY.get(detected.format)
    if target is None:
        known = ", ".join(f.value for f in REGISTRY)
        raise UnsupportedFormatError(
            f"recognised as {detected.format.value}, which this version cannot convert yet "
            f"(readers: {known})",
            path=detected.path,
        )
    module, _, name = target.partition(":")
    cls = getattr(importlib.import_module(module), name)
    reader = cls(detected, ctx)
    assert isinstance(reader, LogReader)
    return reader
