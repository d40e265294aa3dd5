"""The data barrier in front of the filters and the stop schedule of the replay loop."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from navreplay.ingest.meta import SensorMeta
from navreplay.ingest.schema import from_columns
from navreplay.pipeline.estimation.ins import inputs as inp
from navreplay.pipeline.estimation.ins.config import GnssNoiseParams, StepParams
from navreplay.pipeline.estimation.ins.models import measurement as me
from navreplay.pipeline.estimation.ins.replay import resolve_imu_noise
from tests.pipeline.scenarios.drives import params


def test_clean_imu_counts_and_drops_what_must_not_reach_a_filter() -> None:
    t = np.array([0, 10, 10, 20, 15, 30, 40, 2040, 2050, 9000, 9010], dtype=np.int64) * 1_000_000
    data = np.ones((t.size, 6))
    data[6, 2] = math.nan
    out = inp.clean_imu(t, data, StepParams())
    kinds = [e.kind for e in out.events]
    assert kinds.count("imu_duplicate") == 1
    assert kinds.count("imu_backwards") == 1
    assert kinds.count("imu_invalid") == 1
    assert np.all(np.diff(out.t_ns) > 0)
    assert np.isfinite(out.data).all()
    gaps = [e for e in out.events if e.kind == "imu_gap"]
    assert [round(e.value, 3) for e in gaps] == [2.01, 6.95]  # the 40 ms step is no gap
    # 6.95 s exceeds imu_gap_max_s = 5: a new segment (re-alignment), 2.01 s is bridged
    assert [e.kind for e in out.events].count("segment_break") == 1
    assert out.segments == ((0, 6), (6, 8))


def test_fix_blocks_follow_fix_type_and_null_versus_nan() -> None:
    n = 4
    table = from_columns(
        "gnss",
        {
            "t_ns": np.arange(n, dtype=np.int64) * 1_000_000_000,
            "lat_deg": [37.0, 37.0, math.nan, 37.0],
            "lon_deg": [127.0] * n,
            "alt_m": [50.0] * n,
            "vel_n_mps": [1.0, 1.0, 1.0, 1.0],
            "vel_e_mps": [0.0, 0.0, 0.0, math.nan],
            "h_acc_m": [None, 0.1, 2.0, 2.0],
            "v_acc_m": [None, 0.1, 3.0, 3.0],
            "fix_type": [3, 2, 3, 1],
            "num_sats": [8, 5, 8, 0],
        },
    )
    fixes = inp.prepare_fixes(table, GnssNoiseParams())
    f = fixes.fix
    assert f[:, me.FX_POS_DIM].tolist() == [3, 2, 0, 0]  # 3-D, 2-D fix, NaN lat, no fix
    assert f[:, me.FX_VEL_DIM].tolist() == [2, 2, 2, 0]  # no vel_d given: horizontal only
    assert f[0, me.FX_SIG_H] == GnssNoiseParams().pos_sigma_default_m  # null accuracy
    assert f[1, me.FX_SIG_H] == GnssNoiseParams().pos_sigma_floor_m  # floored (F8)
    assert [(e.kind, e.stream) for e in fixes.events] == [
        ("skip_no_fix", "gnss_pos"),
        ("skip_invalid", "gnss_pos"),
    ]
    assert np.isfinite(f).all()


def test_obs_are_corrected_masked_and_grouped_by_epoch() -> None:
    table = from_columns(
        "gnss_obs",
        {
            "t_ns": np.array([0, 0, 0, 1, 1], dtype=np.int64) * 1_000_000_000,
            "sv": ["G01", "G02", "G03", "G01", "G02"],
            "pseudorange_m": [2.0e7, 2.1e7, 2.2e7, 2.0e7, math.nan],
            "pseudorange_rate_mps": [10.0, None, 30.0, 11.0, 21.0],
            "sat_x_m": [1.0e7] * 5,
            "sat_y_m": [1.0e7] * 5,
            "sat_z_m": [1.0e7] * 5,
            "sat_vx_mps": [1.0] * 5,
            "sat_vy_mps": [1.0] * 5,
            "sat_vz_mps": [1.0] * 5,
            "sat_clock_m": [5.0, None, 0.0, 5.0, 0.0],
            "elevation_deg": [45.0, 30.0, 5.0, 45.0, 30.0],
            "iono_delay_m": [2.0, 2.0, 2.0, 2.0, 2.0],
        },
    )
    obs = inp.prepare_obs(table, GnssNoiseParams())
    assert obs.epoch_t_ns.tolist() == [0, 1_000_000_000]
    assert obs.start.tolist() == [0, 2, 4]  # G03 below the 10 deg mask is dropped
    assert obs.masked == 1
    assert obs.obs[0, me.OB_PR] == pytest.approx(2.0e7 + 5.0 - 2.0)
    assert obs.obs[1, me.OB_PRR_OK] == 0.0  # rate not provided: no rate row, no event
    assert obs.obs[3, me.OB_PR_OK] == 0.0  # NaN pseudorange: skipped ...
    assert obs.obs[3, me.OB_PRR_OK] == 1.0  # ... but its rate is used
    assert [(e.kind, e.sv) for e in obs.events] == [("skip_invalid", "G02")]


def test_schedule_merges_grid_updates_and_nhc_slots() -> None:
    s = 1_000_000_000
    fix_t = np.array([1, 2, 3], dtype=np.int64) * s + 30_000_000  # fixes 30 ms off the grid
    stops = inp.build_schedule(0, 3 * s, 0.5, fix_t, None, nhc_rate_hz=1.0)
    t = stops[:, me.ST_T]
    assert np.all(np.diff(t) > 0)
    assert t.tolist() == [s // 2, s, 1_030_000_000, 3 * s // 2, 2 * s, 2_030_000_000, 5 * s // 2,
                          3 * s]  # fmt: skip
    assert stops[:, me.ST_FIX].tolist() == [-1, -1, 0, -1, -1, 1, -1, -1]  # 3.03 s > t_end
    assert stops[:, me.ST_OUT].tolist() == [1, 1, 0, 1, 1, 0, 1, 1]
    # NHC slots at 1, 2, 3 s: stacked onto the fixes within half a period, else alone
    assert stops[:, me.ST_NHC].tolist() == [0, 0, 1, 0, 0, 1, 0, 1]


@pytest.mark.parametrize("rate_hz", [25.0, 100.0])
def test_imu_white_noise_recovers_the_density_under_motion(rate_hz: float) -> None:
    """White noise of known density on a smooth manoeuvre (a 0.2 Hz swerve of 3 m/s^2 and
    0.3 rad/s) is recovered at a decimated and at a full rate: never below it by more than
    the sampling error, and above it by at most 20 % (the manoeuvre's own sample-to-sample
    change, largest for the gyro at 25 Hz): an upper estimate, as a floor should be."""
    rng = np.random.default_rng(5)
    dt = 1.0 / rate_hz
    t = np.arange(0.0, 120.0, dt)
    acc_psd, gyro_psd = 0.05, 0.004  # m/s^2/rtHz, rad/s/rtHz
    data = np.empty((t.size, 6))
    data[:, :3] = 3.0 * np.sin(2 * np.pi * 0.2 * t)[:, None]
    data[:, 3:] = 0.3 * np.cos(2 * np.pi * 0.2 * t)[:, None]
    data[:, :3] += rng.normal(0.0, acc_psd / math.sqrt(dt), (t.size, 3))
    data[:, 3:] += rng.normal(0.0, gyro_psd / math.sqrt(dt), (t.size, 3))
    imu = inp.ImuData((t * 1e9).astype(np.int64), data, ((0, t.size),))
    acc, gyro = inp.imu_white_noise(imu)
    assert 0.95 * acc_psd < acc < 1.2 * acc_psd
    assert 0.95 * gyro_psd < gyro < 1.2 * gyro_psd


def test_imu_noise_floor_applies_only_without_a_dataset_model() -> None:
    p = params().filters.get("lc_ekf")
    rng = np.random.default_rng(1)
    t = np.arange(0, 2000, dtype=np.int64) * 10_000_000
    quiet = inp.ImuData(t, rng.normal(0.0, 1e-5, (t.size, 6)), ((0, t.size),))
    noisy = inp.ImuData(t, rng.normal(0.0, 1.0, (t.size, 6)), ((0, t.size),))
    assert resolve_imu_noise(p, None, quiet) == (p.imu_noise, "params")
    floored, source = resolve_imu_noise(p, None, noisy)
    assert source == "params, floored by the log"
    assert floored.accel_noise_mps2_rthz == pytest.approx(0.1, rel=0.1)  # 1 m/s^2 at 100 Hz
    assert floored.accel_bias_sigma_mps2 == p.imu_noise.accel_bias_sigma_mps2
    declared = replace(p.imu_noise, accel_noise_mps2_rthz=0.001)
    sensors = SensorMeta(imu_noise=declared)
    assert resolve_imu_noise(p, sensors, noisy) == (declared, "dataset")


def test_gating_uses_the_marginal_variance_of_an_inflated_fix() -> None:
    """A fix whose variance was inflated for error correlation is updated with the inflated
    variance but gated against the receiver's own (F7)."""
    n = 3
    table = from_columns(
        "gnss",
        {
            "t_ns": np.arange(n, dtype=np.int64) * 1_000_000_000,
            "lat_deg": [37.0] * n, "lon_deg": [127.0] * n, "alt_m": [50.0] * n,
            "h_acc_m": [1.5] * n, "v_acc_m": [2.0] * n, "fix_type": [3] * n,
        },
    )  # fmt: skip
    fixes = inp.prepare_fixes(table, GnssNoiseParams(pos_error_corr_time_s=30.0))
    phi = math.exp(-1.0 / 30.0)  # Gauss-Markov over 30 s sampled at 1 Hz: ~1 + 2 tau / dt
    infl = (1.0 + phi) / (1.0 - phi)
    assert fixes.noise is not None
    assert fixes.noise.source == "configured"
    assert fixes.fix[0, me.FX_SIG_H] == pytest.approx(1.5 * math.sqrt(infl))
    assert fixes.fix[0, me.FX_POS_INFL] == pytest.approx(infl)
    rows = np.array([[me.K_POS, 0], [me.K_POS + 2, 0], [me.K_VEL, 0]], dtype=np.int64)
    r = np.array([fixes.fix[0, me.FX_SIG_H] ** 2, fixes.fix[0, me.FX_SIG_V] ** 2, 0.04])
    dr = np.empty(3)
    me.gate_shift(rows, 3, fixes.fix, r, dr)
    np.testing.assert_allclose(r + dr, [1.5**2, 2.0**2, 0.04])
    white = inp.prepare_fixes(table, GnssNoiseParams(pos_error_corr_time_s=0.0))
    me.gate_shift(rows, 3, white.fix, r, dr)
    np.testing.assert_array_equal(dr, 0.0)
