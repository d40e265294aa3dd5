"""Detect a log's format from its content (magic bytes and framing), never from its extension.

``detect(path)`` returns a ``Detected`` naming the format, the files to read and a variant
(``rosbag2`` storage plugin, RINEX ``obs``/``nav`` ...). Every format navreplay knows is
recognised here, including those whose reader lives in another module (MAVLink tlog,
DataFlash, ULog, RINEX, Android GnssLogger, NMEA); a reader is then looked up by format in
``ingest.readers.REGISTRY``.

Recognisers, in order:

=============  ===============================================================================
MCAP           ``\\x89MCAP0\\r\\n``
ROS 1 bag      ``#ROSBAG V2.0\\n`` (other versions are refused with their version)
rosbag2        a directory with ``metadata.yaml``; without it, ``.mcap`` storage is read
               directly (recorded as a recovery), ``.db3`` storage is refused (reindex first)
comma2k19      a directory with ``processed_log/`` and/or ``global_pose/`` holding ``.npy``
               arrays (``\x93NUMPY``) without extension: one segment of the comma2k19 dataset
SQLite         ``SQLite format 3\\0``: a rosbag2 ``.db3`` outside its directory is refused
ULog           ``ULog\\x01\\x12\\x35``
DataFlash      ``\\xa3\\x95\\x80``: the FMT record describing FMT, always first
MAVLink tlog   ``[8-byte big-endian us since 1970][0xFE or 0xFD packet]`` repeated, checked
               over the first records
RINEX          ``RINEX VERSION / TYPE`` (or ``CRINEX VERS   / TYPE``) in columns 61-80 of line
               1; gzip-compressed RINEX is recognised through the compression
GnssLogger     text whose ``#`` header defines ``Raw,...TimeNanos``
NMEA           text lines starting ``$GP``/``$GN``/...
libRSF         whitespace text whose lines start with a libRSF measurement type and a time
               (``pseudorange3 0.2 ...``, ``odom3``, ``point3``): the smartLoc dataset
GSDC           CSV of the Google Smartphone Decimeter Challenge, by its header: 2021
               ``*_derived.csv`` and ground truth, 2022 ``device_gnss.csv`` and ground truth
CSV            other UTF-8 text with a consistent delimiter
=============  ===============================================================================

Raises ``UnsupportedFormatError`` naming the file, offset and reason for an empty file, a
known non-log (PNG, JPEG, PDF, ZIP, NumPy) or unrecognised bytes.
"""

from __future__ import annotations

import re
import sqlite3
import struct
import zlib
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path

from navreplay.ingest.errors import CorruptLogError, UnsupportedFormatError

HEAD_BYTES = 8192

MCAP_MAGIC = b"\x89MCAP0\r\n"
ROSBAG_MAGIC = b"#ROSBAG V2.0\n"
SQLITE_MAGIC = b"SQLite format 3\x00"
ULOG_MAGIC = b"ULog\x01\x12\x35"
DATAFLASH_MAGIC = b"\xa3\x95\x80"
GZIP_MAGIC = b"\x1f\x8b"
NPY_MAGIC = b"\x93NUMPY"

_NON_LOGS = (
    (b"\x89PNG\r\n\x1a\n", "a PNG image"),
    (b"\xff\xd8\xff", "a JPEG image"),
    (b"%PDF-", "a PDF document"),
    (b"PK\x03\x04", "a ZIP archive (extract the log first)"),
    (NPY_MAGIC, "a NumPy array file (for a comma2k19 stream, ingest its segment directory)"),
    (b"\x7fELF", "an executable"),
)

# MAVLink tlog: every packet is preceded by a big-endian uint64 of microseconds since 1970.
_TLOG_MIN_US = 946_684_800 * 10**6  # 2000-01-01
_TLOG_MAX_US = 4_102_444_800 * 10**6  # 2100-01-01
_NMEA_RE = re.compile(rb"^\$(G[PNLABQ]|B[DS]|P[A-Z]{3})[A-Z]{3},")
# libRSF dataset text (TU Chemnitz): "<type> <time_s> <values...>", one measurement per line.
_LIBRSF_RE = re.compile(
    r"^(pseudorange[23]|odom[234]|point[23]|imu|range[23]|gnss)\s+[-+0-9.eE]+\s"
)
_COMMA_PARTS = ("processed_log", "global_pose")


