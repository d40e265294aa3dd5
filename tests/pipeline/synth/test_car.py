"""The car of paper 003: linear-tire bicycle model, speed ramp, sensors."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from navreplay.pipeline.nav.earth import OMEGA_IE
from navreplay.pipeline.params import load_params
from navreplay.pipeline.synth import SynthResult, car
from navreplay.pipeline.synth.bicycle import COLUMNS, VehicleParams, simulate

REPO = Path(__file__).resolve().parents[3]
PAPER = car.CarSpeedRampParams()
VP = VehicleParams()


def hold(speed_mps: float, steer_rad: float, seconds: float = 8.0) -> dict[str, float]:
    """Final state after holding speed and steering from straight running, 1 kHz RK4."""
    n = round(seconds * 1000)
    u = np.full(2 * n + 1, speed_mps)
    d = np.full(2 * n + 1, steer_rad)
    out = simulate(u, d, 1e-3, n, VP.as_tuple(), 0.0, math.radians(17.6), math.radians(78.5), 540.0)
    return dict(zip(COLUMNS, out[-1], strict=True))


def test_params_yaml_holds_the_default_drive() -> None:
    assert load_params(REPO / "params.yaml").synth.car_speed_ramp == PAPER
    assert VP.understeer_gradient_rad_per_mps2 == pytest.approx(3.75e-3)


@pytest.mark.parametrize("speed", [5.0, 15.0, 25.0, 35.0])
def test_steady_state_yaw_rate_matches_the_understeer_gradient_formula(speed: float) -> None:
    steer = 0.01
    end = hold(speed, steer)
    expected = speed * steer / (VP.wheelbase_m + VP.understeer_gradient_rad_per_mps2 * speed**2)
    assert end["r_radps"] == pytest.approx(expected, rel=2e-4)
    assert end["r_radps"] == pytest.approx(VP.steady_state_yaw_rate(speed, steer), rel=2e-4)
    # lateral acceleration of a steady turn is u r
    assert end["a_y_mps2"] == pytest.approx(speed * end["r_radps"], rel=1e-3)


def test_at_walking_pace_the_model_is_kinematic_even_for_large_steering() -> None:
    speed, steer = 1.5, 0.4
    end = hold(speed, steer)
    wheelbase = VP.wheelbase_m
    # 0.35 m/s^2 of lateral acceleration still needs 0.2 deg of tire slip: 0.6 % on the rate
    assert end["r_radps"] == pytest.approx(speed * math.tan(steer) / wheelbase, rel=1e-2)
    beta = math.atan2(end["v_y_mps"], speed)
    beta_kin = math.atan(VP.cg_to_rear_m * math.tan(steer) / wheelbase)
    assert beta == pytest.approx(beta_kin, abs=0.005)


def test_sideslip_departs_from_the_kinematic_value_as_speed_grows() -> None:
    wheelbase = VP.wheelbase_m
    gap = []
    for speed in (2.0, 10.0, 20.0, 30.0):
        steer = 0.02 * 10.0 / max(speed, 10.0)  # keep the lateral acceleration moderate
        end = hold(speed, steer)
        beta = math.atan2(end["v_y_mps"], speed)
        beta_kin = math.atan(VP.cg_to_rear_m * math.tan(steer) / wheelbase)
        r_kin = speed * math.tan(steer) / wheelbase
        gap.append((abs(beta - beta_kin), abs(end["r_radps"] - r_kin) / r_kin))
    slip_gap, rate_gap = zip(*gap, strict=True)
    assert list(rate_gap) == sorted(rate_gap)
    assert rate_gap[0] < 0.02
    assert rate_gap[-1] > 0.5
    assert list(slip_gap) == sorted(slip_gap)
    assert slip_gap[0] < 5e-4
    assert slip_gap[-1] > 0.008


@pytest.fixture(scope="module")
def drive() -> SynthResult:
    return car.synthesize(PAPER, seed=2)


def test_the_drive_ramps_from_walking_pace_to_highway_speed_through_curves(
    drive: SynthResult,
) -> None:
    truth = drive.tables["truth"]
    speed = truth["speed_mps"].to_numpy()
    assert speed[0] == pytest.approx(1.5)
    assert speed[-1] == pytest.approx(33.0, abs=0.1)
    assert truth.num_rows == 36_001
    assert drive.tables["gnss"].num_rows == 3601
    yaw_rate = truth["yaw_rate_radps"].to_numpy()
    accel = truth["lateral_accel_mps2"].to_numpy()
    slow, fast = speed < 3.0, speed > 30.0
    assert np.abs(yaw_rate[slow]).max() > 0.3  # tight turns at walking pace
    assert np.abs(accel[fast]).max() == pytest.approx(PAPER.max_lateral_accel_mps2, rel=0.05)
    slip = truth["slip_angle_rad"].to_numpy()
    steer = truth["steer_rad"].to_numpy()
    beta_kin = np.arctan(VP.cg_to_rear_m * np.tan(steer) / VP.wheelbase_m)
    rms = [
        float(np.sqrt(np.mean((slip - beta_kin)[band] ** 2)))
        for band in (speed < 3, (speed > 10) & (speed < 20), speed > 25)
    ]
    assert rms[0] < 0.006
    assert rms[1] > 0.015
    assert rms[2] > 0.015
    # course over ground (from the truth velocity) = yaw + slip
    course = np.arctan2(truth["vel_e_mps"].to_numpy(), truth["vel_n_mps"].to_numpy())
    err = (course - truth["yaw_rad"].to_numpy() - slip + math.pi) % (2 * math.pi) - math.pi
    assert np.abs(err).max() < 1e-9


def test_sensors_carry_the_configured_noise(drive: SynthResult) -> None:
    truth, veh, gnss = (drive.tables[k] for k in ("truth", "vehicle", "gnss"))
    s = PAPER.sensors
    lat = np.radians(truth["lat_deg"].to_numpy())
    earth = -OMEGA_IE * np.sin(lat)  # the transport-rate term is < 1e-6 rad/s here
    e_rate = veh["yaw_rate_radps"].to_numpy() - truth["yaw_rate_radps"].to_numpy() - earth
    e_speed = veh["speed_mps"].to_numpy() - truth["speed_mps"].to_numpy() * np.cos(
        truth["slip_angle_rad"].to_numpy()
    )
    e_steer = veh["steer_rad"].to_numpy() - truth["steer_rad"].to_numpy()
    n = e_rate.size
    tol = 4 * math.sqrt(0.5 / n) + 0.01  # chi-square spread plus the CSV rounding
    assert e_rate.std() == pytest.approx(s.yaw_rate_noise_radps, rel=tol)
    assert e_speed.std() == pytest.approx(s.wheel_speed_noise_mps, rel=tol)
    assert e_steer.std() == pytest.approx(s.steer_noise_rad, rel=tol + 0.02)
    assert abs(e_rate.mean()) < 4 * s.yaw_rate_noise_radps / math.sqrt(n)
    idx = np.arange(0, n, 10)
    e_vn = gnss["vel_n_mps"].to_numpy() - truth["vel_n_mps"].to_numpy()[idx]
    assert e_vn.std() == pytest.approx(s.gnss_velocity_noise_mps, rel=0.1)
    assert drive.sensors.wheelbase_m == VP.wheelbase_m
