"""The alignment sweep of issue 21's acceptance, on generated data.

Grid: start kind x gyro turn-on bias x fix noise x receiver velocity, a few seeds per cell, and
every INS filter that fits the data (the loosely coupled ``lc_ekf``, ``lc_ekf_nhc``; the
tightly coupled ``tc_ekf``, ``tc_ekf_nhc``, ``tc_ukf``, ``tc_ukf_nhc``: the drives carry raw
observables) replayed through ``estimation.ins.replay.run_filter`` with params.yaml's sections
(``divergence.on_divergence: flag``, so a divergence is a status, not an exception).

- start kinds (the car test beds of ``pipeline.synth.car_drives``, whole): ``static`` is
  ``car_stop_and_go`` (15 s at rest, then stop-and-go traffic), ``rolling`` is
  ``car_rolling_start`` (10 m/s at the first sample), ``reversing`` is
  ``car_parking_reverse`` (20 s at rest, then backwards out of a bay);
- gyro turn-on bias: each axis ``+-b`` (signs drawn from the seed) replaces the campus IMU's
  drawn turn-on bias; the declared noise model says ``gyro_bias_sigma = b`` (an honest
  datasheet for that class of gyro); the truth's bias columns include it;
- fix noise: the receiver's UERE is scaled so that the median reported horizontal accuracy
  (per-axis 1-sigma, ``h_acc_m``) is the cell's value; the errors keep the synthesizer's
  Gauss-Markov correlation (``fix_tau_s``, 30 s, which the filters' ``pos_error_corr_time_s``
  assumes; ``--white-fixes`` makes them white, the case where differenced fixes are noisiest);
  the pseudorange noise scales with it (``pr_sigma_m`` x noise / 1.5 m);
- without receiver velocity: the gnss table's ``vel_*`` and ``speed_acc_mps`` are null, so a
  filter differences the fixes (the tightly coupled filters keep their Doppler for the
  updates, but align from the gnss table's fixes as the loosely coupled ones do).

Measured per run (times from the first sustained motion: the truth's horizontal speed above
``MOTION_SPEED_MPS`` for ``SUSTAIN_S``; for a rolling start, the first IMU sample): alignment
time and method, yaw error at alignment and after ``YAW_AFTER_S`` of motion against the truth,
each with the filter's own yaw 1-sigma, and the run status. A run passes if it is ``ok``,
aligned at most ``ALIGN_WITHIN_S`` after the first motion, did not align before the motion
with a heading from the course (noise at standstill), and its yaw error after 60 s of motion
is under 3 deg (5 deg on the 5 m cells without receiver velocity).

    python -m benchmarks.alignment_sweep --csv sweep.csv [--seeds 3] [--workers 2]
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import math
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa

from benchmarks._drives import FILTERS as FILTERS
from benchmarks._drives import REPO as REPO
from benchmarks._drives import Tables as Tables
from benchmarks._drives import add_imu_bias, bias_signs, pool_map, write_csv
from benchmarks._drives import filter_params as filter_params
from benchmarks._drives import without_velocity as without_velocity
from benchmarks._table import print_table
from navreplay.ingest.meta import SensorMeta
from navreplay.pipeline.estimation.ins.models import ins
from navreplay.pipeline.estimation.ins.replay import RunResult, run_filter
from navreplay.pipeline.params import Params, load_params
from navreplay.pipeline.synth import car_drives
from navreplay.pipeline.synth.seoul_params import SeoulCampusParams

KINDS = {
    "static": "car_stop_and_go",
    "rolling": "car_rolling_start",
    "reversing": "car_parking_reverse",
}
BIASES_DPS = (0.01, 0.1, 0.3, 1.0)
NOISES_M = (0.5, 1.5, 5.0)
#: the first sustained motion: the truth's horizontal speed above this ...
MOTION_SPEED_MPS = 0.5
#: ... for this long, s
SUSTAIN_S = 3.0
#: acceptance: aligned at most this long after the first sustained motion, s
ALIGN_WITHIN_S = 5.0
#: the yaw error is taken this long after the first sustained motion, s
YAW_AFTER_S = 60.0
#: the pseudorange noise of the campus receiver goes with 1.5 m fixes
BASE_NOISE_M = 1.5


@dataclass(frozen=True)
class Cell:
    """One cell of the grid."""

    kind: str
    bias_dps: float
    noise_m: float
    velocity: bool

    @property
    def yaw_limit_deg(self) -> float:
        """The acceptance bound on the yaw error after 60 s of motion."""
        return 5.0 if self.noise_m >= 5.0 and not self.velocity else 3.0

    def label(self) -> str:
        vel = "vel" if self.velocity else "no-vel"
        return f"{self.kind} b={self.bias_dps:g}dps {self.noise_m:g}m {vel}"


@dataclass(frozen=True)
class Outcome:
    """One filter run of one cell and seed (NaN where it does not apply)."""

    cell: Cell
    seed: int
    filter: str
    status: str
    method: str
    aligned_after_s: float
    yaw_err_align_deg: float
    yaw_sigma_align_deg: float
    yaw_err_60_deg: float
    yaw_sigma_60_deg: float
    failure: str
    run_failure: str = ""

    @property
    def passed(self) -> bool:
        return not self.failure

    def row(self) -> dict[str, object]:
        return {
            "kind": self.cell.kind,
            "gyro_bias_dps": self.cell.bias_dps,
            "fix_noise_m": self.cell.noise_m,
            "receiver_velocity": self.cell.velocity,
            "seed": self.seed,
            "filter": self.filter,
            "status": self.status,
            "method": self.method,
            "aligned_after_motion_s": self.aligned_after_s,
            "yaw_err_at_alignment_deg": self.yaw_err_align_deg,
            "yaw_sigma_at_alignment_deg": self.yaw_sigma_align_deg,
            "yaw_err_60s_deg": self.yaw_err_60_deg,
            "yaw_sigma_60s_deg": self.yaw_sigma_60_deg,
            "yaw_ratio_60s": abs(self.yaw_err_60_deg) / self.yaw_sigma_60_deg,
            "passed": self.passed,
            "failure": self.failure,
            "run_failure": self.run_failure,
        }


def grid(kinds: Iterable[str] = tuple(KINDS)) -> list[Cell]:
    """Every cell of the grid over ``kinds``."""
    return [
        Cell(k, b, n, v)
        for k, b, n, v in itertools.product(kinds, BIASES_DPS, NOISES_M, (True, False))
    ]


def _campus(params: Params, noise_m: float, uere_m: float, white: bool) -> SeoulCampusParams:
    """The campus car's sensors for a cell: the receiver's UERE and pseudorange noise scaled,
    no drawn gyro turn-on bias (``with_bias`` puts the cell's in)."""
    campus = params.synth.seoul_campus
    g = dataclasses.replace(
        campus.gnss,
        fix_uere_m=uere_m,
        pr_sigma_m=campus.gnss.pr_sigma_m * noise_m / BASE_NOISE_M,
        fix_tau_s=1e-3 if white else campus.gnss.fix_tau_s,
    )
    imu = dataclasses.replace(campus.imu, gyro_bias_sigma_radps=0.0)
    return dataclasses.replace(campus, gnss=g, imu=imu)


def simulate(
    params: Params, kind: str, noise_m: float, seed: int, *, white: bool = False
) -> tuple[Tables, SensorMeta]:
    """The drive of start ``kind`` with fixes of ``noise_m`` per-axis horizontal 1-sigma
    (median of the reported ``h_acc_m``) and no gyro turn-on bias (``with_bias`` adds it)."""
    name = KINDS[kind]
    drive = params.synth.car_drives[name]
    base = params.synth.seoul_campus.gnss.fix_uere_m

    def run(uere: float) -> tuple[Tables, SensorMeta]:
        campus = _campus(params, noise_m, uere, white)
        r = car_drives.simulate(name, campus, drive, seed=seed)
        return dict(r.tables), r.sensors

    tables, _ = run(base)
    h_acc = float(np.median(tables["gnss"].column("h_acc_m").to_numpy()))
    return run(base * noise_m / h_acc)


def with_bias(
    tables: Tables, sensors: SensorMeta, bias_dps: float, seed: int
) -> tuple[Tables, SensorMeta]:
    """The IMU with a constant gyro bias of ``+-bias_dps`` per axis (signs from ``seed``), the
    truth's bias columns with it, and the declared gyro bias 1-sigma ``bias_dps``."""
    b = math.radians(bias_dps) * bias_signs(seed, 21)
    biased = add_imu_bias(tables, b, np.zeros(3))
    assert sensors.imu_noise is not None
    noise = dataclasses.replace(sensors.imu_noise, gyro_bias_sigma_radps=math.radians(bias_dps))
    return biased, dataclasses.replace(sensors, imu_noise=noise)


def first_motion_ns(truth: pa.Table, imu_t0_ns: int, kind: str) -> int:
    """The first sustained motion: the truth's horizontal speed above ``MOTION_SPEED_MPS`` for
    ``SUSTAIN_S``; a rolling start moves from the first IMU sample."""
    if kind == "rolling":
        return imu_t0_ns
    t = truth.column("t_ns").to_numpy()
    speed = np.hypot(truth.column("vel_n_mps").to_numpy(), truth.column("vel_e_mps").to_numpy())
    fast = speed > MOTION_SPEED_MPS
    need = round(SUSTAIN_S * 1e9 / float(np.median(np.diff(t))))
    runs = np.convolve(fast.astype(np.int64), np.ones(need, np.int64), "valid")
    k = int(np.flatnonzero(runs == need)[0])
    return int(t[k])


def _yaw(q: np.ndarray) -> float:
    return math.atan2(2 * (q[0] * q[3] + q[1] * q[2]), 1 - 2 * (q[2] ** 2 + q[3] ** 2))


def _truth_yaw(truth: pa.Table, t_ns: int) -> float:
    t = truth.column("t_ns").to_numpy()
    k = min(int(np.searchsorted(t, t_ns)), t.size - 1)
    return float(truth.column("yaw_rad")[k].as_py())


def _wrap_deg(a: float) -> float:
    return math.degrees(math.remainder(a, 2 * math.pi))


def measure(cell: Cell, seed: int, r: RunResult, truth: pa.Table, t_motion: int) -> Outcome:
    """The figures of one run and whether (and why not) it passes."""
    nan = math.nan
    method, after, e_al, s_al, e60, s60 = "", nan, nan, nan, nan, nan
    fails: list[str] = []
    if r.status != "ok":
        fails.append(f"status {r.status}")
    if r.alignments:
        al = r.alignments[0]
        method = al.method
        after = (al.t_ns - t_motion) * 1e-9
        e_al = _wrap_deg(_yaw(al.x0[ins.X_Q : ins.X_Q + 4]) - _truth_yaw(truth, al.t_ns))
        s_al = math.degrees(math.sqrt(al.P0[ins.E_ATT + 2, ins.E_ATT + 2]))
        if after > ALIGN_WITHIN_S:
            fails.append(f"aligned {after:.1f} s after the first motion")
        if after < 0.0 and method.startswith("gnss_velocity"):
            fails.append(f"aligned on noise at standstill ({-after:.1f} s before motion)")
    t60 = t_motion + int(YAW_AFTER_S * 1e9)
    if r.t_ns.size and r.t_ns[0] <= t60 <= r.t_ns[-1]:
        k = int(np.searchsorted(r.t_ns, t60))
        e60 = _wrap_deg(_yaw(r.x[k, ins.X_Q : ins.X_Q + 4]) - _truth_yaw(truth, int(r.t_ns[k])))
        s60 = math.degrees(math.sqrt(r.P[k, ins.E_ATT + 2, ins.E_ATT + 2]))
        if abs(e60) >= cell.yaw_limit_deg:
            fails.append(f"yaw error {e60:+.1f} deg after 60 s (limit {cell.yaw_limit_deg:g})")
    elif r.alignments:
        fails.append("no estimate 60 s after the first motion")
    elif r.status == "ok":
        fails.append("never aligned")
    return Outcome(
        cell,
        seed,
        r.filter,
        r.status,
        method,
        after,
        e_al,
        s_al,
        e60,
        s60,
        "; ".join(fails),
        r.failure or "",
    )


def run_cells(
    params: Params,
    kind: str,
    noise_m: float,
    seed: int,
    cells: Sequence[Cell],
    filters: Sequence[str] = FILTERS,
    *,
    white: bool = False,
) -> list[Outcome]:
    """Every filter on every cell of (``kind``, ``noise_m``) in ``cells`` for one seed: one
    simulation, the bias and the velocity applied per cell."""
    base, sensors = simulate(params, kind, noise_m, seed, white=white)
    t0 = int(base["imu"].column("t_ns")[0].as_py())
    t_motion = first_motion_ns(base["truth"], t0, kind)
    out: list[Outcome] = []
    for cell in cells:
        if (cell.kind, cell.noise_m) != (kind, noise_m):
            continue
        tables, sens = with_bias(base, sensors, cell.bias_dps, seed)
        if not cell.velocity:
            tables = without_velocity(tables)
        for name in filters:
            r = run_filter(tables, sens, name, filter_params(params, name))
            out.append(measure(cell, seed, r, tables["truth"], t_motion))
    return out


def _task(args: tuple[str, float, int, tuple[Cell, ...], tuple[str, ...], bool]) -> list[Outcome]:
    kind, noise, seed, cells, filters, white = args
    return run_cells(
        load_params(REPO / "params.yaml"), kind, noise, seed, cells, filters, white=white
    )


def sweep(
    cells: Sequence[Cell],
    seeds: Sequence[int],
    filters: Sequence[str] = FILTERS,
    *,
    workers: int = 2,
    white: bool = False,
) -> list[Outcome]:
    """Run ``cells`` x ``seeds`` x ``filters`` on at most ``workers`` processes."""
    groups = sorted({(c.kind, c.noise_m) for c in cells})
    tasks = [
        (k, n, s, tuple(cells), tuple(filters), white)
        for (k, n), s in itertools.product(groups, seeds)
    ]
    return pool_map(_task, tasks, workers)


def summarize(outcomes: Sequence[Outcome]) -> list[list[object]]:
    """One row per cell: the worst alignment delay and yaw error over filters and seeds, the
    runs that fail, the worst run and why."""
    by: dict[Cell, list[Outcome]] = {}
    for o in outcomes:
        by.setdefault(o.cell, []).append(o)
    rows: list[list[object]] = []
    for cell, runs in by.items():
        after = [o.aligned_after_s for o in runs]
        e60 = [abs(o.yaw_err_60_deg) for o in runs]
        worst = max(runs, key=lambda o: (not o.passed, _badness(o)))
        failed = [o for o in runs if not o.passed]
        rows.append(
            [
                cell.kind,
                cell.bias_dps,
                cell.noise_m,
                "yes" if cell.velocity else "no",
                _nanmax(after),
                _nanmax(e60),
                f"{len(runs) - len(failed)}/{len(runs)}",
                "PASS" if not failed else "FAIL",
                f"{worst.filter} s{worst.seed}",
                worst.failure or "-",
            ]
        )
    return rows


def _badness(o: Outcome) -> float:
    e = abs(o.yaw_err_60_deg)
    return math.inf if math.isnan(e) else e


def _nanmax(values: Sequence[float]) -> float:
    finite = [v for v in values if not math.isnan(v)]
    return max(finite) if len(finite) == len(values) else math.nan


HEADERS = (
    "kind",
    "bias dps",
    "noise m",
    "rx vel",
    "aligned after motion s (max)",
    "yaw err 60 s deg (max)",
    "runs ok",
    "status",
    "worst",
    "why",
)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0] if __doc__ else "")
    parser.add_argument("--csv", type=Path, required=True, help="write every run here")
    parser.add_argument("--seeds", type=int, default=3, help="seeds per cell (default 3)")
    parser.add_argument("--workers", type=int, default=2, help="processes, at most 2")
    parser.add_argument("--kinds", nargs="+", default=list(KINDS), choices=list(KINDS))
    parser.add_argument("--filters", nargs="+", default=list(FILTERS), choices=list(FILTERS))
    parser.add_argument(
        "--white-fixes",
        action="store_true",
        help="white fix errors instead of the receiver's 30 s correlation",
    )
    args = parser.parse_args(argv)
    start = time.perf_counter()
    outcomes = sweep(
        grid(args.kinds),
        range(1, args.seeds + 1),
        args.filters,
        workers=args.workers,
        white=args.white_fixes,
    )
    write_csv(args.csv, [o.row() for o in outcomes])
    print_table(HEADERS, summarize(outcomes))
    failed = sum(not o.passed for o in outcomes)
    print(
        f"{len(outcomes)} runs, {failed} failing, {time.perf_counter() - start:.0f} s; "
        f"every run in {args.csv}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
