"""Vehicle-model filters (paper 003) and FWEKF (paper 004): numba against filterpy, same run.

Vehicle filters: the 360 s car_speed_ramp drive (100 Hz vehicle, 10 Hz GPS), each filter on
both backends (after compilation). FWEKF and lc_ekf: the 900 s seoul_campus drive (100 Hz
IMU, 1 Hz GNSS) on the numba backend, and the FWEKF's filterpy backend on its first 120 s.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Mapping
from typing import Literal

import numpy as np
import pyarrow as pa

from benchmarks._table import print_table, timed

Backend = Literal["numba", "filterpy"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--vehicle-fwekf-skip-filterpy", action="store_true", help="numba only (quick look)"
    )


def run(options: argparse.Namespace) -> None:
    from navreplay.pipeline.estimation.ins.replay import run_filter
    from navreplay.pipeline.estimation.vehicle.config import VEHICLE_FILTERS
    from navreplay.pipeline.estimation.vehicle.replay import run_vehicle_filter
    from navreplay.pipeline.params import load_params
    from navreplay.pipeline.synth import car
    from navreplay.pipeline.synth.seoul_campus import simulate

    p = load_params("params.yaml")
    drive = car.synthesize(p.synth.car_speed_ramp, p.synth.seed).tables
    rows: list[list[object]] = []

    def vehicle(name: str, backend: Backend) -> Callable[[], object]:
        return lambda: run_vehicle_filter(drive, name, p.filters.vehicle(name), backend=backend)

    for name in VEHICLE_FILTERS:
        vehicle(name, "numba")()  # compile / load the cache
        ours = timed(vehicle(name, "numba"), repeat=3).seconds
        ref = float("nan")
        if not options.vehicle_fwekf_skip_filterpy:
            ref = timed(vehicle(name, "filterpy")).seconds
        rows.append([name, 360.0, ours, ref, ref / ours, 360.0 / ours])
    seoul = simulate(p.synth.seoul_campus, seed=p.synth.seed, variant="cw")
    dur = p.synth.seoul_campus.duration_s

    def ins(tables: Mapping[str, pa.Table], name: str, backend: Backend) -> Callable[[], object]:
        sec = p.filters.get(name)
        return lambda: run_filter(tables, seoul.sensors, name, sec, backend=backend)

    for name in ("lc_ekf", "fwekf"):
        ins(seoul.tables, name, "numba")()
        ours = timed(ins(seoul.tables, name, "numba"), 3).seconds
        rows.append([name, dur, ours, float("nan"), float("nan"), dur / ours])
    if not options.vehicle_fwekf_skip_filterpy:
        t_end = int(seoul.tables["imu"].column("t_ns")[0].as_py()) + 120 * 10**9
        short = {}
        for k, tab in seoul.tables.items():
            t = np.asarray(tab.column("t_ns").to_numpy())
            short[k] = tab.filter(pa.array(t < t_end))
        ours = timed(ins(short, "fwekf", "numba"), 3).seconds
        ref = timed(ins(short, "fwekf", "filterpy")).seconds
        rows.append(["fwekf (120 s)", 120.0, ours, ref, ref / ours, 120.0 / ours])
    print_table(["filter", "drive s", "numba s", "filterpy s", "ratio", "x real time"], rows)
