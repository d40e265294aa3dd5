"""The NHC measurements of paper 001's comparison: how far the truth breaks the constraint, over
how long, and what that is worth as the white noise the filter assumes (issue 26)."""

from __future__ import annotations

import math

import numpy as np
import pyarrow as pa
import pytest

from navreplay.pipeline.outages import paper
from navreplay.pipeline.synth.trajectory import Body, Leg, Limits, build_profiles, sample


def test_the_correlation_time_of_white_and_of_gauss_markov_sequences() -> None:
    rng = np.random.default_rng(4)
    dt = 0.01
    white = rng.standard_normal(200_000)
    assert paper.correlation_time_s(white, dt) == pytest.approx(dt / 2, abs=0.5 * dt)
    tau = 2.0
    phi = math.exp(-dt / tau)
    gm = np.empty(400_000)
    gm[0] = 0.0
    drive = rng.standard_normal(gm.size) * math.sqrt(1 - phi * phi)
    for k in range(1, gm.size):  # a first-order Gauss-Markov sequence, time constant tau
        gm[k] = phi * gm[k - 1] + drive[k]
    assert paper.correlation_time_s(gm, dt) == pytest.approx(tau, rel=0.15)
    assert paper.correlation_time_s(np.zeros(10), dt) == 0.0
    # 0.05 m/s correlated over 12 s, as white noise at 10 Hz: 0.05 sqrt(241)
    assert paper.white_equivalent(0.05, 12.0, 10.0) == pytest.approx(0.05 * math.sqrt(241.0))


def _truth(body: Body) -> pa.Table:
    legs = [
        Leg("straight", speed_mps=10.0, duration_s=10.0),
        Leg("turn", speed_mps=8.0, angle_deg=90.0, radius_m=25.0),
        Leg("straight", speed_mps=12.0, duration_s=8.0),
        Leg("turn", speed_mps=8.0, angle_deg=-120.0, radius_m=20.0),
    ]
    limits = Limits(accel_mps2=1.5, yaw_accel_radps2=0.3, grade_rate_ps=0.05)
    prof = build_profiles(legs, 5.0, 240.0, limits)
    mo = sample(prof, rate_hz=50, duration_s=240.0, lat0_rad=0.65, lon0_rad=2.2, h0_m=60.0,
                yaw0_rad=0.3, body=body)  # fmt: skip
    cols: dict[str, np.ndarray] = {"t_ns": np.arange(mo.t_s.size, dtype=np.int64) * 20_000_000}
    for i, a in enumerate("ned"):
        cols[f"vel_{a}_mps"] = mo.vel_ned_mps[:, i]
    for i, a in enumerate(("roll", "pitch", "yaw")):
        cols[f"{a}_rad"] = mo.rpy_rad[:, i]
    return pa.table(cols)


def _note(truth: pa.Table) -> str:
    cmp = paper.compare([], {}, 60.0, imu_noise=None, nhc_sigma_mps=(0.1, 0.1), truth=truth,
                        nhc_rate_hz=10.0)  # fmt: skip
    return paper.markdown(cmp, "drive")


def test_the_note_says_when_the_nhc_noise_is_too_small_for_a_car_that_slips() -> None:
    """A car that slips in its turns breaks the constraint by 0.1 m/s for seconds at a time:
    the note measures the correlation and says the filter's white 0.1 m/s at 10 Hz is too
    small. The idealised car obeys it exactly, and the note says that instead."""
    slipping = paper.nhc_validity(_truth(Body(sideslip_per_lat_acc=0.009, road_rms_m=0.01)))
    assert 0.03 < slipping["lateral_rms_mps"] < 0.3
    assert slipping["lateral_corr_s"] > 1.0  # a turn lasts seconds
    assert slipping["vertical_corr_s"] < slipping["lateral_corr_s"]
    note = _note(_truth(Body(sideslip_per_lat_acc=0.009, road_rms_m=0.01)))
    lat = paper.white_equivalent(slipping["lateral_rms_mps"], slipping["lateral_corr_s"], 10.0)
    assert f"worth {lat:.2f} and" in note
    assert "x too small" in note
    ideal = _note(_truth(Body()))
    assert "far more closely than the filter assumes" in ideal
    assert "NHC noise:" not in ideal