class Format(StrEnum):
    """Log formats navreplay recognises (values are the ``--format`` choices)."""

    MCAP = "mcap"
    ROS1BAG = "ros1bag"
    ROS2BAG = "ros2bag"
    TLOG = "tlog"
    DATAFLASH = "dataflash"
    ULOG = "ulog"
    RINEX = "rinex"
    GNSSLOGGER = "gnsslogger"
    NMEA = "nmea"
    LIBRSF = "librsf"
    COMMA2K19 = "comma2k19"
    GSDC = "gsdc"
    CSV = "csv"


@dataclass(frozen=True)
class Detected:
    """What ``detect`` found.

    Attributes:
        path: the path as given (a file or a rosbag2 directory).
        format: the detected format.
        files: the files a reader opens, in order (a rosbag2 directory's storage files).
        variant: format-specific kind: rosbag2 storage (``sqlite3``/``mcap``), RINEX ``obs``/
            ``nav``/``crinex``, compression (``gzip``) ...; empty when there is none.
        version: format version where the format has one (``2.0``, ``3.04`` ...).
        recovery: set when detection worked around damage (e.g. a rosbag2 directory without
            ``metadata.yaml``); the reader records it as a recoverable defect.
    """

    path: Path
    format: Format
    files: tuple[Path, ...]
    variant: str = ""
    version: str = ""
    recovery: str | None = None


def detect(path: str | Path) -> Detected:
    """Detect the format of ``path`` (a log file or a rosbag2 directory).

    Raises:
        UnsupportedFormatError: empty, unreadable, a known non-log, or unrecognised content;
            the message names the file, the offset and the reason.
        CorruptLogError: a rosbag2 ``.db3`` bag without its ``metadata.yaml``.
    """
    path = Path(path)
    if path.is_dir():
        return _detect_dir(path)
    if not path.exists():
        raise UnsupportedFormatError("no such file or directory", path=path)
    try:
        with path.open("rb") as fh:
            head = fh.read(HEAD_BYTES)
    except OSError as err:
        raise UnsupportedFormatError(f"cannot read: {err.strerror}", path=path) from err
    if not head:
        raise UnsupportedFormatError("file is empty (0 bytes)", path=path, offset=0)
    return _detect_bytes(path, head)


def _detect_bytes(path: Path, head: bytes) -> Detected:
    one = (path,)
    if head.startswith(b"#ROSBAG V"):
        return _detect_rosbag(path, head)
    simple = (
        (MCAP_MAGIC, Format.MCAP, head[5:6].decode("ascii", "replace")),
        (ULOG_MAGIC, Format.ULOG, str(head[7]) if len(head) > 7 else ""),
        (DATAFLASH_MAGIC, Format.DATAFLASH, ""),
    )
    for magic, fmt, version in simple:
        if head.startswith(magic):
            return Detected(path, fmt, one, version=version)
    if head.startswith(SQLITE_MAGIC):
        return _detect_sqlite(path)
    if head.startswith(GZIP_MAGIC):
        return _detect_gzip(path, head)
    for magic, what in _NON_LOGS:
        if head.startswith(magic):
            raise UnsupportedFormatError(
                f"not a log: the content is {what} (magic {magic!r})", path=path, offset=0
            )
    if _looks_like_tlog(head) or _tlog_start(head) is not None:
        # _tlog_start: console text or other bytes before the first record (a GCS that wrote
        # its log after a banner); the reader skips them as garbage and reports their offset.
        return Detected(path, Format.TLOG, one)
    text = _as_text(head)
    found = _detect_text(path, text) if text is not None else None
    if found is not None:
        return found
    raise UnsupportedFormatError(
        f"unrecognised content: no known log magic or framing (first bytes {head[:16].hex(' ')})",
        path=path,
        offset=0,
        hint="see `navreplay ingest --help` for the formats navreplay reads",
    )


