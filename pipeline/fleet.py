"""Fleet analysis: ``analyze`` over many logs, with a report per log and a fleet summary.

``fleet(logs, out_dir, params, ...)`` analyzes each log as one task of
``pipeline.compute.run_tasks`` (forked workers by default, or a Dask cluster): a task runs
``analyze.analyze`` into a scratch folder on its worker and returns that folder as a tar
archive, which this process unpacks into ``out_dir/logs/<name>`` atomically, so workers need
no shared file system for the results (each must reach the logs' paths). A log whose analysis
raises (unreadable, no IMU, ...) is recorded with its error and the fleet goes on. Finished
logs are kept in ``out_dir/.tasks`` until the summary is written, so a rerun after an
interruption analyzes only the logs that are missing.

``out_dir`` then holds:

- ``logs/<name>/{tables,runs,report}``: what ``navreplay analyze`` writes, per log;
- ``summary/``: filters ranked across the logs (``report.summary``: against the truth where a
  log has one, against the onboard estimate's drift where it has that instead);
- ``index.html``, ``fleet.csv``, ``fleet.json``: one row per log (platform, duration, the
  status of every run, GNSS trouble and why), the failed logs with their errors, and the
  reduction per satellite count pooled over every log's outage windows (paper 001's measure,
  ``outages.stats.paired_reduction``, for each pair of ``outages.pairs`` that ran).

GNSS trouble is flagged from the log's own fixes: a gap of 5 s or more between fixes, 5 % or
more of the fixes without a 3-D solution, a reported horizontal accuracy whose 95th
percentile exceeds 5 m, or fewer than 5 satellites used at some point.
"""

from __future__ import annotations

import csv
import io
import json
import logging
import math
import shutil
import tarfile
import tempfile
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow.parquet as pq

from navreplay.ingest.atomic import atomic_directory, atomic_write_json, atomic_write_text
from navreplay.ingest.tables import params_hash
from navreplay.ingest.typed import to_plain
from navreplay.pipeline.compute import TaskError, TaskStore, run_tasks
from navreplay.pipeline.params import Params

GAP_TROUBLE_S = 5.0
NO_FIX_TROUBLE = 0.05
HACC_TROUBLE_M = 5.0
SATS_TROUBLE = 5


@dataclass(frozen=True)
class FleetJob:
    """What every log's analysis shares."""

    params: Params
    filters: tuple[str, ...] | None = None
    scenarios: tuple[str, ...] | None = None
    outages: tuple[str, ...] = ()
    smooth: bool = False


@dataclass(frozen=True)
class LogTask:
    """One log to analyze (its files: a log, or a log and its companions, e.g. RINEX
    observations and navigation), and the name of its folder and dataset."""

    name: str
    paths: tuple[str, ...]

    @property
    def path(self) -> str:
        """The log's files as one text (absolute paths, ``+`` between them)."""
        return " + ".join(self.paths)


@dataclass(frozen=True)
class LogDone:
    """A finished analysis: its folder as a tar archive, and how long it took."""

    name: str
    archive: bytes
    seconds: float


@dataclass
class FleetResult:
    """What ``fleet`` wrote: the rows per log, the failures, the summary's paths."""

    out_dir: Path
    rows: list[dict[str, Any]]
    failed: list[dict[str, str]]
    not_logs: list[dict[str, str]] = field(default_factory=list)
    reduction: list[dict[str, Any]] = field(default_factory=list)
    seconds: float = 0.0

    @property
    def index(self) -> Path:
        return self.out_dir / "index.html"


_CSV_REASON = (
    "delimited text: a CSV log needs its columns mapped in a dataset.yaml (`csv:`), so it is "
    "analyzed with `navreplay analyze --dataset-config`, not in a folder of logs"
)


