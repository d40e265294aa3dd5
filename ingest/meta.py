"""A dataset's ``meta.json``: what the tables came from and the sensor metadata filters need.

Written by ingest beside the canonical tables (``datasets/<id>/tables/meta.json``), read by
``navreplay run``. The ``audit`` member holds the ingest report (rates, gaps, duplicates,
recovered damage ...) as plain JSON; its structure belongs to the ingest audit.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from navreplay.ingest.atomic import atomic_write_json
from navreplay.ingest.config import ImuNoise, Vec3
from navreplay.ingest.errors import ConfigError
from navreplay.ingest.platform import UNKNOWN, Platform
from navreplay.ingest.tables import SourceFile, package_version
from navreplay.ingest.typed import KeyPathError, load_dataclass, to_plain

META_NAME = "meta.json"


class _MetaError(KeyPathError):
    pass


@dataclass(frozen=True)
class SensorMeta:
    """Sensor metadata the filters use.

    Attributes:
        imu_noise: the IMU noise model, if the dataset declares one (else filter defaults).
        lever_arm_m: GNSS antenna relative to the IMU, body FRD, m.
        imu_mounting_rpy_deg: the mounting rotation applied at ingest (for the record).
        wheelbase_m: vehicle wheelbase, m, if known.
        platform: the vehicle kind and its source (``ingest.platform``).
        gnss_latency_s: how late the fixes' stamps are against the IMU's (``dataset.yaml``
            ``gnss.latency_s``, or measured at ingest: ``ingest.latency``); None: not known.
        gnss_latency_source: where ``gnss_latency_s`` comes from, in words.
    """

    imu_noise: ImuNoise | None = None
    lever_arm_m: Vec3 = (0.0, 0.0, 0.0)
    imu_mounting_rpy_deg: Vec3 = (0.0, 0.0, 0.0)
    wheelbase_m: float | None = None
    platform: Platform = UNKNOWN
    gnss_latency_s: float | None = None
    gnss_latency_source: str = ""


@dataclass(frozen=True)
class SourceRecord:
    """One source file of the dataset (name and sha256) and its detected format."""

    name: str
    sha256: str
    format: str


@dataclass(frozen=True)
class DatasetMeta:
    """The whole ``meta.json``.

    Attributes:
        dataset: dataset id.
        time_base: ``gps``, ``utc`` or ``recorder`` (the clock ``t_ns`` counts on).
        sources: the files ingested.
        tables: canonical table name -> row count, for the tables written.
        sensors: sensor metadata.
        frame_conversions: human-readable list of conversions applied (e.g. "imu: FLU->FRD").
        package_version: navreplay version that wrote it.
        audit: the ingest report (plain JSON).
    """

    dataset: str
    time_base: str
    sources: tuple[SourceRecord, ...]
    tables: dict[str, int]
    sensors: SensorMeta = field(default_factory=SensorMeta)
    frame_conversions: tuple[str, ...] = ()
    package_version: str = field(default_factory=package_version)
    audit: dict[str, Any] = field(default_factory=dict)

    def source_files(self) -> tuple[SourceFile, ...]:
        return tuple(SourceFile(s.name, s.sha256) for s in self.sources)


def write_meta(directory: str | Path, meta: DatasetMeta) -> Path:
    """Write ``meta.json`` atomically into ``directory``; returns its path."""
    path = Path(directory) / META_NAME
    atomic_write_json(path, to_plain(meta))
    return path


def read_meta(directory: str | Path) -> DatasetMeta:
    """Read ``meta.json`` from a tables directory.

    Raises:
        ConfigError: the file is missing or malformed, naming the key.
    """
    path = Path(directory) / META_NAME
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except OSError as err:
        raise ConfigError(
            f"cannot read {META_NAME}: {err.strerror}",
            path=path,
            hint="ingest the dataset first (`navreplay ingest` or `dvc repro`)",
        ) from err
    except ValueError as err:
        raise ConfigError(f"not valid JSON: {err}", path=path) from err
    try:
        return load_dataclass(DatasetMeta, data, error=_MetaError)
    except _MetaError as err:
        raise ConfigError(f"{err.key_path}: {err.reason}", path=path) from err
