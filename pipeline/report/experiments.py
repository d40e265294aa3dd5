"""Experiment sections of a dataset report: ``datasets/<id>/experiments/<name>/``.

An experiment stage (paper reproductions, Monte Carlo sweeps, speed-band studies ...) writes
its results into its own directory; the report renders each directory as one section.

The contract, ``<name>/section.json`` (every key but ``title`` optional)::

    {"title": "Cascaded filters (paper 000)",
     "order": 40,                                  sections sort by (order, name); default 50
     "summary": ["paragraph", ...],                plain text, one string per paragraph
     "claims": [{"claim": "UKF bias convergence faster than the EKF's",
                 "paper": "about 2x faster", "ours": "1.4x (CI 1.1-1.8)",
                 "verdict": "agrees" | "differs" | "partly" | "n/a"}],
     "tables": [{"title": "...", "csv": "convergence.csv", "caption": "..."}],
     "figures": [{"title": "...", "file": "bands.svg", "caption": "..."}]}   .svg or .png

A directory without ``section.json`` is rendered generically: each ``*.csv`` a table (the
first ``sections.MAX_TABLE_ROWS`` rows on the page; every CSV, and the JSON of the same
name beside it, is copied whole to ``reports/<id>/tables/experiments/<name>/``) and each
``*.svg``/``*.png`` (also in a ``figures/`` sub-directory; an SVG wins over a PNG of the same
name) a figure, in name order.
Each ``*.md`` file of a generic directory is a note rendered as prose (``markdown``).

The outages stage (issue 6) writes the dataset-level results the report shows in their own
sections rather than as an experiment (``find_outage_results``), wherever they lie under
``experiments/``: ``sat_reduction.csv`` (columns of ``SAT_REDUCTION_COLUMNS``; paper 001's
Table 1) with ``sat_reduction_vs_paper.md`` beside it (why ours differs from the paper), and
``drift_vs_length.csv``. The report copies both CSVs to ``reports/<id>/tables/``.

Unknown keys, a referenced file that does not exist, a CSV that does not parse or a figure
of another type are ``ReportInputError``s naming the file.
"""

from __future__ import annotations

import base64
import csv
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from navreplay.pipeline.outages.tables import SAT_REDUCTION_COLUMNS
from navreplay.pipeline.report.input_files import ReportInputError, read_json

SECTION_NAME = "section.json"
SAT_REDUCTION_NAME = "sat_reduction.csv"
SAT_REDUCTION_NOTE = "sat_reduction_vs_paper.md"
DRIFT_NAME = "drift_vs_length.csv"
_OUTAGE_FILES = {SAT_REDUCTION_NAME, SAT_REDUCTION_NOTE, DRIFT_NAME}
_KEYS = {"title", "order", "summary", "claims", "tables", "figures"}
_CLAIM_KEYS = {"claim", "paper", "ours", "verdict"}
_VERDICTS = {"agrees", "differs", "partly", "n/a"}


@dataclass(frozen=True)
class CsvTable:
    """A CSV file read as text cells (header + rows)."""

    path: Path
    title: str
    caption: str
    header: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]


@dataclass(frozen=True)
class Figure:
    """An experiment figure: inline SVG text, or a PNG as a data URI."""

    path: Path
    title: str
    caption: str
    svg: str | None = None
    png_data_uri: str | None = None


@dataclass
class Experiment:
    """One experiment directory, ready to render."""

    name: str
    path: Path
    title: str
    order: int = 50
    summary: list[str] = field(default_factory=list)
    claims: list[dict[str, str]] = field(default_factory=list)
    tables: list[CsvTable] = field(default_factory=list)
    figures: list[Figure] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)  # Markdown texts


@dataclass(frozen=True)
class OutageResults:
    """The outages stage's tables: the reduction per satellite count (with its explanatory
    note against the paper, Markdown) and drift against outage length; each may be absent."""

    sat_reduction: CsvTable | None = None
    sat_reduction_note: str | None = None
    drift: CsvTable | None = None