def log_tasks(paths: Sequence[Path]) -> tuple[list[LogTask], list[dict[str, str]]]:
    """The logs of ``paths`` and the files of their folders that are not logs.

    Each path is a log (taken as it is, whatever it holds), or a folder: a folder that is
    itself a log (a rosbag2 bag) is one; otherwise each of its files whose format is
    recognized is a log, files sharing a stem (``drive.obs`` and ``drive.nav``) being one log,
    and the others (``README.md``, and delimited text, which needs a dataset.yaml) are listed
    with the reason. Logs are named by their stems,
    made unique in order (``a``, ``a_2``).

    Raises:
        FileNotFoundError: a path does not exist.
    """
    from navreplay.ingest.detect import Format, detect
    from navreplay.ingest.errors import IngestError, UnsupportedFormatError

    groups: list[list[Path]] = []
    not_logs: list[dict[str, str]] = []
    for p in paths:
        if not p.exists():
            raise FileNotFoundError(f"{p}: no such log or folder")
        if not p.is_dir():
            groups.append([p])
            continue
        try:
            detect(p)
            groups.append([p])
            continue
        except IngestError:
            pass  # a folder of logs
        by_stem: dict[str, list[Path]] = {}
        for c in sorted(p.iterdir()):
            if c.name.startswith("."):
                continue
            try:
                if detect(c).format is Format.CSV:
                    not_logs.append({"file": str(c), "reason": _CSV_REASON})
                    continue
            except UnsupportedFormatError as err:
                not_logs.append({"file": str(c), "reason": err.reason})
                continue
            except IngestError:
                pass  # a damaged log is still a log: its analysis says what is wrong
            by_stem.setdefault(c.name.split(".")[0], []).append(c)
        groups += by_stem.values()
    tasks, seen = [], set()
    for files in groups:
        base = files[0].name.split(".")[0] or files[0].name
        name, k = base, 2
        while name in seen:
            name, k = f"{base}_{k}", k + 1
        seen.add(name)
        tasks.append(LogTask(name, tuple(str(f.resolve()) for f in files)))
    return tasks, not_logs


def analyze_log(job: FleetJob, task: LogTask) -> LogDone:
    """Analyze one log into a scratch folder; its contents as a tar archive (a task)."""
    from navreplay.pipeline.analyze import analyze

    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="navreplay-fleet-") as tmp, _quiet():
        out = Path(tmp) / task.name
        analyze(
            [Path(f) for f in task.paths],
            out,
            job.params,
            filters=job.filters,
            scenarios=job.scenarios,
            outages=job.outages,
            smooth=job.smooth,
            name=task.name,
        )
        buf = io.BytesIO()
        with tarfile.open(fileobj=buf, mode="w") as tar:
            for path in sorted(out.rglob("*")):
                if path.is_file():
                    tar.add(path, arcname=path.relative_to(out).as_posix(), recursive=False)
    return LogDone(task.name, buf.getvalue(), time.perf_counter() - t0)


@contextmanager
def _quiet() -> Iterator[None]:
    """navreplay's warnings off while a log is analyzed: each log's report holds them, and
    from many logs at once they would bury the progress."""
    logger = logging.getLogger("navreplay")
    level = logger.level
    logger.setLevel(max(logging.ERROR, logger.getEffectiveLevel()))
    try:
        yield
    finally:
        logger.setLevel(level)


def _unpack(done: LogDone, target: Path) -> None:
    """The archive's files into ``target``, replacing it as a whole (atomically)."""
    with atomic_directory(target) as tmp, tarfile.open(fileobj=io.BytesIO(done.archive)) as tar:
        tar.extractall(tmp, filter="data")


