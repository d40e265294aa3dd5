"""Dask: the outage Monte Carlo on a local Dask cluster of 1 and 2 workers, vs forked workers.

The workload is the outage Monte Carlo of params.yaml (tc_ukf on a 10-minute seoul_campus
drive; per window start every case: k = 0..4 satellites for 60 s and complete outages of
10-120 s, each with its tail) with ``--dask-starts`` window starts, one task each. It runs in
this process (the tasks' own time), on a Dask ``LocalCluster`` (``compute.dask_client``:
processes, one thread each) of one and of two workers, reached through its address as a
remote cluster would be (``run_montecarlo(scheduler=ADDRESS)``: a client, the job scattered
to every worker, a task per start) after every worker has loaded the kernel, and on the
default engine (two forked workers). Printed:

- wall time, tasks per second, wall x workers per task;
- overhead per task: ``(wall x workers - serial) / tasks``, what scheduling, sending and
  collecting cost per task on this machine, and the efficiency ``serial / (wall x workers)``;
- the 1 -> 2 worker scaling efficiency ``T1 / (2 T2)`` (target >= 85 %);
- the scheduler's throughput on empty tasks, and from it and the measured task time, the
  extrapolation to 100 workers: the task rate 100 workers would ask of the scheduler
  (``100 / task s``) against what it sustains.

The machine has two cores shared with the scheduler and this client, so the two-worker
figures include their CPU use.
"""

from __future__ import annotations

import argparse
import os
import time
from dataclasses import replace
from typing import Any

from benchmarks._table import print_table
from navreplay.pipeline.estimation.ins.replay import run_filter
from navreplay.pipeline.outages.montecarlo import cases_for, draw_starts, run_montecarlo
from tests.pipeline.scenarios.drives import drive, params

NAME = "tc_ukf"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--dask-starts", type=int, default=64, help="window starts, one task each (default 64)"
    )
    parser.add_argument(
        "--dask-empty", type=int, default=2000, help="empty tasks for the scheduler's rate"
    )


def _load_kernel(tables: Any, sensors: Any) -> int:
    """On a worker: replay the first minute, so that the kernel is loaded before the timing."""
    from navreplay.pipeline.estimation.ins.replay import run_filter
    from navreplay.pipeline.scenarios.apply import log_span

    t0, _ = log_span(tables)
    short = {
        k: t.filter(t.column("t_ns").to_numpy() < t0 + 60 * 10**9) if "t_ns" in t.column_names
        else t
        for k, t in tables.items()
    }  # fmt: skip
    run_filter(short, sensors, NAME, params().filters.get(NAME))
    return os.getpid()


def _nothing(shared: int, item: int) -> int:
    return item


def _row(engine: str, workers: int, wall: float, serial: float, tasks: int) -> list[object]:
    return [engine, workers, wall, tasks / wall, wall * workers / tasks,
            1e3 * (wall * workers - serial) / tasks, serial / (wall * workers)]  # fmt: skip


def run(options: argparse.Namespace) -> None:
    from navreplay.pipeline.compute import ComputeParams, dask_client, run_tasks

    tables, sensors = drive(600.0, seed=21)
    t = tables["imu"].column("t_ns").to_numpy()
    p = params()
    o = p.outages
    section = p.filters.get(NAME)
    cases = cases_for(o.sats, o.sats_window_s, o.lengths_s)
    longest = max(c.length_s for c in cases)
    seeds = list(range(1, -(-options.dask_starts // 8) + 1))
    starts = draw_starts(seeds, 8, int(t[0]), int(t[-1]), o.earliest_s, longest, o.tail_s)
    starts = starts[: options.dask_starts]
    nominal = run_filter(tables, sensors, NAME, replace(section, smooth=False))

    def montecarlo(**engine: Any) -> tuple[float, float]:
        """(wall s of the tasks, from submitting the first to the last result; their own s)"""
        rows, timing, failed = run_montecarlo(
            tables, sensors, sensors.lever_arm_m, NAME, section, starts, cases,
            policy=o.policy, tail_s=o.tail_s, mask_deg=p.scenarios.selection_mask_deg,
            metrics=p.scenarios.metrics, nominal=nominal, **engine,
        )  # fmt: skip
        assert not failed, failed[0].error
        return timing["replay_wall_s"], float(sum(r["replay_s"] for r in rows))

    serial, _ = montecarlo(workers=1)  # in this process: the tasks' own time, no overhead
    table: list[list[object]] = [["this process (serial)", 1, serial, len(starts) / serial,
                                  serial / len(starts), 0.0, 1.0]]  # fmt: skip
    walls: dict[int, float] = {}
    rate = 0.0
    for n in (1, 2):
        with dask_client("local", ComputeParams(workers=n)) as client:
            address = client.scheduler.address
            client.run(_load_kernel, tables, sensors)
            wall, _ = montecarlo(scheduler=address)
            walls[n] = wall
            table.append(_row(f"Dask, {n} worker{'s' if n > 1 else ''}", n, wall, serial,
                              len(starts)))  # fmt: skip
            if n == 2:
                w = time.perf_counter()
                run_tasks(_nothing, 0, list(range(options.dask_empty)),
                          scheduler=address)  # fmt: skip
                rate = options.dask_empty / (time.perf_counter() - w)
    wall, _ = montecarlo(workers=2)
    table.append(_row("forked (the default)", 2, wall, serial, len(starts)))
    print(f"   {NAME}, {len(starts)} window starts on a 10-minute drive, one task each: its")
    print(f"   {len(cases)} cases of params.yaml's outages (k = 0..4 at 60 s, complete outages of")
    print("   10-120 s), replayed from the nominal run's state. Wall: from the client's")
    print("   connection and sending the job to the workers to the last result.")
    print("   Overhead per task: (wall x workers - serial) / tasks; efficiency: serial /")
    print("   (wall x workers).")
    print_table(["engine", "workers", "wall s", "tasks/s", "task s", "overhead/task ms",
                 "efficiency"], table)  # fmt: skip
    eff = walls[1] / (2.0 * walls[2])
    task_s = serial / len(starts)
    print(f"   1 -> 2 Dask workers: scaling efficiency T1 / (2 T2) {100 * eff:.0f} % (target "
          ">= 85 %)")  # fmt: skip
    need = 100.0 / task_s
    print(f"   scheduler: {rate:,.0f} empty tasks/s; 100 workers on {task_s:.2f} s tasks would ask "
          f"{need:,.0f} tasks/s of it ({100 * need / rate:.0f} % of that)")  # fmt: skip