def _detect_rosbag(path: Path, head: bytes) -> Detected:
    version = head[9:].split(b"\n", 1)[0].decode("ascii", "replace")
    if not head.startswith(ROSBAG_MAGIC):
        raise UnsupportedFormatError(
            f"ROS bag format version {version} is not supported (only 2.0)",
            path=path,
            offset=0,
            hint="migrate it with ROS 1 `rosbag fix` first",
        )
    return Detected(path, Format.ROS1BAG, (path,), version="2.0")


def _tlog_start(head: bytes, chain: int = 3) -> int | None:
    """The first offset of ``head`` where ``chain`` consecutive tlog records frame, if any
    (a tlog behind leading garbage; pymavlink resynchronises on such records)."""
    for pos in range(1, max(len(head) - 18, 0)):
        if head[pos + 8] in (0xFE, 0xFD) and _tlog_chain(head, pos) >= chain:
            return pos
    return None


def _looks_like_tlog(head: bytes) -> bool:
    """At least two consecutive ``[BE us timestamp][MAVLink packet]`` records (one if short)."""
    good = _tlog_chain(head, 0, whole=True)
    return good >= 2 or good == -1


def _tlog_chain(head: bytes, pos: int, *, whole: bool = False) -> int:
    """How many records (up to 3) frame one after the other from ``pos``; -1 when one record
    exactly fills ``head`` and ``whole`` is set."""
    good = 0
    while pos + 10 <= len(head) and good < 3:
        (stamp_us,) = struct.unpack_from(">Q", head, pos)
        stx = head[pos + 8]
        if not _TLOG_MIN_US <= stamp_us <= _TLOG_MAX_US or stx not in (0xFE, 0xFD):
            return good
        payload = head[pos + 9]
        if stx == 0xFE:
            size = 8 + payload
        else:
            if pos + 11 > len(head):
                break
            signed = head[pos + 10] & 0x01
            size = 12 + payload + (13 if signed else 0)
        pos += 8 + size
        good += 1
    return -1 if whole and good == 1 and pos == len(head) else good


#: a text head may hold damaged lines (invalid UTF-8, NUL or control bytes from a bit flip or
#: a zeroed block): up to this fraction of its lines (at least one) and of its bytes, so that
#: the reader names the damaged lines; random or binary bytes damage nearly every line
TEXT_DAMAGED_LINES_MAX = 0.1
TEXT_DAMAGED_BYTES_MAX = 0.25
_CONTROL = re.compile(r"[\x00-\x08\x0b\x0c\x0e-\x1f\x7f\ufffd]")


def _as_text(head: bytes) -> str | None:
    """``head`` decoded as UTF-8 text (damaged characters as U+FFFD), or None if it is binary.

    A multi-byte character cut by the head boundary is still text, and so is text with a few
    damaged lines (``TEXT_DAMAGED_LINES_MAX``, ``TEXT_DAMAGED_BYTES_MAX``).
    """
    text = head.decode("utf-8", "replace")
    if text.endswith("\ufffd") and b"\x00" not in head[-3:]:
        text = text.rstrip("\ufffd")  # a character cut by the head boundary
    if not text:
        return None
    bad = len(_CONTROL.findall(text))
    if not bad:
        return text
    lines = text.split("\n")
    damaged = sum(bool(_CONTROL.search(ln)) for ln in lines)
    if len(lines) < 2 or damaged > max(1, TEXT_DAMAGED_LINES_MAX * len(lines)):
        return None
    if bad > TEXT_DAMAGED_BYTES_MAX * len(text):
        return None
    return _CONTROL.sub("\ufffd", text)


