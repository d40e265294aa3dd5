"""Outage Monte Carlo: 256 outage scenarios of a 10-minute drive with tc_ukf, vs full replays.

One 10-minute seoul_campus drive (the synthesizer of params.yaml: 100 Hz IMU, 1 Hz GNSS,
7-8 satellites, 10 s at rest first). Each scenario is
a complete 60 s GNSS outage at a start drawn uniformly over the drive (32 seeds x 8 starts).
Ours: ``outages.montecarlo.run_montecarlo``, every window replayed from the nominal run's
state at its start over the window and a 30 s tail, on ``--outages-workers`` processes (the
nominal run and the pool start-up included). Reference, measured in the same run: the
straightforward way, each scenario applied to the tables and replayed in full from the start
of the log on one core (``--outages-reference`` of them, extrapolated to all scenarios on the
same number of cores). Both give the same window metrics (checked here, and in
tests/pipeline/outages/test_montecarlo.py to 1e-6 m). Target: ours under 120 s.
"""

from __future__ import annotations

import argparse
import time

from benchmarks._table import print_table
from navreplay.pipeline.estimation.core.windows import NS
from navreplay.pipeline.estimation.ins.metrics import compute_metrics
from navreplay.pipeline.estimation.ins.replay import run_filter
from navreplay.pipeline.outages.montecarlo import Case, draw_starts, run_montecarlo
from navreplay.pipeline.scenarios.apply import apply_scenario
from navreplay.pipeline.scenarios.config import ScenarioSpec, WindowsSpec
from tests.pipeline.scenarios.drives import drive, params

LENGTH_S, TAIL_S, PER_SEED = 60.0, 30.0, 8


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--outages-scenarios", type=int, default=256, help="outage scenarios (default 256)"
    )
    parser.add_argument(
        "--outages-reference",
        type=int,
        default=6,
        help="scenarios replayed in full for the reference (default 6, extrapolated)",
    )
    parser.add_argument("--outages-workers", type=int, default=2, help="processes (default 2)")


def run(options: argparse.Namespace) -> None:
    name = "tc_ukf"
    p = params()
    section = p.filters.get(name)
    tables, sensors = drive(600.0, seed=21)
    t = tables["imu"].column("t_ns").to_numpy()
    t0, t_end = int(t[0]), int(t[-1])
    seeds = list(range(1, -(-options.outages_scenarios // PER_SEED) + 1))
    starts = draw_starts(seeds, PER_SEED, t0, t_end, 60.0, LENGTH_S, TAIL_S)
    starts = starts[: options.outages_scenarios]
    run_filter(tables, sensors, name, section)  # compile (or load the cache) outside the timing

    wall = time.perf_counter()
    rows, timing, failed = run_montecarlo(
        tables,
        sensors,
        sensors.lever_arm_m,
        name,
        section,
        starts,
        [Case(LENGTH_S, 0)],
        policy="highest_elevation",
        tail_s=TAIL_S,
        mask_deg=10.0,
        metrics=p.scenarios.metrics,
        workers=options.outages_workers,
    )
    ours_s = time.perf_counter() - wall
    if failed:
        raise RuntimeError(f"{len(failed)} Monte Carlo windows failed: {failed[0].error}")

    n_ref = min(options.outages_reference, len(starts))
    diffs = []
    wall = time.perf_counter()
    for s, row in zip(starts[:n_ref], rows[:n_ref], strict=True):
        spec = ScenarioSpec(
            windows=WindowsSpec("explicit", LENGTH_S, starts_s=((s.start_ns - t0) / NS,))
        )
        applied = apply_scenario(tables, "one", spec)
        r = run_filter(applied.tables, sensors, name, section)
        m = compute_metrics(
            r,
            tables["truth"],
            windows=applied.outage_windows,
            t0_ns=t0,
            window_params=p.scenarios.metrics,
        )
        diffs.append(abs(m["outage_windows"][0]["err_end_m"] - row["err_end_m"]))
    ref_each = (time.perf_counter() - wall) / max(n_ref, 1)
    ref_total = ref_each * len(starts) / options.outages_workers
    replayed = timing["replayed_s"]
    print_table(
        ["method", "scenarios", "log replayed s", "wall s", "per scenario s", "vs ours"],
        [
            [
                "window replays from checkpoints (ours)",
                len(starts),
                replayed,
                ours_s,
                ours_s / len(starts),
                1.0,
            ],
            [
                f"full replays (measured {n_ref}, extrapolated, {options.outages_workers} cores)",
                len(starts),
                600.0 * len(starts),
                ref_total,
                ref_each,
                ref_total / ours_s,
            ],
        ],
    )
    print(
        f"  target: {len(starts)} scenarios in < 120 s -> {ours_s:.1f} s "
        f"({'met' if ours_s < 120 else 'NOT met'}); nominal run {timing['nominal_s']:.1f} s, "
        f"{replayed / timing['replay_wall_s']:.0f}x real time over {options.outages_workers} "
        f"processes; window metrics equal to full replays within {max(diffs, default=0):.1e} m"
    )
