"""seoul_campus drives for the scenario and outage tests (the synthesizer of params.yaml).

``drive`` runs ``pipeline.synth.seoul_campus.simulate`` with the repository's settings,
shortened to ``duration_s`` and with 10 s at rest first (alignment); its ``gnss_obs`` carries
the elevation and azimuth the selection policies need.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from functools import lru_cache
from pathlib import Path
from typing import Any

import pyarrow as pa

from navreplay.ingest.meta import DatasetMeta, SensorMeta, write_meta
from navreplay.ingest.tables import Provenance, write_table
from navreplay.pipeline.estimation.core.windows import NS
from navreplay.pipeline.outages.montecarlo import Case, Start, run_montecarlo
from navreplay.pipeline.params import Params, load_params
from navreplay.pipeline.scenarios.config import Policy
from navreplay.pipeline.synth.seoul_campus import simulate

REPO = Path(__file__).resolve().parents[3]
Tables = dict[str, pa.Table]

#: outage windows of 10 s that fit a drive of a minute or more (params.yaml's need >= 210 s)
SHORT_WINDOWS = {
    "placement": "random",
    "length_s": 10.0,
    "count": 2,
    "seed": 1,
    "earliest_s": 15.0,
    "min_gap_s": 10.0,
    "tail_s": 5.0,
}


def write_tables(
    out: Path, tables: Tables, dataset: str, sensors: SensorMeta, time_base: str = "gps"
) -> Path:
    """``tables`` as a dataset's tables directory ``out`` (canonical Parquet and meta.json)."""
    for name, table in tables.items():
        write_table(out / f"{name}.parquet", name, table, Provenance.create(name))
    rows = {name: t.num_rows for name, t in tables.items()}
    write_meta(out, DatasetMeta(dataset, time_base, (), rows, sensors=sensors))
    return out


def short_window_scenarios(data: dict[str, Any]) -> dict[str, Any]:
    """params.yaml data (edited in place and returned) whose windowed scenarios use
    ``SHORT_WINDOWS``."""
    named = data["scenarios"]["named"]
    for name, spec in named.items():
        if "windows" in spec:
            named[name] = dict(spec, windows=SHORT_WINDOWS)
    return data


@lru_cache(maxsize=1)
def params() -> Params:
    """The repository's params.yaml."""
    return load_params(REPO / "params.yaml")


@lru_cache(maxsize=4)
def drive(duration_s: float = 60.0, seed: int = 7) -> tuple[Tables, SensorMeta]:
    """A seoul_campus drive (cw lap) of ``duration_s``: 10 s at rest, then driving."""
    sp = replace(params().synth.seoul_campus, duration_s=duration_s, stationary_s=10.0)
    result = simulate(sp, seed=seed, variant="cw")
    return dict(result.tables), result.sensors


def montecarlo_rows(
    name: str,
    duration_s: float,
    starts_s: Sequence[float],
    cases: Sequence[Case],
    *,
    tail_s: float,
    policy: Policy = "highest_elevation",
    mask_deg: float | None = None,
    workers: int = 1,
    **engine: Any,
) -> list[dict[str, Any]]:
    """The Monte Carlo rows of filter ``name`` on ``drive(duration_s)``: windows (seed 1,
    numbered in order) at ``starts_s`` seconds after the first IMU sample, each under every
    case; ``mask_deg`` defaults to params.yaml's selection mask; ``engine``: where the starts
    run (``run_montecarlo``'s ``scheduler``, ``compute``, ``progress``)."""
    tables, sensors = drive(duration_s)
    t0 = int(tables["imu"].column("t_ns")[0].as_py())
    rows, _, failed = run_montecarlo(
        tables,
        sensors,
        sensors.lever_arm_m,
        name,
        params().filters.get(name),
        [Start(1, i, t0 + round(s * NS)) for i, s in enumerate(starts_s)],
        list(cases),
        policy=policy,
        tail_s=tail_s,
        mask_deg=params().scenarios.selection_mask_deg if mask_deg is None else mask_deg,
        metrics=params().scenarios.metrics,
        workers=workers,
        **engine,
    )
    assert not failed, [f.error for f in failed]
    return rows