def read_csv(path: Path, title: str = "", caption: str = "") -> CsvTable:
    """A CSV file with a header row; ragged or empty files are ``ReportInputError``s."""
    try:
        with path.open(newline="", encoding="utf-8") as fh:
            rows = list(csv.reader(fh))
    except OSError as err:
        raise ReportInputError(path, f"cannot read: {err.strerror}") from err
    except (csv.Error, UnicodeDecodeError) as err:
        raise ReportInputError(path, f"not a CSV file: {err}") from err
    if not rows or not rows[0]:
        raise ReportInputError(path, "empty CSV (no header row)")
    header = tuple(rows[0])
    for i, r in enumerate(rows[1:], start=2):
        if len(r) != len(header):
            raise ReportInputError(path, f"line {i}: {len(r)} cells, the header has {len(header)}")
    return CsvTable(path, title or path.stem, caption, header, tuple(tuple(r) for r in rows[1:]))


def read_figure(path: Path, title: str = "", caption: str = "") -> Figure:
    """An SVG (inlined) or PNG (base64) figure file."""
    if not path.is_file():
        raise ReportInputError(path, "figure file does not exist")
    suffix = path.suffix.lower()
    if suffix == ".svg":
        text = path.read_text(encoding="utf-8")
        if "<svg" not in text:
            raise ReportInputError(path, "not an SVG file (no <svg> element)")
        return Figure(path, title or path.stem, caption, svg=text[text.index("<svg") :])
    if suffix == ".png":
        data = path.read_bytes()
        if not data.startswith(b"\x89PNG\r\n\x1a\n"):
            raise ReportInputError(path, "not a PNG file (bad signature)")
        uri = "data:image/png;base64," + base64.b64encode(data).decode("ascii")
        return Figure(path, title or path.stem, caption, png_data_uri=uri)
    raise ReportInputError(path, "figures must be .svg or .png")


def _str_list(path: Path, value: Any, key: str) -> list[str]:
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise ReportInputError(path, f"{key}: expected a list of strings")
    return list(value)


def _items(path: Path, spec: dict[str, Any], key: str) -> list[dict[str, Any]]:
    items = spec.get(key, [])
    if not isinstance(items, list) or not all(isinstance(i, dict) for i in items):
        raise ReportInputError(path, f"{key}: expected a list of objects")
    return items


def _from_section(directory: Path) -> Experiment:
    path = directory / SECTION_NAME
    spec = read_json(path)
    if not isinstance(spec, dict):
        raise ReportInputError(path, "expected a JSON object")
    unknown = sorted(set(spec) - _KEYS)
    if unknown:
        raise ReportInputError(path, f"unknown keys {unknown}; allowed: {sorted(_KEYS)}")
    if not isinstance(spec.get("title"), str):
        raise ReportInputError(path, "title: missing or not a string")
    order = spec.get("order", 50)
    if not isinstance(order, int) or isinstance(order, bool):
        raise ReportInputError(path, "order: expected an integer")
    exp = Experiment(directory.name, directory, spec["title"], order)
    exp.summary = _str_list(path, spec.get("summary", []), "summary")
    for i, c in enumerate(_items(path, spec, "claims")):
        if set(c) - _CLAIM_KEYS or not all(isinstance(v, str) for v in c.values()):
            raise ReportInputError(path, f"claims[{i}]: keys {sorted(_CLAIM_KEYS)}, strings")
        if c.get("verdict", "n/a") not in _VERDICTS:
            raise ReportInputError(path, f"claims[{i}].verdict: one of {sorted(_VERDICTS)}")
        exp.claims.append({k: c.get(k, "") for k in ("claim", "paper", "ours", "verdict")})
    for i, t in enumerate(_items(path, spec, "tables")):
        if not isinstance(t.get("csv"), str):
            raise ReportInputError(path, f"tables[{i}].csv: missing or not a string")
        csv_path = directory / t["csv"]
        if not csv_path.is_file():
            raise ReportInputError(path, f"tables[{i}]: {csv_path} does not exist")
        exp.tables.append(read_csv(csv_path, str(t.get("title", "")), str(t.get("caption", ""))))
    for i, f in enumerate(_items(path, spec, "figures")):
        if not isinstance(f.get("file"), str):
            raise ReportInputError(path, f"figures[{i}].file: missing or not a string")
        exp.figures.append(
            read_figure(directory / f["file"], str(f.get("title", "")), str(f.get("caption", "")))
        )
    return exp


