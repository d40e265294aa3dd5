"""The robustness sweep of issue 22's acceptance, on generated data.

The drive: ``car_stop_and_go`` of ``pipeline.synth.car_drives`` (15 s at rest, so alignment is
not what is tested, then city traffic) lengthened to ``DURATION_S`` (345 s of motion), with the
campus car's sensors changed per cell (``dataclasses.replace`` on ``SeoulCampusParams``):

- IMU grade (``GRADES``): noise densities and bias random walks in the simulator; the turn-on
  bias of the grade added in full to every axis, signs drawn from the seed (the truth's bias
  columns with it). The dataset declares no IMU noise model (``SensorMeta.imu_noise`` None):
  the filters use ``filters.<name>.imu_noise`` of params.yaml floored by the log's own noise,
  the case of the issue's "bias priors wide enough for consumer MEMS unless the dataset
  declares better"; the ``declared`` cells give the grade's model (turn-on bias as the bias
  1-sigma) instead;
- fix errors: white (``fix_tau_s`` 1e-3 s, the simulator needs > 0), or first-order
  Gauss-Markov with tau 10 s or 60 s (per-axis sigma UERE x DOP as the campus receiver's);
- covariance given or absent: absent, the ``gnss`` table's ``h_acc_m``, ``v_acc_m`` and
  ``speed_acc_mps`` and the ``gnss_obs`` table's ``pseudorange_std_m`` and
  ``pseudorange_rate_std_mps`` are null (a receiver or a RINEX file that reports none);
- GNSS at 1 / 5 / 10 Hz and IMU at 25 / 100 / 400 Hz, one at a time around the base cell
  (consumer MEMS, white fixes, covariance given, 1 Hz GNSS, 100 Hz IMU).

Every filter (``FILTERS``: the six INS filters, the fuzzy-adaptive ``fwekf`` and the
innovation-based adaptive ``iae_ekf``) runs through ``estimation.ins.replay.run_filter``
with params.yaml's section (``on_divergence: flag``), measured with
``ins.metrics.compute_metrics`` and given its status by the run contract's integrity monitor
(``ins.run.decode``), twice per cell and seed:

- ``nominal`` (all GNSS): horizontal RMS of the filter's IMU position against the truth at its
  output epochs (every ``step_s`` from the alignment), the reference's RMS over its epochs in
  the same span (the raw fixes for loose coupling, epoch-by-epoch SPP on the same observables
  for tight coupling; both at the antenna against the truth's antenna: ``_robustness``), their
  ratio, the NEES of position, velocity and attitude per dof (``compute_metrics``), the status;
- ``outages``: the ``gnss`` and ``gnss_obs`` rows inside ``OUTAGES`` removed
  (``scenarios.apply.apply_scenario``); per window, the first returning epoch (1: the first
  one back) with an accepted fix position (loose) or satellite block (a pseudorange and its
  rate; tight) in the run's innovation log, whether the stream was reset (``gate_reset``)
  before it, and the largest horizontal error over its own 3 sigma inside the window.

Acceptance (issue 22), per run: ``accuracy`` (nominal): loose ratio <= 0.8 on white cells,
<= 1.0 on correlated ones, tight <= 1.0; ``integrity`` (both runs): not ``ok`` with a
horizontal error over 10x its own 3 sigma anywhere; ``nees`` (nominal): NEES / dof in
[0.5, 2]; ``recovery`` (outages): every window's first returning epoch accepted by the
second.

``navreplay experiment robustness --out DIR`` (``stages.experiment``) writes ``runs.csv``, the
tables of ``summarize`` and ``pass_counts`` and ``note.md``; ``python -m
benchmarks.robustness_sweep --csv out.csv [--seeds 2] [--workers 2] [--cells ...]`` prints
them.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from navreplay.ingest.meta import SensorMeta
from navreplay.pipeline.compute import ComputeParams, TaskError
from navreplay.pipeline.estimation.ins.config import FILTER_KINDS
from navreplay.pipeline.estimation.ins.inputs import prepare_fixes, prepare_obs
from navreplay.pipeline.estimation.ins.metrics import compute_metrics
from navreplay.pipeline.estimation.ins.models import measurement as me
from navreplay.pipeline.estimation.ins.replay import run_filter
from navreplay.pipeline.estimation.ins.run import decode
from navreplay.pipeline.experiments.drives import FILTERS as INS_FILTERS
from navreplay.pipeline.experiments.drives import Tables, filter_params, pool_map
from navreplay.pipeline.experiments.robustness import measure as rb
from navreplay.pipeline.experiments.robustness.grid import (
    OUTAGES,
    Cell,
    SweepParams,
    grid,
    outage_windows,
    prepare,
    simulate,
    with_outages,
)

FILTERS = (*INS_FILTERS, "fwekf", "iae_ekf")
SCENARIOS = ("nominal", "outages")
#: acceptance bounds of issue 22
LOOSE_WHITE_RATIO, LOOSE_CORRELATED_RATIO, TIGHT_RATIO = 0.8, 1.0, 1.0
SIGMA_RATIO_MAX = 10.0
NEES_BOUNDS = (0.5, 2.0)
RECOVERY_EPOCHS = 2


@dataclass(frozen=True)
class WindowOutcome:
    """One outage window of a run: its length, the first returning epoch accepted (None:
    never), whether the stream was reset, the largest error over 3 sigma inside it."""

    length_s: float
    recovery_epochs: int | None
    reset: bool
    sigma_ratio: float

    @property
    def recovered(self) -> bool:
        return self.recovery_epochs is not None and self.recovery_epochs <= RECOVERY_EPOCHS


@dataclass(frozen=True)
class Outcome:
    """One run of one filter on one cell and seed (NaN where it does not apply)."""

    cell: Cell
    seed: int
    filter: str
    scenario: str
    status: str
    failure: str
    rms_h_m: float
    ref_rms_h_m: float
    nees_per_dof: float
    sigma_ratio: float
    windows: tuple[WindowOutcome, ...] = ()

    @property
    def loose(self) -> bool:
        return FILTER_KINDS[self.filter].coupling == "loose"

    @property
    def ratio(self) -> float:
        return self.rms_h_m / self.ref_rms_h_m

    def accuracy_ok(self) -> bool | None:
        """Nominal: the RMS within the issue's factor of the reference's."""
        if self.scenario != "nominal":
            return None
        bound = TIGHT_RATIO
        if self.loose:
            bound = LOOSE_WHITE_RATIO if self.cell.white else LOOSE_CORRELATED_RATIO
        return bool(self.ratio <= bound)

    def integrity_ok(self) -> bool:
        """Not ``ok`` while the error is over 10x its own 3 sigma."""
        return not (self.status == "ok" and not self.sigma_ratio <= SIGMA_RATIO_MAX)

    def nees_ok(self) -> bool | None:
        if self.scenario != "nominal":
            return None
        return bool(NEES_BOUNDS[0] <= self.nees_per_dof <= NEES_BOUNDS[1])

    def recovery_ok(self) -> bool | None:
        if self.scenario != "outages":
            return None
        return all(w.recovered for w in self.windows)

    def row(self) -> dict[str, object]:
        c = self.cell
        row: dict[str, object] = {
            "grade": c.grade,
            "fix_tau_s": c.fix_tau_s,
            "covariance": c.covariance,
            "gnss_hz": c.gnss_hz,
            "imu_hz": c.imu_hz,
            "imu_noise_declared": c.declared,
            "seed": self.seed,
            "filter": self.filter,
            "coupling": FILTER_KINDS[self.filter].coupling,
            "scenario": self.scenario,
            "status": self.status,
            "rms_h_m": self.rms_h_m,
            "ref_rms_h_m": self.ref_rms_h_m,
            "ratio": self.ratio,
            "nees_per_dof": self.nees_per_dof,
            "max_err_over_3sigma": self.sigma_ratio,
        }
        for (_, length), w in itertools.zip_longest(OUTAGES, self.windows):
            key = f"{length:g}s"
            row[f"recovery_epochs_{key}"] = "" if w is None else _text(w.recovery_epochs)
            row[f"reset_{key}"] = "" if w is None else w.reset
            row[f"window_err_over_3sigma_{key}"] = math.nan if w is None else w.sigma_ratio
        row.update(
            {
                "accuracy_ok": _text(self.accuracy_ok()),
                "integrity_ok": self.integrity_ok(),
                "nees_ok": _text(self.nees_ok()),
                "recovery_ok": _text(self.recovery_ok()),
                "failure": self.failure,
            }
        )
        return row


def _text(value: object) -> object:
    return "" if value is None else value


@dataclass(frozen=True)
class References:
    """A cell's references: the raw fixes (loose) and SPP (tight)."""

    fixes: rb.Track
    spp: rb.Track


