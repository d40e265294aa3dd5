"""Cascaded tractor filters (paper 000): compiled backend vs filterpy, and the closed loop.

On the 80 s, 50 Hz ``tractor_straight`` recording (synthesized in memory from params.yaml),
each of ``cascaded_ekf``, ``cascaded_ukf`` and ``cascaded_hybrid`` is replayed open loop on
the numba backend and on the filterpy backend (same model, same gating): time per sample,
real-time factor and the ratio. Then one closed-loop run per filter (the LQR steering
``TractorSim`` from the estimates), next to the simulator alone stepping the same 4000 steps,
so the filter's share of a Monte Carlo run is visible. Compilation is excluded (one warm-up
run); the figures are best of ``--cascaded-repeat``.
"""

from __future__ import annotations

import argparse
from functools import partial
from pathlib import Path

from benchmarks._table import print_table, timed
from navreplay.pipeline.estimation.cascaded.backends import replay
from navreplay.pipeline.estimation.cascaded.closed_loop import run_closed_loop
from navreplay.pipeline.estimation.cascaded.config import CASCADED_KINDS
from navreplay.pipeline.estimation.cascaded.engine import make_setup
from navreplay.pipeline.estimation.cascaded.inputs import prepare_inputs
from navreplay.pipeline.params import load_params
from navreplay.pipeline.synth.tractor import TractorSim
from navreplay.pipeline.synth.tractor_log import synthesize

REPO = Path(__file__).resolve().parents[1]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--cascaded-repeat", type=int, default=3, help="repetitions, best taken (default 3)"
    )


def run(options: argparse.Namespace) -> None:
    params = load_params(REPO / "params.yaml")
    sim = params.synth.tractor_straight
    tables = dict(synthesize(sim, params.synth.seed).tables)
    inp = prepare_inputs(tables, "cascaded_ekf")
    n = inp.veh_t.size
    seconds = sim.duration_s
    repeat = options.cascaded_repeat
    rows: list[list[object]] = []
    for name in CASCADED_KINDS:
        setup = make_setup(name, params.filters.cascaded(name))
        replay(setup, inp.veh_t, inp.veh, inp.gps_t, inp.gps, "numba")  # compile / load cache
        fast = timed(partial(replay, setup, inp.veh_t, inp.veh, inp.gps_t, inp.gps, "numba"),
                     repeat)  # fmt: skip
        ref = timed(partial(replay, setup, inp.veh_t, inp.veh, inp.gps_t, inp.gps, "filterpy"))
        rows.append([name, fast.seconds / n * 1e6, seconds / fast.seconds,
                     ref.seconds / n * 1e6, ref.seconds / fast.seconds])  # fmt: skip
    print(f"open-loop replay of {seconds:g} s at {sim.rate_hz} Hz ({n} samples)")
    print_table(["filter", "numba us/sample", "x real time", "filterpy us/sample", "ratio"], rows)

    def sim_only() -> None:
        s = TractorSim(sim, 1)
        for _ in range(sim.steps):
            s.step(0.0)

    t_sim = timed(sim_only, repeat).seconds
    rows = []
    for name in CASCADED_KINDS:
        setup = make_setup(name, params.filters.cascaded(name))
        loop = timed(partial(run_closed_loop, setup, sim, 1), repeat).seconds
        rows.append([name, loop, loop / sim.steps * 1e6])
    rows.append(["simulator alone", t_sim, t_sim / sim.steps * 1e6])
    print(f"closed loop, one {seconds:g} s run (LQR on the estimates, TractorSim)")
    print_table(["run", "s per run", "us per step"], rows)