def fleet(
    paths: Sequence[Path],
    out_dir: Path,
    params: Params,
    *,
    filters: Sequence[str] | None = None,
    scenarios: Sequence[str] | None = None,
    outages: Sequence[str] = (),
    smooth: bool = False,
    scheduler: str = "processes",
    workers: int = 1,
    progress: Callable[[str], None] | None = None,
) -> FleetResult:
    """Analyze every log of ``paths`` and summarize the fleet (see the module docstring)."""
    from navreplay.ingest.errors import OutputPathError
    from navreplay.pipeline.report.summary import render_summary

    t0 = time.perf_counter()
    if out_dir.exists() and not out_dir.is_dir():
        raise OutputPathError(
            "the output path is a file; the fleet writes a folder there",
            path=out_dir,
            hint="give --out a new folder or a previous fleet's; nothing was written",
        )
    tasks, not_logs = log_tasks(paths)
    if not tasks:
        raise FileNotFoundError(f"no logs in {', '.join(str(p) for p in paths)}")
    job = FleetJob(
        params,
        tuple(filters) if filters else None,
        tuple(scenarios) if scenarios else None,
        tuple(outages),
        smooth,
    )
    fingerprint = str(params_hash({"job": to_plain(job)}))
    store: TaskStore[LogDone] = TaskStore(out_dir / ".tasks", fingerprint)
    keys = [f"{t.name}:{t.path}:{','.join(_stamp(Path(f)) for f in t.paths)}" for t in tasks]
    results = run_tasks(
        analyze_log, job, tasks, scheduler=scheduler, workers=workers, params=params.compute,
        label="fleet", keys=keys, store=store, progress=progress,
    )  # fmt: skip
    rows: list[dict[str, Any]] = []
    failed: list[dict[str, str]] = []
    reports: list[Path] = []
    for task, res in zip(tasks, results, strict=True):
        if isinstance(res, TaskError):
            failed.append({"log": task.path, "name": task.name, "error": res.error,
                           "traceback": res.traceback})  # fmt: skip
            continue
        folder = out_dir / "logs" / task.name
        _unpack(res, folder)
        reports.append(folder / "report")
        rows.append(_log_row(task, folder, res.seconds))
    reduction = pooled_reduction(reports, params)
    if reports:
        render_summary(reports, out_dir / "summary")
    result = FleetResult(out_dir, rows, failed, not_logs, reduction, time.perf_counter() - t0)
    _write(result, params)
    shutil.rmtree(out_dir / ".tasks", ignore_errors=True)  # ours; the logs' folders hold it all
    return result


def _stamp(path: Path) -> str:
    """Size and modification time of a log (a folder: of its files): a changed log is new."""
    files = sorted(path.rglob("*")) if path.is_dir() else [path]
    st = [(f.name, f.stat().st_size, f.stat().st_mtime_ns) for f in files if f.is_file()]
    return str(params_hash({"files": [list(s) for s in st]}))


def _runs(folder: Path) -> list[dict[str, Any]]:
    path = folder / "report" / "tables" / "runs.json"
    runs = json.loads(path.read_text(encoding="utf-8")) if path.is_file() else []
    return [r for r in runs if isinstance(r, dict)]


def gnss_trouble(tables: Path) -> list[str]:
    """Why the log's GNSS was troubled (see the module docstring); [] when it was not."""
    gnss = tables / "gnss.parquet"
    if not gnss.is_file():
        return ["no GNSS fixes"]
    t = pq.read_table(gnss)
    if t.num_rows == 0:
        return ["no GNSS fixes"]
    why = []
    ts = np.asarray(t.column("t_ns").to_numpy(), dtype=np.int64)
    gap = float(np.max(np.diff(ts))) / 1e9 if ts.size > 1 else 0.0
    if gap >= GAP_TROUBLE_S:
        why.append(f"fixes stop for {gap:.1f} s")
    names = t.column_names
    if "fix_type" in names:
        ft = np.asarray(t.column("fix_type").to_numpy(zero_copy_only=False), dtype=float)
        ft = ft[np.isfinite(ft)]
        if ft.size and np.mean(ft < 3) >= NO_FIX_TROUBLE:
            why.append(f"{100 * np.mean(ft < 3):.0f} % of fixes without a 3-D solution")
    if "h_acc_m" in names:
        acc = np.asarray(t.column("h_acc_m").to_numpy(zero_copy_only=False), dtype=float)
        acc = acc[np.isfinite(acc)]
        if acc.size and np.percentile(acc, 95) > HACC_TROUBLE_M:
            why.append(f"reported horizontal accuracy {np.percentile(acc, 95):.1f} m (95th pct)")
    if "num_sats" in names:
        ns = np.asarray(t.column("num_sats").to_numpy(zero_copy_only=False), dtype=float)
        ns = ns[np.isfinite(ns)]
        if ns.size and ns.min() < SATS_TROUBLE:
            why.append(f"as few as {ns.min():.0f} satellites used")
    return why


