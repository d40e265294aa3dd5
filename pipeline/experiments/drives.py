"""What the generated-drive sweeps share (``robustness``; ``benchmarks/alignment_sweep.py``).

The campus car's drives as tables, the transformations a sweep applies to them before the
replay (a constant IMU bias in the IMU and in the truth, receiver columns made null), the
filters' parameter sections with a divergence flagged instead of raised, and where the
sweeps run (``pool_map``: at most two forked workers, the machine's two cores being shared,
or a Dask cluster).
"""

from __future__ import annotations

import csv
import dataclasses
import logging
import multiprocessing
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import TypeVar

import numpy as np
import pyarrow as pa

from navreplay.pipeline.compute import ComputeParams, TaskError, run_tasks
from navreplay.pipeline.estimation.config import FiltersParams
from navreplay.pipeline.estimation.ins.config import InsFilterParams

#: every INS filter that reads the car drives' tables (the adaptive fwekf and iae_ekf aside)
FILTERS = ("lc_ekf", "lc_ekf_nhc", "tc_ekf", "tc_ekf_nhc", "tc_ukf", "tc_ukf_nhc")
#: the receiver velocity columns of the ``gnss`` table
VELOCITY_COLUMNS = ("vel_n_mps", "vel_e_mps", "vel_d_mps", "speed_acc_mps")

Tables = dict[str, pa.Table]
T = TypeVar("T")
R = TypeVar("R")


def filter_params(filters: FiltersParams, name: str) -> InsFilterParams:
    """``filters.<name>`` of params.yaml, divergence flagged instead of raised, not smoothed
    (the sweeps measure the filter)."""
    p = filters.get(name)
    return dataclasses.replace(
        p, divergence=dataclasses.replace(p.divergence, on_divergence="flag"), smooth=False
    )


def with_nulls(table: pa.Table, columns: Iterable[str]) -> pa.Table:
    """``table`` with ``columns`` (those it has) all null, types kept."""
    for col in columns:
        if col in table.column_names:
            i = table.column_names.index(col)
            table = table.set_column(
                i, table.schema.field(col), pa.nulls(table.num_rows, table.schema.field(col).type)
            )
    return table


def without_velocity(tables: Mapping[str, pa.Table]) -> Tables:
    """The gnss table with its receiver velocity (and speed accuracy) null."""
    return dict(tables, gnss=with_nulls(tables["gnss"], VELOCITY_COLUMNS))


def bias_signs(seed: int, salt: int) -> np.ndarray:
    """Three signs (+-1) drawn from ``seed`` and ``salt``: which way each axis's bias points."""
    return np.random.default_rng(np.random.SeedSequence([seed, salt])).choice([-1.0, 1.0], 3)


def add_imu_bias(
    tables: Mapping[str, pa.Table], gyro_radps: np.ndarray, accel_mps2: np.ndarray
) -> Tables:
    """The IMU with constant biases added per body axis (gyro rad/s, accel m/s^2, each (3,)),
    and the truth's bias columns with them (so the NEES over biases stays right)."""
    imu, truth = tables["imu"], tables["truth"]
    for sensor, unit, bias in (("gyro", "radps", gyro_radps), ("acc", "mps2", accel_mps2)):
        for j, axis in enumerate("xyz"):
            if bias[j] == 0.0:
                continue
            col = f"{sensor}_{axis}_{unit}"
            imu = imu.set_column(
                imu.column_names.index(col), col, pa.array(imu.column(col).to_numpy() + bias[j])
            )
            col = f"{sensor}_bias_{axis}_{unit}"
            truth = truth.set_column(
                truth.column_names.index(col), col, pa.array(truth.column(col).to_numpy() + bias[j])
            )
    return dict(tables, imu=imu, truth=truth)


def _quietly(task: Callable[[T], list[R]], item: T) -> list[R]:
    """``task(item)``; in a worker process without the filters' own warnings (a divergence,
    no alignment), which are in the outcomes already (this process's logging is left
    alone)."""
    if multiprocessing.parent_process() is not None:
        logging.getLogger("navreplay").setLevel(logging.ERROR)
    return task(item)


def pool_map(
    task: Callable[[T], list[R]],
    tasks: Sequence[T],
    workers: int,
    *,
    scheduler: str = "processes",
    compute: ComputeParams | None = None,
    failed: list[TaskError] | None = None,
    progress: Callable[[str], None] | None = None,
) -> list[R]:
    """``task`` over ``tasks``, flattened, in order, as tasks of ``compute.run_tasks``: in
    this process with ``workers <= 1``, else on at most two forked processes (the machine's
    two cores are shared), or on a Dask cluster (``scheduler``; ``task`` must be a
    module-level function). A task that raised is appended to ``failed`` and the others
    still run; without ``failed``, the first is raised once all have run."""
    results = run_tasks(
        _quietly, task, tasks, scheduler=scheduler, workers=min(workers, 2), params=compute,
        label="sweep", progress=progress,
    )  # fmt: skip
    out: list[R] = []
    for r in results:
        if isinstance(r, TaskError):
            if failed is None:
                r.reraise()
            else:
                failed.append(r)
        else:
            out += r
    return out


def write_csv(path: Path, rows: Sequence[Mapping[str, object]]) -> None:
    """One CSV row per mapping; the columns are the first row's keys."""
    with path.open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
