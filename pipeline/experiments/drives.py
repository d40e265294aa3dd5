"""What the generated-drive sweeps share (``robustness``; ``benchmarks/alignment_sweep.py``).

The campus car's drives as tables, the transformations a sweep applies to them before the
replay (a constant IMU bias in the IMU and in the truth, receiver columns made null), the
filters' parameter sections with a divergence flagged instead of raised, and the pool of at
most two spawned workers the sweeps run on (the machine's two cores are shared).
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


def quiet() -> None:
    """The filters' own warnings (a divergence, no alignment) are in the outcomes already: a
    worker process leaves them out (the calling process's logging is left alone)."""
    logging.getLogger("navreplay").setLevel(logging.ERROR)


def pool_map(task: Callable[[T], list[R]], tasks: Sequence[T], workers: int) -> list[R]:
    """``task`` over ``tasks``, flattened, in order: in this process with ``workers <= 1``,
    else on at most two spawned processes (``task`` must be a module-level function)."""
    if workers <= 1:
        return [o for t in tasks for o in task(t)]
    with multiprocessing.get_context("spawn").Pool(min(workers, 2), initializer=quiet) as pool:
        return [o for part in pool.imap(task, tasks) for o in part]


def write_csv(path: Path, rows: Sequence[Mapping[str, object]]) -> None:
    """One CSV row per mapping; the columns are the first row's keys."""
    with path.open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
