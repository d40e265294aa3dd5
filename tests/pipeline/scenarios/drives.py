"""seoul_campus-type drives for the scenario and outage tests, with a full sky.

``tests.pipeline.estimation.drive.simulate`` gives every canonical table but no satellite
azimuth; the selection policies need it, so ``drive`` adds ``elevation_deg`` and
``azimuth_deg`` computed from the satellite positions and the true receiver position.
"""

from __future__ import annotations

import math
from functools import lru_cache
from pathlib import Path

import numpy as np
import pyarrow as pa

from ingest.meta import SensorMeta
from pipeline.nav import earth
from pipeline.params import Params, load_params
from pipeline.scenarios.faults import column, with_values
from tests.pipeline.estimation.drive import DriveSpec, simulate

REPO = Path(__file__).resolve().parents[3]
Tables = dict[str, pa.Table]


@lru_cache(maxsize=1)
def params() -> Params:
    """The repository's params.yaml."""
    return load_params(REPO / "params.yaml")


def with_sky(tables: Tables) -> Tables:
    """``gnss_obs`` with elevation and azimuth from the satellite and true receiver positions."""
    obs, truth = tables["gnss_obs"], tables["truth"]
    t_obs = obs.column("t_ns").to_numpy()
    t_tr = truth.column("t_ns").to_numpy()
    k = np.searchsorted(t_tr, t_obs)
    lat = np.radians(truth.column("lat_deg").to_numpy()[k])
    lon = np.radians(truth.column("lon_deg").to_numpy()[k])
    h = truth.column("alt_m").to_numpy()[k]
    sat = np.column_stack([column(obs, f"sat_{a}_m") for a in "xyz"])
    el, az = np.empty(obs.num_rows), np.empty(obs.num_rows)
    for i in range(obs.num_rows):
        d = sat[i] - earth.geodetic_to_ecef(lat[i], lon[i], h[i])
        n, e, dn = earth.dcm_ecef_to_ned(lat[i], lon[i]) @ (d / np.linalg.norm(d))
        el[i] = math.degrees(math.asin(-dn))
        az[i] = math.degrees(math.atan2(e, n)) % 360.0
    out = with_values(obs, "elevation_deg", el, keep_nulls=False)
    return dict(tables, gnss_obs=with_values(out, "azimuth_deg", az, keep_nulls=False))


@lru_cache(maxsize=4)
def drive(duration_s: float = 60.0, seed: int = 7) -> tuple[Tables, SensorMeta]:
    """A seoul_campus-type drive (static start, turns both ways, 8 satellites), with sky."""
    tables, sensors = simulate(DriveSpec(duration_s=duration_s), seed=seed)
    return with_sky(tables), sensors