def _log_row(task: LogTask, folder: Path, seconds: float) -> dict[str, Any]:
    """The fleet table's row of one analyzed log."""
    tables = folder / "tables"
    meta = json.loads((tables / "meta.json").read_text(encoding="utf-8"))
    runs = _runs(folder)
    nominal = [r for r in runs if r.get("scenario") == "nominal" and r.get("status") != "skipped"]
    finished = [r for r in nominal if r.get("pos_err_h_rms_m") is not None]
    best = min(finished, key=lambda r: float(r["pos_err_h_rms_m"]), default=None)
    trouble = gnss_trouble(tables)
    statuses: dict[str, int] = {}
    for r in runs:
        statuses[str(r.get("status"))] = statuses.get(str(r.get("status")), 0) + 1
    return {
        "name": task.name,
        "log": task.path,
        "platform": (meta.get("sensors") or {}).get("platform", {}).get("kind", "unknown"),
        "duration_s": _duration(tables),
        "runs": len(runs),
        "statuses": ", ".join(f"{k} {v}" for k, v in sorted(statuses.items())),
        "gnss_trouble": "; ".join(trouble),
        "best_nominal": best["filter"] if best else None,
        "best_h_rms_m": float(best["pos_err_h_rms_m"]) if best else None,
        "best_reference": best.get("reference") if best else None,
        "analysis_s": round(seconds, 1),
        "report": f"logs/{task.name}/report/index.html",
    }


def _duration(tables: Path) -> float | None:
    imu = tables / "imu.parquet"
    if not imu.is_file():
        return None
    t = pq.read_table(imu, columns=["t_ns"]).column("t_ns").to_numpy()
    return float(t[-1] - t[0]) / 1e9 if len(t) > 1 else 0.0


def pooled_reduction(reports: Sequence[Path], params: Params) -> list[dict[str, Any]]:
    """Per pair of ``outages.pairs`` and satellite count k: the reduction of the candidate's
    mean error over the baseline's, pooled over the k-satellite windows of every log where both
    ran (paired per window), with its paired bootstrap interval."""
    from navreplay.pipeline.outages.stats import paired_reduction

    errs: dict[tuple[str, int], dict[tuple[str, str, int], float]] = {}
    refs: dict[tuple[str, int], set[str]] = {}
    for rep in reports:
        path = rep / "tables" / "windows.csv"
        if not path.is_file():
            continue
        with path.open(encoding="utf-8", newline="") as fh:
            for w in csv.DictReader(fh):
                sats, err = w.get("sats") or "", w.get("err_mean_m") or ""
                if not sats or not err or not str(w.get("scenario", "")).startswith("sats_"):
                    continue
                key = (str(w["filter"]), round(float(sats)))
                errs.setdefault(key, {})[(rep.parent.name, w["scenario"], int(w["window"]))] = (
                    float(err)
                )
                refs.setdefault(key, set()).add(str(w.get("reference") or ""))
    rows = []
    o = params.outages
    for i, (a, b) in enumerate(o.pairs):
        for k in o.sats:
            ea_map, eb_map = errs.get((a, k), {}), errs.get((b, k), {})
            common = sorted(set(ea_map) & set(eb_map))
            ea = np.array([ea_map[c] for c in common])
            eb = np.array([eb_map[c] for c in common])
            keep = np.isfinite(ea) & np.isfinite(eb)
            ea, eb = ea[keep], eb[keep]
            if ea.size == 0:
                continue
            iv = paired_reduction(ea, eb, o.confidence, o.resamples, seed=1000 * i + k)
            rows.append({
                "pair": f"{a} -> {b}", "sats": k, "windows": int(ea.size),
                "logs": len({c[0] for c in common}),
                "err_a_mean_m": float(ea.mean()), "err_b_mean_m": float(eb.mean()),
                "reduction_pct": _finite(iv.estimate), "ci_low_pct": _finite(iv.low),
                "ci_high_pct": _finite(iv.high),
                "reference": ", ".join(sorted(refs.get((a, k), set()) | refs.get((b, k), set()))),
            })  # fmt: skip
    return rows


