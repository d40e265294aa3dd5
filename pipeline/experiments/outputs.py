"""Deterministic experiment outputs: JSON and CSV tables beside the figures."""

from __future__ import annotations

import csv
import io
import math
from pathlib import Path
from typing import Any

from navreplay.ingest.atomic import atomic_path, atomic_write_json


def _plain(v: Any) -> Any:
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def write_rows(out_dir: Path, stem: str, rows: list[dict[str, Any]], **extra: Any) -> None:
    """``<stem>.json`` ({rows, ...extra}) and ``<stem>.csv`` (the rows) in ``out_dir``."""
    out_dir.mkdir(parents=True, exist_ok=True)
    clean = [{k: _plain(v) for k, v in r.items()} for r in rows]
    atomic_write_json(out_dir / f"{stem}.json", {"rows": clean, **extra})
    keys: list[str] = []
    for r in clean:
        keys += [k for k in r if k not in keys]
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=keys, lineterminator="\n")
    writer.writeheader()
    for r in clean:
        writer.writerow({k: ("" if r.get(k) is None else r.get(k)) for k in keys})
    with atomic_path(out_dir / f"{stem}.csv") as tmp:
        tmp.write_text(buf.getvalue(), encoding="utf-8")
