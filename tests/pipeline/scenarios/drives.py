"""seoul_campus drives for the scenario and outage tests (the synthesizer of params.yaml).

``drive`` runs ``pipeline.synth.seoul_campus.simulate`` with the repository's settings,
shortened to ``duration_s`` and with 10 s at rest first (alignment); its ``gnss_obs`` carries
the elevation and azimuth the selection policies need.
"""

from __future__ import annotations

from dataclasses import replace
from functools import lru_cache
from pathlib import Path

import pyarrow as pa

from navreplay.ingest.meta import SensorMeta
from navreplay.pipeline.params import Params, load_params
from navreplay.pipeline.synth.seoul_campus import simulate

REPO = Path(__file__).resolve().parents[3]
Tables = dict[str, pa.Table]


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