def _finite(v: float) -> float | None:
    return v if math.isfinite(v) else None


_ROW_COLS = (
    ("name", "log"), ("platform", "platform"), ("duration_s", "duration s"),
    ("statuses", "runs by status"), ("gnss_trouble", "GNSS trouble"),
    ("best_nominal", "best nominal run"), ("best_h_rms_m", "its horizontal RMS m"),
    ("best_reference", "against"), ("analysis_s", "analysis s"),
)  # fmt: skip
_RED_COLS = (
    ("pair", "pair"), ("sats", "k"), ("windows", "windows"), ("logs", "logs"),
    ("err_a_mean_m", "e_A m"), ("err_b_mean_m", "e_B m"), ("reduction_pct", "reduction %"),
    ("ci_low_pct", "95 % low"), ("ci_high_pct", "95 % high"), ("reference", "against"),
)  # fmt: skip


def _write(result: FleetResult, params: Params) -> None:
    """``index.html``, ``fleet.csv`` and ``fleet.json`` of the fleet (atomically, each)."""
    from navreplay.pipeline.report import html as h
    from navreplay.pipeline.report import tables as tb

    out = result.out_dir
    troubled = [r for r in result.rows if r["gnss_trouble"]]
    links = "".join(
        f'<li><a href="{h.esc(r["report"])}">{h.esc(r["name"])}</a></li>' for r in result.rows
    )
    failed = "".join(
        f"<li><b>{h.esc(f['name'])}</b> ({h.esc(f['log'])}): {h.esc(f['error'])}</li>"
        for f in result.failed
    )
    sections = [
        ("logs", "Logs", h.table(result.rows, _ROW_COLS) + f"<ul>{links}</ul>"),
        ("failed", "Logs that could not be analyzed", f"<ul>{failed}</ul>" if failed else ""),
        (
            "not_logs",
            "Files in the folders that are not logs",
            h.table(result.not_logs, (("file", "file"), ("reason", "why")))
            if result.not_logs
            else "",
        ),
        (
            "gnss",
            "GNSS trouble",
            h.table(troubled, (("name", "log"), ("gnss_trouble", "why")))
            + h.para(
                f"From each log's fixes: a gap of {GAP_TROUBLE_S:g} s or more, "
                f"{100 * NO_FIX_TROUBLE:g} % or more without a 3-D solution, a reported "
                f"horizontal accuracy above {HACC_TROUBLE_M:g} m (95th percentile), or fewer "
                f"than {SATS_TROUBLE} satellites.",
                "note",
            )
            if troubled
            else h.para("No log shows GNSS trouble by these measures.", "note"),
        ),
        (
            "ranking",
            "Filters ranked across the fleet",
            '<p><a href="summary/index.html">The ranking across logs</a> (paired, with '
            "intervals; against the truth where a log has one).</p>"
            if (out / "summary" / "index.html").is_file()
            else "",
        ),
        (
            "satellites",
            "Error reduction per satellite count, pooled over the fleet",
            h.table(result.reduction, _RED_COLS)
            + h.para(
                "Per pair (outages.pairs) and k: 100 (1 - mean e_B / mean e_A) over every "
                "log's k-satellite outage windows where both filters ran, paired per window, "
                "with a paired BCa bootstrap interval over windows. 'against' names what the "
                "errors were measured against (truth, or on logs without one the fixes or the "
                "smoothed nominal run).",
                "note",
            )
            if result.reduction
            else "",
        ),
    ]
    page = h.page(
        "navreplay: fleet",
        f"{len(result.rows)} logs analyzed, {len(result.failed)} failed, "
        f"{len(troubled)} with GNSS trouble, in {result.seconds:.0f} s",
        sections,
    )
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out / "index.html", page)
    atomic_write_text(out / "fleet.csv", tb.to_csv(result.rows))
    atomic_write_json(
        out / "fleet.json",
        {
            "logs": result.rows,
            "failed": result.failed,
            "not_logs": result.not_logs,
            "sat_reduction": result.reduction,
            "seconds": result.seconds,
            "params": params_hash(to_plain(params)),
        },
    )