def _figure_files(directory: Path) -> list[Path]:
    """SVG and PNG files of ``directory`` and its ``figures/``; an SVG wins over a PNG twin."""
    files = [p for d in (directory, directory / "figures") if d.is_dir()
             for p in sorted(d.iterdir()) if p.suffix in (".svg", ".png")]  # fmt: skip
    stems_svg = {(p.parent, p.stem) for p in files if p.suffix == ".svg"}
    return [p for p in files if p.suffix == ".svg" or (p.parent, p.stem) not in stems_svg]


def _generic(directory: Path, name: str) -> Experiment:
    exp = Experiment(name, directory, name.replace("_", " "))
    for p in sorted(directory.glob("*.csv")):
        if p.name not in _OUTAGE_FILES:
            exp.tables.append(read_csv(p))
    for p in sorted(directory.glob("*.md")):
        if p.name not in _OUTAGE_FILES:
            exp.notes.append(_read_text(p))
    exp.figures = [read_figure(p) for p in _figure_files(directory)]
    return exp


def _load(directory: Path, name: str) -> Experiment:
    return (
        _from_section(directory)
        if (directory / SECTION_NAME).is_file()
        else _generic(directory, name)
    )


def load_experiments(experiments_dir: Path) -> list[Experiment]:
    """Every experiment directory under ``experiments_dir`` (none if it is absent).

    Files directly in ``experiments_dir`` (an experiment stage that writes there) form one
    more experiment named ``results``; a ``figures/`` directory belongs to its parent.
    """
    if not experiments_dir.is_dir():
        return []
    out = []
    if (experiments_dir / SECTION_NAME).is_file() or any(
        p.suffix in (".csv", ".svg", ".png") for p in experiments_dir.iterdir()
    ):
        out.append(_load(experiments_dir, "results"))
    for d in sorted(p for p in experiments_dir.iterdir() if p.is_dir() and p.name != "figures"):
        out.append(_load(d, d.name))
    out = [e for e in out if e.tables or e.figures or e.summary or e.claims or e.notes]
    return sorted(out, key=lambda e: (e.order, e.name))


def _read_text(path: Path) -> str:
    try:
        return path.read_text(encoding="utf-8")
    except OSError as err:
        raise ReportInputError(path, f"cannot read: {err.strerror}") from err
    except UnicodeDecodeError as err:
        raise ReportInputError(path, f"not UTF-8 text: {err}") from err


def _first(experiments_dir: Path, name: str) -> Path | None:
    return next(iter(sorted(experiments_dir.rglob(name))), None)


def find_outage_results(experiments_dir: Path | None) -> OutageResults:
    """The outages stage's tables under ``experiments_dir`` (first in path order of each),
    the reduction table checked for its columns (see the module docstring)."""
    if experiments_dir is None or not experiments_dir.is_dir():
        return OutageResults()
    red = note = drift = None
    path = _first(experiments_dir, SAT_REDUCTION_NAME)
    if path is not None:
        red = read_csv(path, "Error reduction per satellite count")
        missing = [c for c in SAT_REDUCTION_COLUMNS if c not in red.header]
        if missing:
            raise ReportInputError(path, f"missing columns {missing}")
        if (path.parent / SAT_REDUCTION_NOTE).is_file():
            note = _read_text(path.parent / SAT_REDUCTION_NOTE)
    path = _first(experiments_dir, DRIFT_NAME)
    if path is not None:
        drift = read_csv(path, "Drift against outage length")
    return OutageResults(red, note, drift)
