"""Random streams and the output folder of the vehicle synthesizers (tractor, fwekf, car).

Each of these synthesizers is a pure function ``synthesize(params, seed) -> SynthResult``; a
separate ``write`` turns the result into the log files a user's own tools open (CSV, MAVLink
tlog), plus the synthesizer's canonical tables as Parquet under ``reference/`` (the layout of
``pipeline.synth.files``) for round-trip tests. Measurement tables in a result hold the values
exactly as the log files encode them (quantized to the format's resolution), so a reader must
reproduce them; truth is kept at full precision.
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from navreplay.ingest.atomic import atomic_directory
from navreplay.ingest.meta import DatasetMeta, SourceRecord, write_meta
from navreplay.ingest.schema import from_columns
from navreplay.ingest.tables import Provenance, sha256_file, write_table
from navreplay.ingest.typed import to_plain
from navreplay.ingest.writers.csv import CsvColumn, quantize, write_csv
from navreplay.pipeline.synth import SynthResult

REFERENCE_DIR = "reference"  # as in pipeline.synth.files
#: the kinds of log a synthesized dataset folder holds besides tables and JSON (a folder of
#: them is a previous synth output that may be replaced: ``ingest.atomic.check_output_dir``)
SYNTH_LOG_SUFFIXES = (".mcap", ".bag", ".obs", ".nav", ".tlog")


def dataset_seed(seed: int, dataset: str) -> np.random.SeedSequence:
    """The seed of one dataset: ``synth.seed`` mixed with a hash of the dataset id.

    Datasets drawn from one ``synth.seed`` are independent of each other, and each is
    reproducible on its own.
    """
    return np.random.SeedSequence([seed, zlib.crc32(dataset.encode())])


def dataset_rng(seed: int, dataset: str) -> np.random.Generator:
    """A generator on ``dataset_seed(seed, dataset)``."""
    return np.random.default_rng(dataset_seed(seed, dataset))


def check_dataset(module: str, name: str, *made: str) -> None:
    """A synthesizer's registry entry point is asked for ``name``: raise ``ValueError`` unless
    it is one of the datasets ``made`` by ``module``."""
    if name not in made:
        raise ValueError(f"{module} makes {' and '.join(map(repr, made))}, not {name!r}")


def synth_params(seed: int, section: str, params: Any) -> dict[str, Any]:
    """The plain parameters recorded (hashed) in a dataset's provenance: ``synth.seed`` and
    the dataclass ``params`` of its section ``synth.<section>``."""
    return {"seed": seed, section: to_plain(params)}


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
    with atomic_directory(out, extra_suffixes=SYNTH_LOG_SUFFIXES) as tmp:
        logs = list(write_logs(tmp))
        ref = write_reference(tmp, dataset, result, sources=logs, params=params)
    return [out / p.relative_to(tmp) for p, _ in logs] + [out / p.relative_to(tmp) for p in ref]


def level_truth_columns(
    t_us: np.ndarray,
    lat_deg: np.ndarray,
    lon_deg: np.ndarray,
    alt_m: np.ndarray,
    vel_n_mps: np.ndarray,
    vel_e_mps: np.ndarray,
    heading_rad: np.ndarray,
    fmt: str,
) -> list[CsvColumn]:
    """The leading columns of the truth log of a vehicle on level ground: time, position,
    NED velocity (no vertical), roll and pitch zero, yaw (the heading wrapped to [-pi, pi))."""
    zero = np.zeros(t_us.size)
    return [
        CsvColumn("time_us", t_us, "%d"),
        CsvColumn("lat_deg", lat_deg, fmt),
        CsvColumn("lon_deg", lon_deg, fmt),
        CsvColumn("alt_m", alt_m, fmt),
        CsvColumn("vel_n_mps", vel_n_mps, fmt),
        CsvColumn("vel_e_mps", vel_e_mps, fmt),
        CsvColumn("vel_d_mps", zero, fmt),
        CsvColumn("roll_rad", zero, fmt),
        CsvColumn("pitch_rad", zero, fmt),
        CsvColumn("yaw_rad", (heading_rad + math.pi) % (2 * math.pi) - math.pi, fmt),
    ]


def csv_tables(
    cols: Mapping[str, Sequence[CsvColumn]],
    measured: Mapping[str, Mapping[str, str]],
    *,
    scale: Mapping[str, float] | None = None,
) -> dict[str, pa.Table]:
    """The canonical tables of a dataset written as CSV logs (one log per table).

    Measurements are taken as the CSV holds them (quantized to each column's format), the
    ``truth`` log whole at full precision; ``t_ns`` comes from each log's ``time_us`` column
    (integer UNIX microseconds).

    Args:
        cols: each log's columns, by canonical table name (``truth`` among them).
        measured: for each measurement table, canonical column -> CSV column. Integer columns
            (format ``%d``) are taken as they are.
        scale: canonical column -> factor applied to what the CSV holds (a unit change).

    Returns:
        the measurement tables in the order of ``measured``, then ``truth``.
    """
    by = {name: {c.name: c for c in columns} for name, columns in cols.items()}

    def t_ns(table: str) -> np.ndarray:
        return np.asarray(by[table]["time_us"].values.astype(np.int64) * 1000)

    tables: dict[str, pa.Table] = {}
    for table, columns in measured.items():
        data: dict[str, object] = {"t_ns": t_ns(table)}
        for canon, src in columns.items():
            c = by[table][src]
            if c.fmt == "%d":
                data[canon] = c.values
            else:
                logged = quantize(c.values, c.fmt)
                data[canon] = logged * scale[canon] if scale and canon in scale else logged
        tables[table] = from_columns(table, data)
    truth: dict[str, object] = {"t_ns": t_ns("truth")}
    truth.update({k: c.values for k, c in by["truth"].items() if k != "time_us"})
    tables["truth"] = from_columns("truth", truth)
    return tables


def write_csv_dataset(
    out_dir: str | Path,
    dataset: str,
    result: SynthResult,
    cols: Mapping[str, Sequence[CsvColumn]],
    *,
    comment: str,
    params: Mapping[str, Any],
) -> list[Path]:
    """``write_dataset_dir`` for a dataset logged as CSV: ``<dataset>_<table>.csv`` for each
    table of ``cols``, each headed by ``comment``, then ``reference/``."""

    def write_logs(folder: Path) -> list[tuple[Path, str]]:
        logs = []
        for name, columns in cols.items():
            path = folder / f"{dataset}_{name}.csv"
            write_csv(path, columns, comment=comment)
            logs.append((path, "csv"))
        return logs

    return write_dataset_dir(out_dir, dataset, result, write_logs, params=params)
