"""RTS smoothing: memory and time of the backward pass for one hour of data.

Data: one hour of the seoul_campus drive (params.yaml's synthesizer: 100 Hz IMU, 1 Hz GNSS
fixes and observables), the filters' default 0.1 s covariance step (36,000 stops).

For each filter: the forward run without smoothing, the forward run recording for smoothing
(``records.SmoothLog``), and the backward pass (``kernels.smoother.smooth``), in CPU seconds
per hour, timed after a warm-up that compiles or loads the kernels. Memory: what the forward
pass kept for the backward pass (as allocated), against what a covariance per IMU step would
take (15 or 17 states, 360,000 steps: the store the issue rules out) and beside the forward
run's own output covariances (kept with or without smoothing). The reference: filterpy's
``rts_smoother`` doing every backward step on the same log
(``ins.reference_smoother.smooth_filterpy``), timed on the whole hour.

Targets (issue 25): what the backward pass needs <= 100 MB per hour; the backward pass <= 1x
the forward pass's time.
"""

from __future__ import annotations

import argparse
import resource
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

from benchmarks._options import Option
from benchmarks._table import print_table

FILTERS = ("lc_ekf", "lc_ekf_nhc", "tc_ekf", "tc_ukf")
TARGET_MB_PER_H = 100.0
TARGET_BACKWARD_RATIO = 1.0

OPTIONS = [
    Option("--smoother-hours", "hours of data (default 1)", float, 1.0),
]


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _data(hours: float) -> tuple[dict[str, Any], Any]:
    from navreplay.pipeline.params import load_params
    from navreplay.pipeline.synth.seoul_campus import simulate

    synth = load_params(Path("params.yaml")).synth
    sp = replace(synth.seoul_campus, duration_s=3600.0 * hours)
    result = simulate(sp, seed=synth.seed, variant="cw")
    return dict(result.tables), result.sensors


def _run(tables: dict[str, Any], sensors: Any, name: str, smooth: bool) -> tuple[float, Any]:
    """(forward CPU s without the backward pass and the compile, result) of one run."""
    from navreplay.pipeline.estimation.ins.replay import run_filter
    from navreplay.pipeline.params import load_params

    p = replace(load_params(Path("params.yaml")).filters.get(name), smooth=smooth)
    cpu = _cpu()
    res = run_filter(tables, sensors, name, p)
    cpu = _cpu() - cpu - res.compile_s
    if res.smoothing is not None:
        cpu -= res.smoothing.runtime_s  # single-threaded: wall ~ cpu
    return cpu, res


def _filterpy_backward(tables: dict[str, Any], sensors: Any, name: str) -> float:
    """CPU s of filterpy's ``rts_smoother`` over the smoothing log of the whole run."""
    from navreplay.pipeline.estimation.ins import replay
    from navreplay.pipeline.estimation.ins.reference_smoother import smooth_filterpy

    captured: list[tuple[Any, ...]] = []
    compiled = replay._backward

    def capture(backward: Any, sm: Any, out_x: Any, out_P: Any, cfg: Any) -> Any:
        captured.append((sm, out_x, out_P, cfg))
        return compiled(backward, sm, out_x, out_P, cfg)

    replay._backward = capture
    try:
        _run(tables, sensors, name, True)
    finally:
        replay._backward = compiled
    cpu = _cpu()
    for sm, out_x, out_P, cfg in captured:
        smooth_filterpy(sm, out_x, out_P, cfg, out_x.copy(), out_P.copy())
    return _cpu() - cpu


def run(options: argparse.Namespace) -> None:
    hours = options.smoother_hours
    t = time.perf_counter()
    tables, sensors = _data(hours)
    print(f"   data: {hours:g} h synthesized in {time.perf_counter() - t:.1f} s", flush=True)
    t0 = int(tables["imu"].column("t_ns")[0].as_py())
    import pyarrow as pa

    warm = {
        k: v.filter(pa.array(v.column("t_ns").to_numpy() <= t0 + int(90e9)))
        for k, v in tables.items()
    }
    for name in FILTERS:  # compile or load every kernel and the backward pass first
        _run(warm, sensors, name, True)
    rows: list[list[object]] = []
    for name in FILTERS:
        fwd, plain = _run(tables, sensors, name, False)
        fwd_sm, res = _run(tables, sensors, name, True)
        assert res.smoothing is not None, name
        assert res.smoothing.status == "ok", res.smoothing
        per_h = 3600.0 / res.duration_s
        back = res.smoothing.runtime_s * per_h
        ref = _filterpy_backward(tables, sensors, name) * per_h
        mem = res.smoothing.memory_bytes / 1e6 * per_h
        imu_steps = tables["imu"].num_rows * per_h
        per_step = imu_steps * res.n * res.n * 8 / 1e6
        rows.append([
            name, fwd * per_h, fwd_sm * per_h, back, back / (fwd * per_h), ref, ref / back,
            mem, per_step, plain.P.nbytes / 1e6 * per_h,
        ])  # fmt: skip
    print("   per hour of data; CPU s (backward: wall, single-threaded). forward = the run")
    print("   without smoothing, + record = the forward run keeping the smoothing log;")
    print("   backward / fwd is the issue's <= 1x; filterpy = rts_smoother doing each step")
    print("   on the same log; memory = the smoothing log as allocated, against a covariance")
    print("   per IMU step and beside the run's own output covariances")
    print_table(
        ["filter", "forward s", "+ record s", "backward s", "backward/fwd", "filterpy s",
         "filterpy/ours", "memory MB", "per-IMU-step MB", "outputs' P MB"],
        rows,
    )  # fmt: skip
    print(f"   targets: memory <= {TARGET_MB_PER_H:g} MB per hour, backward/fwd <= "
          f"{TARGET_BACKWARD_RATIO:g}")  # fmt: skip