def references(params: SweepParams, tables: Tables, lever_b: Sequence[float]) -> References:
    """The raw fixes' and SPP's horizontal errors of a cell's (nominal) tables."""
    truth = tables["truth"]
    gnss = params.filters.get("tc_ekf").gnss
    return References(
        rb.fix_reference(tables["gnss"], truth, lever_b),
        rb.spp_reference(tables["gnss_obs"], gnss, truth, lever_b),
    )


def run_one(
    params: SweepParams,
    cell: Cell,
    seed: int,
    name: str,
    tables: Tables,
    sensors: SensorMeta,
    refs: References,
    windows: Sequence[tuple[int, int]] = (),
    log: Tables | None = None,
) -> Outcome:
    """Run filter ``name`` on ``tables`` (outages: ``windows`` were removed) and measure it;
    its noise models learned from ``log`` (the whole log's tables, as the pipeline's scenario
    runs learn them) where given."""
    section = filter_params(params.filters, name)
    noise = None if log is None else prepare_fixes(log["gnss"], section.gnss).noise
    obs_noise = None if log is None else prepare_obs(log["gnss_obs"], section.gnss).noise
    result = run_filter(tables, sensors, name, section, fix_noise=noise, obs_noise=obs_noise)
    truth = tables["truth"]
    metrics = compute_metrics(result, truth)
    run = decode(result, metrics, (), section.integrity)
    track = rb.run_errors(result, truth)
    loose = FILTER_KINDS[name].coupling == "loose"
    ref = refs.fixes if loose else refs.spp
    nan = math.nan
    rms = ref_rms = sigma_ratio = nan
    if track.t_ns.size:
        t0, t1 = int(track.t_ns[0]), int(track.t_ns[-1])
        rms, ref_rms = track.rms_between(t0, t1), ref.rms_between(t0, t1)
        sigma_ratio = track.max_sigma_ratio(t0, t1 + 1)
    nees = metrics.get("nees_mean")
    dof = metrics.get("nees_dof") or 0
    outs: list[WindowOutcome] = []
    if windows:
        stream, table = (me.S_POS, "gnss") if loose else (me.S_OBS, "gnss_obs")
        epochs = np.asarray(tables[table].column("t_ns").to_numpy(), dtype=np.int64)
        starts = [a for a, _ in windows]
        for a, b in windows:
            later = [s for s in starts if s >= b]
            until = later[0] if later else int(epochs.max(initial=b)) + 1
            rec = rb.recovery(result.inn_i, result.events, epochs, stream, b, until)
            outs.append(
                WindowOutcome((b - a) * 1e-9, rec.epochs, rec.reset, track.max_sigma_ratio(a, b))
            )
    return Outcome(
        cell,
        seed,
        name,
        "outages" if windows else "nominal",
        run.status,
        str(run.metrics.get("failure") or ""),
        rms,
        ref_rms,
        nees / dof if nees is not None and dof else nan,
        sigma_ratio,
        tuple(outs),
    )


