"""Monte Carlo over outage placements and seeds, one filter, efficiently.

Every seed draws window starts independently and uniformly over the drive (``draw_starts``);
every start is replayed under each case (a partial outage keeping k satellites, a complete
outage of a given length). A scenario changes nothing before its window, so the filter's
state at the window's start is the nominal run's: each case is replayed from the nominal
run's output (state and covariance) just before the window, over the window and ``tail_s``
after it, instead of from the start of the log. The replay is the same ``run_filter`` with
``initial`` set, on the same transformed tables (``scenarios.apply_scenario``), and the
errors before the checkpoint are the nominal run's, so the window metrics equal those of a
full replay of that scenario (a test checks this to 1e-6 m) at a fraction of the cost.

Each start is a task of ``pipeline.compute.run_tasks``: on forked workers of this process by
default (they share the loaded kernels and tables), or on a Dask cluster; the rows do not
depend on where they ran.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import pyarrow as pa

from navreplay.ingest.meta import SensorMeta
from navreplay.pipeline.compute import ComputeParams, TaskError, TaskStore, run_tasks
from navreplay.pipeline.estimation.core.contract import Backend
from navreplay.pipeline.estimation.core.windows import (
    NS,
    ErrorTrack,
    WindowMetricsParams,
    window_metrics,
)
from navreplay.pipeline.estimation.ins.alignment import Alignment
from navreplay.pipeline.estimation.ins.config import InsFilterParams
from navreplay.pipeline.estimation.ins.fixnoise import FixNoise, ObsNoise
from navreplay.pipeline.estimation.ins.inputs import prepare_fixes, prepare_obs
from navreplay.pipeline.estimation.ins.replay import RunResult, run_filter
from navreplay.pipeline.estimation.ins.tracks import (
    fixes_track,
    truth_track,
)
from navreplay.pipeline.nav.earth import I64
from navreplay.pipeline.scenarios.apply import apply_scenario, log_span
from navreplay.pipeline.scenarios.config import Policy, SatellitesSpec, ScenarioSpec, WindowsSpec

log = logging.getLogger(__name__)

SKIPPED = "skipped.json"  # in a filter's Monte Carlo folder instead of windows.parquet


@dataclass(frozen=True)
class Case:
    """One replay of a window: its length and the satellites kept inside (0: none)."""

    length_s: float
    sats: int


@dataclass(frozen=True)
class Start:
    """One drawn window start."""

    seed: int
    window: int
    start_ns: int


@dataclass(frozen=True)
class Job:
    """Everything a worker needs, sent once per process."""

    name: str
    params: InsFilterParams
    backend: Backend
    tables: dict[str, pa.Table]
    sensors: SensorMeta | None
    lever_b: tuple[float, float, float]
    nominal: RunResult
    track: ErrorTrack
    t0_ns: int
    cases: tuple[Case, ...]
    policy: Policy
    tail_s: float
    mask_deg: float
    metrics: WindowMetricsParams
    fix_noise: FixNoise | None = None  # learned from the whole log, not a window's slice
    obs_noise: ObsNoise | None = None


def draw_starts(
    seeds: Sequence[int],
    per_seed: int,
    t0_ns: int,
    t_end_ns: int,
    earliest_s: float,
    longest_s: float,
    tail_s: float,
) -> list[Start]:
    """Window starts, ``per_seed`` per seed, i.i.d. uniform in ``[earliest, end - longest -
    tail]`` seconds from ``t0_ns`` (``numpy.random.default_rng(seed)``), rounded to 1 ms.

    Raises:
        ValueError: the log is too short for one window after ``earliest_s``.
    """
    latest = (t_end_ns - t0_ns) / NS - longest_s - tail_s
    if latest <= earliest_s:
        raise ValueError(
            f"the log ({(t_end_ns - t0_ns) / NS:.0f} s) is too short for {longest_s:g} s "
            f"windows after {earliest_s:g} s with a {tail_s:g} s tail"
        )
    out = []
    for seed in seeds:
        u = np.random.default_rng(seed).uniform(earliest_s, latest, per_seed)
        out += [Start(seed, w, t0_ns + round(s * 1e3) * 1_000_000) for w, s in enumerate(u)]
    return out


def _slice(table: pa.Table, lo: int, hi: int) -> pa.Table:
    """Rows with ``lo <= t_ns <= hi`` of a table sorted by time (zero-copy)."""
    t = np.asarray(table.column("t_ns").to_numpy(), dtype=np.int64)
    a, b = int(np.searchsorted(t, lo, "left")), int(np.searchsorted(t, hi, "right"))
    return table.slice(a, b - a)


def _merge(before: ErrorTrack, after: ErrorTrack, t_c: int) -> ErrorTrack:
    """The nominal track before ``t_c`` followed by the replay's from ``t_c`` on."""
    a = before.t_ns < t_c
    b = after.t_ns >= t_c

    def cat(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return np.concatenate([x[a], y[b]])

    return ErrorTrack(
        cat(before.t_ns, after.t_ns),
        cat(before.err_ned_m, after.err_ned_m),
        cat(before.sigma_ned_m, after.sigma_ned_m),
        cat(before.ref_ned_m, after.ref_ned_m),
        before.reference,
        before.origin,
    )


def replay_start(job: Job, start: Start) -> list[dict[str, Any]]:
    """Replay every case of one window start from the nominal checkpoint before it."""
    nom = job.nominal
    k = int(np.searchsorted(nom.t_ns, start.start_ns, "left")) - 1
    if k < 0:
        raise ValueError(f"window at {start.start_ns} ns starts before the nominal run")
    t_c = int(nom.t_ns[k])
    initial = Alignment(t_c, nom.x[k].copy(), nom.P[k].copy(), "checkpoint", 0.0, 0.0)
    rows = []
    for case in job.cases:
        end = start.start_ns + round(case.length_s * NS)
        hi = end + round(job.tail_s * NS)
        sub = {
            n: _slice(t, t_c - NS if n == "imu" else t_c + 1, hi)
            for n, t in job.tables.items()
            if n in ("imu", "gnss", "gnss_obs")
        }
        seed = start.seed * 100_000 + start.window  # the random policy's draw, per window
        sats = SatellitesSpec(case.sats, job.policy, seed) if case.sats else None
        start_s = (start.start_ns - job.t0_ns) / NS
        spec = ScenarioSpec(
            windows=WindowsSpec("explicit", case.length_s, starts_s=(start_s,)), satellites=sats
        )
        applied = apply_scenario(
            sub, "montecarlo", spec, mask_deg=job.mask_deg, windows=[(start.start_ns, end)]
        )
        t_wall = time.perf_counter()
        r = run_filter(
            applied.tables, job.sensors, job.name, job.params, backend=job.backend,
            initial=initial, fix_noise=job.fix_noise, obs_noise=job.obs_noise,
        )  # fmt: skip
        t_run = time.perf_counter() - t_wall
        if job.track.reference == "truth":
            # the truth around the replay only: interpolating the whole drive's truth for
            # every replay cost more than replaying a loosely coupled filter
            truth = _slice(job.tables["truth"], t_c - NS, hi + NS)
            after = truth_track(r, truth, job.track.origin)
        else:
            after = fixes_track(r, job.tables["gnss"], job.lever_b, job.track.origin)
        track = _merge(job.track, after, t_c)
        (m,) = window_metrics(track, applied.outage_windows, job.t0_ns, job.metrics)
        m.update(
            filter=job.name,
            seed=start.seed,
            window=start.window,
            length_s=case.length_s,
            policy=job.policy if case.sats else "",
            status=r.status,
            gate_rejections=int(np.sum(r.inn_i[:, 4] == 0)) if r.inn_i.size else 0,
            replay_s=t_run,
            replayed_s=(r.t_ns[-1] - t_c) / NS if r.t_ns.size else 0.0,
        )
        m["sats"] = case.sats
        sel = applied.selections[0] if applied.selections else None
        m["kept_svs"] = ",".join(sel.svs) if sel else ""
        m["kept_elevation_mean_deg"] = float(np.mean(sel.elevation_deg)) if sel else None
        m["kept_gdop"] = sel.gdop if sel else None
        rows.append(m)
    return rows


def run_montecarlo(
    tables: dict[str, pa.Table],
    sensors: SensorMeta | None,
    lever_b: tuple[float, float, float],
    name: str,
    params: InsFilterParams,
    starts: Sequence[Start],
    cases: Sequence[Case],
    *,
    policy: Policy,
    tail_s: float,
    mask_deg: float,
    metrics: WindowMetricsParams,
    backend: Backend = "numba",
    workers: int = 1,
    nominal: RunResult | None = None,
    scheduler: str = "processes",
    compute: ComputeParams | None = None,
    store: TaskStore[list[dict[str, Any]]] | None = None,
    progress: Callable[[str], None] | None = None,
    progress_every_s: float = 5.0,
) -> tuple[list[dict[str, Any]], dict[str, float], list[TaskError]]:
    """The window metrics of every (start, case) for filter ``name``.

    Divergence is flagged, not raised, so one diverging window is recorded (``status``) and
    the others still run. The starts are tasks of ``pipeline.compute.run_tasks`` on
    ``scheduler`` (``workers``: processes of the default engine); a start whose replay raised
    is returned as a ``TaskError`` and the others still run. Returns (one row per start and
    case, sorted by seed, window, length and sats; timing: nominal_s, replay_wall_s,
    replayed_s, replays; the failed starts).
    """
    # divergence flagged; not smoothed: the Monte Carlo measures the filter's drift
    flagged = replace(
        params, divergence=replace(params.divergence, on_divergence="flag"), smooth=False
    )
    t_wall = time.perf_counter()
    if nominal is None:
        nominal = run_filter(tables, sensors, name, flagged, backend=backend)
    t_nominal = time.perf_counter() - t_wall
    truth = tables.get("truth")
    if truth is not None and truth.num_rows:
        track = truth_track(nominal, truth)
    else:
        track = fixes_track(nominal, tables["gnss"], lever_b)
    t0, _ = log_span(tables)
    job = Job(
        name,
        flagged,
        backend,
        dict(tables),
        sensors,
        lever_b,
        nominal,
        track,
        t0,
        tuple(cases),
        policy,
        tail_s,
        mask_deg,
        metrics,
        prepare_fixes(tables["gnss"], flagged.gnss).noise if "gnss" in tables else None,
        prepare_obs(tables["gnss_obs"], flagged.gnss).noise if "gnss_obs" in tables else None,
    )
    t_wall = time.perf_counter()
    rows: list[dict[str, Any]] = []
    errors: list[TaskError] = []
    results = run_tasks(
        replay_start, job, starts, scheduler=scheduler, workers=workers, params=compute,
        label=f"montecarlo {name}", keys=[start_key(s) for s in starts], store=store,
        progress=progress, progress_every_s=progress_every_s,
    )  # fmt: skip
    for part in results:
        if isinstance(part, TaskError):
            errors.append(part)
        else:
            rows += part
    timing = {
        "nominal_s": t_nominal,
        "replay_wall_s": time.perf_counter() - t_wall,
        "replayed_s": float(sum(r["replayed_s"] for r in rows)),
        "replay_cpu_s": float(sum(r["replay_s"] for r in rows)),
        "replays": float(len(rows)),
    }
    rows.sort(key=lambda r: (r["seed"], r["window"], r["length_s"], r["sats"]))
    return rows, timing, errors


def start_key(start: Start) -> str:
    """The task key of one window start (``compute.TaskStore``)."""
    return f"{start.seed}/{start.window}/{start.start_ns}"


def cases_for(sats: Sequence[int], sats_window_s: float, lengths_s: Sequence[float]) -> list[Case]:
    """The distinct cases of both experiments (a complete outage of ``sats_window_s`` serves
    both the k = 0 row and that length)."""
    out = {Case(sats_window_s, k) for k in sats} | {Case(length, 0) for length in lengths_s}
    return sorted(out, key=lambda c: (c.length_s, c.sats))


def windows_table(rows: Sequence[dict[str, Any]]) -> pa.Table:
    """The rows as a table, timing columns left out (the table is byte-stable)."""
    skip = {"replay_s"}
    keys = [k for k in rows[0] if k not in skip] if rows else []
    return pa.table({k: [r[k] for r in rows] for k in sorted(keys)})


def starts_ns(starts: Sequence[Start]) -> I64:
    return np.array([s.start_ns for s in starts], dtype=np.int64)
