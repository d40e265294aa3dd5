"""Chunk decompression shared by the container readers (MCAP, ROS 1 bag).

``decompress`` handles the codecs these containers use: none (``""`` in MCAP, ``none`` in
ROS 1 bags), zstd, lz4 (frame format, as MCAP and ROS 1's roslz4 write it) and bz2. With
``partial`` it returns what a truncated stream still yields (zstd and lz4 frames and bz2
decode block by block), which is how a cut chunk's readable prefix is salvaged.
"""

from __future__ import annotations

import bz2

import lz4.frame
import zstandard

MAX_CHUNK_BYTES = 1 << 31  # a larger declared size is taken as a corrupt header


class DecompressError(Exception):
    """The data does not decompress with its declared codec, or not to its declared size."""


def decompress(codec: str, data: bytes, size: int | None, *, partial: bool = False) -> bytes:
    """Decompress ``data`` with ``codec``; ``size`` is the declared uncompressed size.

    Raises:
        DecompressError: unknown codec, corrupt data, implausible or mismatched size.
    """
    if size is not None and size > MAX_CHUNK_BYTES:
        raise DecompressError(f"declared size {size} is implausible")
    try:
        if codec in ("", "none"):
            out = data
        elif codec == "zstd":
            if partial:
                out = zstandard.ZstdDecompressor().decompressobj().decompress(data)
            else:
                out = zstandard.ZstdDecompressor().decompress(data, max_output_size=size or 0)
        elif codec == "lz4":
            out = (
                lz4.frame.LZ4FrameDecompressor().decompress(data)
                if partial
                else lz4.frame.decompress(data)
            )
        elif codec == "bz2":
            out = bz2.BZ2Decompressor().decompress(data) if partial else bz2.decompress(data)
        else:
            raise DecompressError(f"unsupported compression {codec!r}")
    except (zstandard.ZstdError, RuntimeError, ValueError, OSError, EOFError) as err:
        raise DecompressError(str(err)) from err
    if not partial and size is not None and len(out) != size:
        raise DecompressError(f"{len(out)} bytes decompressed, the header says {size}")
    return bytes(out)