def run_group(
    params: SweepParams, cells: Sequence[Cell], seed: int, filters: Sequence[str] = FILTERS
) -> list[Outcome]:
    """Every filter, nominal and with outages, on ``cells`` (one simulation: they share it)."""
    keys = {c.sim_key for c in cells}
    assert len(keys) == 1, f"cells of different simulations: {keys}"
    base, sensors = simulate(params, cells[0], seed)
    windows = outage_windows(base)
    out: list[Outcome] = []
    for cell in cells:
        nominal, sens = prepare(base, sensors, cell)
        refs = references(params, nominal, sens.lever_arm_m)
        gapped = with_outages(nominal)
        for name in filters:
            out.append(run_one(params, cell, seed, name, nominal, sens, refs))
            out.append(run_one(params, cell, seed, name, gapped, sens, refs, windows, nominal))
    return out


def _task(args: tuple[SweepParams, tuple[Cell, ...], int, tuple[str, ...]]) -> list[Outcome]:
    params, cells, seed, filters = args
    return run_group(params, cells, seed, filters)


def sweep(
    params: SweepParams,
    cells: Sequence[Cell],
    seeds: Sequence[int],
    filters: Sequence[str] = FILTERS,
    *,
    workers: int = 2,
    scheduler: str = "processes",
    compute: ComputeParams | None = None,
    failed: list[TaskError] | None = None,
    progress: Callable[[str], None] | None = None,
) -> list[Outcome]:
    """Run ``cells`` x ``seeds`` x ``filters`` on at most ``workers`` processes or on a Dask
    cluster (``drives.pool_map``), one task per simulation (the biggest first, so that the
    pool ends together); a simulation that raised goes to ``failed``."""
    groups: dict[tuple[str, float, int, int], list[Cell]] = {}
    for c in cells:
        groups.setdefault(c.sim_key, []).append(c)
    tasks = [(params, tuple(g), s, tuple(filters)) for g in groups.values() for s in seeds]
    tasks.sort(key=lambda t: -len(t[1]) * t[1][0].imu_hz)
    return pool_map(_task, tasks, workers, scheduler=scheduler, compute=compute, failed=failed,
                    progress=progress)  # fmt: skip


STATUS_LETTER = {"ok": "o", "inconsistent": "i", "diverged": "d", "not_aligned": "n"}


