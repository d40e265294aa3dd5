"""The tractor simulator of paper 000: plant eq. 1-4, sensors of Table 2, closed loop."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from navreplay.pipeline.control.lqr import YawSteerModel, lqr_command, tractor_lqr_gain
from navreplay.pipeline.params import load_params
from navreplay.pipeline.synth import tractor_log
from navreplay.pipeline.synth.output import dataset_seed
from navreplay.pipeline.synth.tractor import (
    TractorMeasurement,
    TractorSim,
    TractorState,
    TractorStraightParams,
)

REPO = Path(__file__).resolve().parents[3]
PAPER = TractorStraightParams()
M = YawSteerModel()


def at_rest(steer_rad: float = 0.0) -> TractorState:
    return TractorState(0.0, 0.0, 0.0, PAPER.speed_mps, 0.0, 0.0, 0.0, steer_rad, 0.0)


def test_params_yaml_holds_the_papers_scenario() -> None:
    assert load_params(REPO / "params.yaml").synth.tractor_straight == PAPER
    assert (PAPER.rate_hz, PAPER.duration_s, PAPER.speed_mps, PAPER.steps) == (50, 80.0, 3.0, 4000)


def test_steering_valve_step_is_the_first_order_response_of_eq_4() -> None:
    sim, u = TractorSim(PAPER, 1), 0.2
    tau, kv = M.tau_v_s, M.k_v
    for _ in range(100):
        sim.step(u)
        t = sim.t_s
        x = sim.truth
        assert x.steer_rate_radps == pytest.approx(kv * u * (1 - math.exp(-t / tau)), abs=1e-14)
        expected = kv * u * (t - tau * (1 - math.exp(-t / tau)))
        assert x.steer_rad == pytest.approx(expected, abs=1e-14)


def test_yaw_rate_step_is_the_second_order_response_of_eq_3() -> None:
    delta = 0.1
    sim = TractorSim(PAPER, 1, initial=at_rest(delta))
    zeta, wn, kr = M.zeta, M.omega_n_radps, M.k_r
    wd = wn * math.sqrt(1 - zeta**2)
    for _ in range(150):
        sim.step(0.0)
        t = sim.t_s
        decay = math.exp(-zeta * wn * t)
        r = (
            kr
            * delta
            * (1 - decay * (math.cos(wd * t) + zeta / math.sqrt(1 - zeta**2) * math.sin(wd * t)))
        )
        r_dot = kr * delta * decay * wn / math.sqrt(1 - zeta**2) * math.sin(wd * t)
        assert sim.truth.yaw_rate_radps == pytest.approx(r, abs=1e-13)
        assert sim.truth.yaw_accel_radps2 == pytest.approx(r_dot, abs=1e-12)
        assert sim.truth.steer_rad == delta
    # steady state: yaw rate = K_R delta (a constant steer angle turns at a constant rate)
    assert sim.truth.yaw_rate_radps == pytest.approx(kr * delta, rel=1e-3)


def paper_ode(_t: float, x: np.ndarray, u: float, v: float) -> list[float]:
    """Eq. 1-4 written out plainly: x = [E, N, psi, psi_dot, psi_ddot, delta, delta_dot]."""
    _e, _n, psi, r, r_dot, d, d_dot = x
    wn, z = M.omega_n_radps, M.zeta
    return [
        v * math.sin(psi),
        v * math.cos(psi),
        r,
        r_dot,
        -2 * z * wn * r_dot - wn**2 * r + M.k_r * wn**2 * d,
        d_dot,
        -d_dot / M.tau_v_s + M.k_v / M.tau_v_s * u,
    ]


def test_plant_matches_an_independent_integration_of_eq_1_to_4() -> None:
    rng = np.random.default_rng(7)
    commands = rng.uniform(-2.0, 2.0, 150)  # 3 s of wild steering, held per sample
    sim = TractorSim(PAPER, 1)
    x = np.zeros(7)
    for u in commands:
        sol = solve_ivp(
            paper_ode, (0.0, PAPER.dt_s), x, args=(u, PAPER.speed_mps), rtol=1e-12, atol=1e-13
        )
        x = sol.y[:, -1]
        sim.step(u)
        t = sim.truth
        got = [t.east_m, t.north_m, t.heading_rad, t.yaw_rate_radps, t.yaw_accel_radps2]
        got += [t.steer_rad, t.steer_rate_radps]
        np.testing.assert_allclose(got, x, atol=1e-9)
    assert abs(x[2]) > 0.05  # the heading really moved, so eq. 1-2 were exercised


def test_measurements_carry_the_configured_biases_and_table_2_noise() -> None:
    sim = TractorSim(PAPER, 11)
    n = 20_000
    rows = np.empty((n, 6))
    for i in range(n):
        z = sim.step(0.0)
        x = sim.truth
        rows[i] = (
            z.east_m - x.east_m,
            z.north_m - x.north_m,
            z.heading_rad - x.heading_rad,
            z.yaw_rate_radps - x.yaw_rate_radps,
            z.steer_rad - x.steer_rad,
            z.speed_mps - x.speed_mps,
        )
    b, v = PAPER.biases, PAPER.noise
    bias = np.array([0.0, 0.0, b.heading_rad, b.gyro_radps, b.steer_rad, b.radar_mps])
    var = np.array(
        [v.east_m2, v.north_m2, v.heading_rad2, v.yaw_rate_rad2ps2, v.steer_rad2, v.speed_m2ps2]
    )
    # mean within 4 standard errors; variance within 4 sigma of its chi-square spread
    assert np.all(np.abs(rows.mean(axis=0) - bias) < 4 * np.sqrt(var / n))
    assert np.all(np.abs(rows.var(axis=0) / var - 1.0) < 4 * math.sqrt(2.0 / n))
    # sensors are independent
    corr = np.corrcoef(rows.T) - np.eye(6)
    assert np.abs(corr).max() < 4 / math.sqrt(n)


def test_gps_outage_windows_and_per_step_override_leave_the_other_noise_paired() -> None:
    nominal = TractorSim(PAPER, 5)
    outage = TractorSim(PAPER, 5, gps_outages_s=[(0.1, 0.2)])
    seen: list[tuple[TractorMeasurement, TractorMeasurement]] = []
    for k in range(20):
        a = nominal.step(0.3)
        b = outage.step(0.3, gps=False if k == 15 else None)
        seen.append((a, b))
    for k, (a, b) in enumerate(seen):
        t = (k + 1) / PAPER.rate_hz
        off = 0.1 <= t < 0.2 or k == 15
        assert b.gps_valid is not off
        assert a.gps_valid
        if off:
            assert math.isnan(b.east_m)
            assert math.isnan(b.north_m)
            assert math.isnan(b.heading_rad)
        else:
            assert (b.east_m, b.north_m, b.heading_rad) == (a.east_m, a.north_m, a.heading_rad)
        assert (b.yaw_rate_radps, b.steer_rad, b.speed_mps) == (
            a.yaw_rate_radps,
            a.steer_rad,
            a.speed_mps,
        )
    with pytest.raises(ValueError, match="end > start"):
        TractorSim(PAPER, 5, gps_outages_s=[(3.0, 2.0)])
    with pytest.raises(ValueError, match="non-finite"):
        nominal.step(math.nan)


def test_stepping_by_hand_reproduces_the_recording_with_the_same_seed() -> None:
    params = TractorStraightParams(duration_s=4.0)
    rec = tractor_log.record(params, seed=3)
    sim = TractorSim(params, dataset_seed(3, tractor_log.DATASET))
    gain = tractor_lqr_gain(params.speed_mps, params.dt_s)
    line = params.line()
    for k in range(params.steps + 1):
        x, z = sim.truth, sim.measurement
        assert (x.east_m, x.heading_rad, x.steer_rate_radps) == (
            rec["east_m"][k],
            rec["heading_rad"][k],
            rec["steer_rate_radps"][k],
        )
        assert (z.east_m, z.yaw_rate_radps, z.speed_mps) == (
            rec["meas_east_m"][k],
            rec["meas_yaw_rate_radps"][k],
            rec["meas_speed_mps"][k],
        )
        u = lqr_command(gain, line.control_state(*x[1:3], *x[4:]))
        assert u == rec["u"][k]
        sim.step(u)


def test_the_true_state_lqr_brings_the_3_m_step_back_to_the_line() -> None:
    rec = tractor_log.record(PAPER, seed=1)
    t, east = rec["t_s"], rec["east_m"]
    assert east[0] == 0.0
    assert PAPER.line_east_m == 3.0
    settled = t >= 10.0
    assert np.abs(east[settled] - 3.0).max() < 1e-3
    assert np.abs(rec["heading_rad"][settled]).max() < 1e-3
    overshoot = east.max() - 3.0
    assert 0.0 <= overshoot < 0.2  # 0.11 m with the paper's gain
    # the north coordinate advances at about V_x once on the line
    assert rec["north_m"][-1] == pytest.approx(3.0 * 80.0, abs=2.0)
