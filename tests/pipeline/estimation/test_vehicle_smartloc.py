"""The vehicle-model filters on the real smartLoc drive (Berlin), ingested in place."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest

from navreplay.ingest.api import ingest
from navreplay.ingest.schema import TableName
from navreplay.ingest.tables import read_table
from navreplay.pipeline.experiments.vehicle_smartloc import smartloc_rows, spp_fixes
from navreplay.pipeline.params import load_params

REPO = Path(__file__).resolve().parents[3]
DATA = REPO.parent / "shared" / "data" / "smartloc_berlin_potsdamer_platz"


@pytest.fixture(scope="module")
def smartloc(tmp_path_factory: pytest.TempPathFactory) -> dict[str, pa.Table]:
    """The Berlin run through the libRSF reader: gnss_obs, vehicle (no steering), truth."""
    logs = [DATA / "Berlin_Potsdamer_Platz_Input.txt", DATA / "Berlin_Potsdamer_Platz_GT.txt"]
    if not all(p.is_file() for p in logs):
        pytest.skip(f"smartLoc data not found at {DATA} (shared/data is read in place)")
    out = tmp_path_factory.mktemp("smartloc") / "tables"
    ingest(logs, out)
    names = (TableName.GNSS_OBS, TableName.VEHICLE, TableName.TRUTH)
    return {n.value: read_table(out / f"{n.value}.parquet", n).table for n in names}


def test_least_squares_fixes_cover_every_epoch_with_two_clocks(
    smartloc: dict[str, pa.Table],
) -> None:
    fixes = spp_fixes(smartloc["gnss_obs"])
    assert fixes.num_rows > 0.95 * 1372
    assert np.all(np.asarray(fixes.column("num_sats").to_numpy()) >= 6)


def test_vehicle_filters_beat_the_least_squares_fixes_on_the_smartloc_drive(
    smartloc: dict[str, pa.Table],
) -> None:
    filters = load_params(REPO / "params.yaml").filters
    rows = smartloc_rows(smartloc, filters)
    overall = {
        (r["scenario"], r["filter"], r["subset"]): r["pos_h_rms_m"]
        for r in rows
        if r["band_hi_mps"] == float("inf")
    }
    spp = overall[("spp_fixes", "least_squares", "all")]
    assert 20.0 < spp < 50.0  # urban canyon: reflected signals dominate the fixes
    for name in ("vehicle_kinematic", "vehicle_dynamic", "vehicle_switched", "vehicle_imm"):
        assert overall[("nominal", name, "all")] < 0.85 * spp
        assert overall[("outages", name, "all")] < spp
