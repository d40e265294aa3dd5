"""The switching-speed calibration rule of vehicle_switched (paper 003) on synthetic tables."""

from __future__ import annotations

import itertools
from typing import Any

import pytest

from navreplay.ingest.typed import FieldError
from navreplay.pipeline.experiments.vehicle_bands_config import VehicleBandsParams
from navreplay.pipeline.experiments.vehicle_switch_speed import (
    calibration_seeds,
    dynamic_vs_kinematic,
    note,
    switch_speeds,
)

EDGES = (1.5, 2.0, 2.5, 3.0, 10.0)


def _rows(dyn_minus_kin: dict[tuple[str, float], float]) -> list[dict[str, Any]]:
    """Five seeds; kinematic 0.20 m everywhere, dynamic 0.20 + the given offset +- 1 mm."""
    rows = []
    for s, noise in enumerate((0.001, -0.001, 0.0005, -0.0005, 0.0)):
        for scen in ("nominal", "outages"):
            for lo, hi in itertools.pairwise(EDGES):
                d = dyn_minus_kin.get((scen, lo), -0.05)
                for f, v in (("vehicle_kinematic", 0.20), ("vehicle_dynamic", 0.20 + d + noise)):
                    rows.append({"seed": s, "scenario": scen, "band_lo_mps": lo,
                                 "band_hi_mps": hi, "filter": f, "pos_h_rms_m": v})  # fmt: skip
    return rows


def test_switch_is_the_lowest_edge_above_every_band_where_the_dynamic_model_is_worse() -> None:
    # dynamic 3 cm worse at 1.5-2 m/s nominal and 2-2.5 m/s with outages; 5 mm worse at
    # 2.5-3 m/s nominal, within the 10 mm margin (5 % of 0.2 m)
    table = dynamic_vs_kinematic(
        _rows({("nominal", 1.5): 0.03, ("outages", 2.0): 0.03, ("nominal", 2.5): 0.005}),
        0.95,
        0.05,
    )
    ok = {(r["scenario"], r["band_lo_mps"]): r["dynamic_ok"] for r in table}
    assert not ok[("nominal", 1.5)]
    assert not ok[("outages", 2.0)]
    assert ok[("nominal", 2.5)]
    assert ok[("outages", 3.0)]
    assert switch_speeds(table) == (2.5, 2.0)
    assert "**2.5 m/s**" in note(table, 2.5, 2.0)


def test_a_worse_band_high_up_moves_the_switch_above_it() -> None:
    table = dynamic_vs_kinematic(_rows({("outages", 2.5): 0.03}), 0.95, 0.05)
    assert switch_speeds(table) == (3.0, 2.5)
    assert switch_speeds(table, hysteresis_mps=2.0) == (3.0, 1.5)  # at least half
    with pytest.raises(ValueError, match="no switching needed"):
        switch_speeds(dynamic_vs_kinematic(_rows({}), 0.95, 0.05))
    with pytest.raises(ValueError, match="highest band"):
        switch_speeds(dynamic_vs_kinematic(_rows({("nominal", 3.0): 0.03}), 0.95, 0.05))


def test_calibration_seeds_are_disjoint_from_the_acceptance_seeds() -> None:
    exp = VehicleBandsParams(seeds=60, calibration_seeds=20, calibration_seed_offset=1000)
    cal = calibration_seeds(7, exp)
    assert cal == list(range(1007, 1027))
    assert not set(cal) & {7 + i for i in range(exp.seeds)}
    with pytest.raises(FieldError):
        VehicleBandsParams(seeds=60, calibration_seed_offset=50)