def _cell_entry(runs: Sequence[Outcome]) -> str:
    """A filter's runs on one cell: worst ratio, NEES/dof furthest from 1, slowest recovery
    (``x``: a window never recovered), the statuses nominal / with outages (o k,
    i nconsistent, d iverged, n ot aligned), ``!`` if any acceptance point fails."""
    nominal = [o for o in runs if o.scenario == "nominal"]
    ratio = max((o.ratio for o in nominal), default=math.nan, key=_nan_last)
    nees = max(
        (o.nees_per_dof for o in nominal),
        default=math.nan,
        key=lambda v: abs(math.log(v)) if v > 0 else math.inf,
    )
    recs = [w.recovery_epochs for o in runs for w in o.windows]
    rec = "x" if None in recs else str(max((r for r in recs if r is not None), default=0))
    statuses = "/".join(_letters(o for o in runs if o.scenario == s) for s in SCENARIOS)
    bad = any(_fails(o) for o in runs)
    return f"{ratio:.2f} {nees:.2g} r{rec} {statuses}{'!' if bad else ''}"


def _letters(runs: Iterable[Outcome]) -> str:
    return "".join(sorted({STATUS_LETTER.get(o.status, "?") for o in runs}, key="oidn?".find))


def _nan_last(v: float) -> float:
    return math.inf if math.isnan(v) else v


def _fails(o: Outcome) -> list[str]:
    return [k for k, v in _checks(o).items() if v is False]


def _checks(o: Outcome) -> dict[str, bool | None]:
    return {
        "accuracy": o.accuracy_ok(),
        "integrity": o.integrity_ok(),
        "nees": o.nees_ok(),
        "recovery": o.recovery_ok(),
    }


def summarize(outcomes: Sequence[Outcome], filters: Sequence[str]) -> list[list[object]]:
    """One row per cell, one column per filter (``_cell_entry``)."""
    by: dict[Cell, dict[str, list[Outcome]]] = {}
    for o in outcomes:
        by.setdefault(o.cell, {}).setdefault(o.filter, []).append(o)
    order = {c: k for k, c in enumerate(grid())}
    return [
        [cell.label(), *(_cell_entry(runs.get(f, [])) for f in filters)]
        for cell, runs in sorted(by.items(), key=lambda kv: order.get(kv[0], len(order)))
    ]


def pass_counts(outcomes: Sequence[Outcome], filters: Sequence[str]) -> list[list[object]]:
    """Per acceptance point, per filter and in all: runs passing / runs it applies to, and in
    brackets cells passing in every seed / cells (the issue states its points per cell)."""
    rows: list[list[object]] = []
    for point in ("accuracy", "integrity", "nees", "recovery"):
        row: list[object] = [point]
        for f in (*filters, None):
            by_cell: dict[tuple[Cell, str], list[bool]] = {}
            for o in outcomes:
                v = _checks(o)[point]
                if v is not None and (f is None or o.filter == f):
                    by_cell.setdefault((o.cell, o.filter), []).append(v)
            runs = [v for vs in by_cell.values() for v in vs]
            cells = [all(vs) for vs in by_cell.values()]
            row.append(f"{sum(runs)}/{len(runs)} ({sum(cells)}/{len(cells)})")
        rows.append(row)
    return rows


LEGEND = (
    "per filter: worst nominal RMS / reference, NEES/dof furthest from 1, slowest recovery "
    "(first accepted epoch back; x never), statuses nominal/outages (o ok, i inconsistent, "
    "d diverged, n not aligned), ! an acceptance point fails"
)


def _markdown(headers: Sequence[str], rows: Sequence[Sequence[object]]) -> list[str]:
    lines = ["| " + " | ".join(headers) + " |", "|" + "---|" * len(headers)]
    return lines + ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]


def note(outcomes: Sequence[Outcome], filters: Sequence[str], seeds: range) -> str:
    """Markdown: what was run (on ``seeds``), the acceptance counts, the table per cell."""
    cells = len({o.cell for o in outcomes})
    which = f"seed {seeds.start}" if len(seeds) == 1 else f"seeds {seeds.start}-{seeds[-1]}"
    return "\n".join(
        [
            "# Robustness sweep (issue 22)",
            "",
            f"{cells} cells x {len(seeds)} seeds ({which}) x {len(filters)} filters, each run "
            "nominal and with "
            f"outages of {', '.join(f'{n:g}' for _, n in OUTAGES)} s: {len(outcomes)} runs "
            "(`runs.csv`, one row each; the grid and the acceptance points: "
            "`navreplay.pipeline.experiments.robustness.sweep`).",
            "",
            "Runs passing / runs (cells passing in every seed / cells), per acceptance point:",
            "",
            *_markdown(("acceptance", *filters, "all"), pass_counts(outcomes, filters)),
            "",
            LEGEND[0].upper() + LEGEND[1:] + ":",
            "",
            *_markdown(("cell", *filters), summarize(outcomes, filters)),
            "",
        ]
    )