def _detect_text(path: Path, text: str) -> Detected | None:
    one = (path,)
    first = text.split("\n", 1)[0].rstrip("\r")
    label = first[60:80].strip() if len(first) >= 61 else ""
    if label == "RINEX VERSION / TYPE":
        version = first[:9].strip()
        kind = first[20:21].upper()
        variant = {"O": "obs", "N": "nav", "G": "nav", "H": "nav", "L": "nav", "M": "met"}.get(
            kind, kind.lower()
        )
        return Detected(path, Format.RINEX, one, variant=variant, version=version)
    if label.startswith("CRINEX VERS"):
        return Detected(path, Format.RINEX, one, variant="crinex", version=first[:9].strip())
    lines = [ln for ln in text.splitlines()[:60] if ln.strip()]
    _refuse_damaged_rinex(path, first, lines)
    if any(re.match(r"^#\s*Raw,.*TimeNanos", ln) for ln in lines):
        return Detected(path, Format.GNSSLOGGER, one)
    if lines and sum(bool(_NMEA_RE.match(ln.encode())) for ln in lines) >= max(1, len(lines) // 2):
        return Detected(path, Format.NMEA, one)
    return _detect_delimited(path, lines)


_RINEX_LABELS = ("PGM / RUN BY / DATE", "MARKER NAME", "END OF HEADER", "LEAP SECONDS")


def _refuse_damaged_rinex(path: Path, first: str, lines: list[str]) -> None:
    """A RINEX header whose first line is damaged: say so rather than guess another format."""
    labels = sum(ln[60:80].strip() in _RINEX_LABELS for ln in lines[:40])
    if labels >= 2:
        raise CorruptLogError(
            f"a RINEX header whose first line is not a valid 'RINEX VERSION / TYPE' line "
            f"({first[:80]!r})",
            path=path,
            record="line 1",
            hint="the header's first line is damaged; restore it (version in columns 1-9, "
            "file type in column 21, the label in columns 61-80)",
        )


def _detect_delimited(path: Path, lines: list[str]) -> Detected | None:
    """A GSDC CSV (by its header), libRSF text, another delimited text, or None."""
    gsdc = _gsdc_variant(lines[0]) if lines else None
    if gsdc is not None:
        return Detected(path, Format.GSDC, (path,), variant=gsdc)
    data_lines = [ln for ln in lines if not ln.lstrip().startswith("#")]
    if data_lines and all(ln.isprintable() or "\t" in ln for ln in data_lines):
        # The last line of the head may be cut short.
        body = lines[:-1] or lines
        librsf = sum(bool(_LIBRSF_RE.match(ln)) for ln in body) >= 0.9 * len(body)
        return Detected(path, Format.LIBRSF if librsf else Format.CSV, (path,))
    return None


_GSDC_HEADERS = (
    ("collectionName,phoneName,millisSinceGpsEpoch,constellationType,svid,", "derived2021"),
    ("collectionName,phoneName,millisSinceGpsEpoch,latDeg,lngDeg,", "truth2021"),
    ("MessageType,Provider,LatitudeDegrees,LongitudeDegrees,", "truth2022"),
)


def _gsdc_variant(header: str) -> str | None:
    """The kind of GSDC CSV whose header line is ``header``, or None."""
    for start, variant in _GSDC_HEADERS:
        if header.startswith(start):
            return variant
    names = set(header.split(","))
    if header.startswith("MessageType,") and {"SvPositionXEcefMeters", "TimeNanos"} <= names:
        return "device_gnss2022"
    return None


def _detect_gzip(path: Path, head: bytes) -> Detected:
    try:
        inner = zlib.decompressobj(wbits=16 + zlib.MAX_WBITS).decompress(head, HEAD_BYTES)
    except zlib.error as err:
        raise UnsupportedFormatError(
            f"gzip-compressed file that does not decompress: {err}", path=path, offset=0
        ) from err
    text = _as_text(inner)
    found = _detect_text(path, text) if text is not None else None
    if found is not None and found.format == Format.RINEX:
        return Detected(path, Format.RINEX, (path,), f"{found.variant}+gzip", found.version)
    raise UnsupportedFormatError(
        "gzip-compressed file whose content is not RINEX",
        path=path,
        offset=0,
        hint="decompress it (gunzip) and ingest the result",
    )


def _is_rosbag2_db(path: Path) -> bool:
    try:
        con = sqlite3.connect(f"file:{path}?mode=ro&immutable=1", uri=True)
        try:
            names = {r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type='table'")}
        finally:
            con.close()
    except sqlite3.Error:
        return False
    return {"messages", "topics"} <= names


def _detect_sqlite(path: Path) -> Detected:
    if not _is_rosbag2_db(path):
        raise UnsupportedFormatError(
            "an SQLite database that is not a rosbag2 storage file (no messages/topics tables)",
            path=path,
            offset=0,
        )
    if (path.parent / "metadata.yaml").is_file():
        return _detect_dir(path.parent)
    raise _db3_without_metadata(path)


def _db3_without_metadata(path: Path) -> CorruptLogError:
    return CorruptLogError(
        "rosbag2 sqlite3 storage without its metadata.yaml: the bag's file list, "
        "compression and message counts are unknown",
        path=path,
        hint="run `ros2 bag reindex <bag directory> -s sqlite3` on a copy of the bag, "
        "then ingest the directory",
    )


def _detect_dir(path: Path) -> Detected:
    meta = path / "metadata.yaml"
    if meta.is_file():
        storage, files = _read_rosbag2_metadata(path, meta)
        return Detected(path, Format.ROS2BAG, files, variant=storage)
    arrays = _comma2k19_arrays(path)
    if arrays:
        return Detected(path, Format.COMMA2K19, arrays, variant="segment")
    mcaps = sorted(p for p in path.iterdir() if p.is_file() and has_magic(p, MCAP_MAGIC))
    if mcaps:
        return Detected(
            path,
            Format.ROS2BAG,
            tuple(mcaps),
            variant="mcap",
            recovery=f"rosbag2 directory without metadata.yaml: read its {len(mcaps)} MCAP "
            "storage file(s) directly",
        )
    dbs = sorted(p for p in path.iterdir() if p.is_file() and has_magic(p, SQLITE_MAGIC))
    if dbs:
        raise _db3_without_metadata(dbs[0])
    raise UnsupportedFormatError(
        "a directory that is not a rosbag2 bag (no metadata.yaml, no .mcap or .db3 storage) "
        "nor a comma2k19 segment (no processed_log/ or global_pose/ arrays)",
        path=path,
    )


def _comma2k19_arrays(path: Path) -> tuple[Path, ...]:
    """The ``.npy`` files of a comma2k19 segment directory (empty if it is not one)."""
    parts = [path / p for p in _COMMA_PARTS if (path / p).is_dir()]
    found = sorted(f for part in parts for f in part.rglob("*") if f.is_file())
    arrays = tuple(f for f in found if has_magic(f, NPY_MAGIC))
    return arrays if len(arrays) * 2 >= len(found) else ()


def has_magic(path: Path, magic: bytes) -> bool:
    """Whether ``path`` begins with ``magic`` (False if it cannot be read)."""
    try:
        with path.open("rb") as fh:
            return fh.read(len(magic)) == magic
    except OSError:
        return False


def _read_rosbag2_metadata(path: Path, meta: Path) -> tuple[str, tuple[Path, ...]]:
    import yaml

    try:
        doc = yaml.safe_load(meta.read_text(encoding="utf-8"))
        info = doc["rosbag2_bagfile_information"]
        storage = str(info["storage_identifier"])
        rel = [str(p) for p in info.get("relative_file_paths") or ()]
    except (OSError, yaml.YAMLError, KeyError, TypeError) as err:
        raise CorruptLogError(
            f"rosbag2 metadata.yaml is unreadable: {err}",
            path=meta,
            hint="run `ros2 bag reindex` on a copy of the bag",
        ) from err
    files = tuple(path / Path(p).name for p in rel)
    missing = [f.name for f in files if not f.is_file()]
    if missing:
        raise CorruptLogError(
            f"storage file(s) listed in metadata.yaml are missing: {', '.join(missing)}",
            path=path,
        )
    return storage, files
