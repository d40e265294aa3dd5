"""Random streams and the output folder of the vehicle synthesizers (tractor, fwekf, car).

Each of these synthesizers is a pure function ``synthesize(params, seed) -> SynthResult``; a
separate ``write`` turns the result into the log files a user's own tools open (CSV, MAVLink
tlog), plus the synthesizer's canonical tables as Parquet under ``reference/`` (the layout of
``pipeline.synth.files``) for round-trip tests. Measurement tables in a result hold the values
exactly as the log files encode them (quantized to the format's resolution), so a reader must
reproduce them; truth is kept at full precision.
"""

from __future__ import annotations

import zlib
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from navreplay.ingest.atomic import atomic_directory
from navreplay.ingest.meta import DatasetMeta, SourceRecord, write_meta
from navreplay.ingest.tables import Provenance, sha256_file, write_table
from navreplay.pipeline.synth import SynthResult

REFERENCE_DIR = "reference"  # as in pipeline.synth.files


def dataset_seed(seed: int, dataset: str) -> np.random.SeedSequence:
    """The seed of one dataset: ``synth.seed`` mixed with a hash of the dataset id.

    Datasets drawn from one ``synth.seed`` are independent of each other, and each is
    reproducible on its own.
    """
    return np.random.SeedSequence([seed, zlib.crc32(dataset.encode())])


def dataset_rng(seed: int, dataset: str) -> np.random.Generator:
    """A generator on ``dataset_seed(seed, dataset)``."""
    return np.random.default_rng(dataset_seed(seed, dataset))


def write_reference(
    out_dir: Path,
    dataset: str,
    result: SynthResult,
    *,
    sources: Sequence[tuple[Path, str]],
    params: Mapping[str, Any],
) -> list[Path]:
    """Write ``result``'s tables and ``meta.json`` under ``out_dir/reference``.

    Args:
        out_dir: the synthesizer's output folder.
        dataset: the dataset id.
        result: the synthesized dataset.
        sources: the log files written (path, format name); recorded with their sha256.
        params: the plain parameters that produced the dataset (hashed into provenance).

    Returns:
        the files written.
    """
    ref = out_dir / REFERENCE_DIR
    written: list[Path] = []
    for name, table in sorted(result.tables.items()):
        path = ref / f"{name}.parquet"
        prov = Provenance.create(
            name,
            sources=[p for p, _ in sources],
            params=params,
            extra={"synthesizer": dataset},
        )
        write_table(path, name, table, prov)
        written.append(path)
    meta = DatasetMeta(
        dataset=dataset,
        time_base=result.time_base,
        sources=tuple(SourceRecord(p.name, sha256_file(p), fmt) for p, fmt in sources),
        tables={name: t.num_rows for name, t in sorted(result.tables.items())},
        sensors=result.sensors,
        frame_conversions=(),
    )
    written.append(write_meta(ref, meta))
    return written


def write_dataset_dir(
    out_dir: str | Path,
    dataset: str,
    result: SynthResult,
    write_logs: Callable[[Path], Sequence[tuple[Path, str]]],
    *,
    params: Mapping[str, Any],
) -> list[Path]:
    """Write a dataset's folder: its log files and ``reference/``, replacing ``out_dir`` whole.

    Args:
        out_dir: the dataset's ``raw/`` folder; it appears complete or not at all.
        dataset: the dataset id.
        result: the synthesized dataset (its tables go to ``reference/``).
        write_logs: writes the log files into the folder it is given; returns (path, format).
        params: the plain parameters that produced the dataset.

    Returns:
        the final paths of the log files, then of the reference files.
    """
    out = Path(out_dir)
    with atomic_directory(out) as tmp:
        logs = list(write_logs(tmp))
        ref = write_reference(tmp, dataset, result, sources=logs, params=params)
    return [out / p.relative_to(tmp) for p, _ in logs] + [out / p.relative_to(tmp) for p in ref]
