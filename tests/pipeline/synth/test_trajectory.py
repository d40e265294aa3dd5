"""Drive profiles and sampled motion: smoothness, exact turn angles, non-holonomic motion."""

from __future__ import annotations

import math

import numpy as np
import pytest

from navreplay.ingest.typed import FieldError
from navreplay.pipeline.nav.rotations import quat_to_dcm
from navreplay.pipeline.synth.profile import ProfileBuilder
from navreplay.pipeline.synth.trajectory import (
    Body,
    Leg,
    Limits,
    Motion,
    Profiles,
    build_profiles,
    sample,
)

LIMITS = Limits(accel_mps2=1.5, yaw_accel_radps2=0.3, grade_rate_ps=0.05)
LEGS = [
    Leg("straight", speed_mps=10.0, duration_s=10.0),
    Leg("turn", speed_mps=6.0, angle_deg=-270.0, radius_m=15.0),
    Leg("straight", speed_mps=12.0, duration_s=30.0, hill_m=5.0),
    Leg("stop", duration_s=5.0),
]


def test_profiles_are_c2_at_every_breakpoint() -> None:
    b = ProfileBuilder()
    b.hold(1.0)
    b.ramp(3.0, 2.0)
    b.hold(0.5)
    b.ramp(-1.0, 1.5)
    pp = b.build(6.0)
    d1, d2 = pp.derivative(), pp.derivative(2)
    for x in pp.x[1:-1]:
        for f in (pp, d1, d2):
            assert f(x - 1e-9) == pytest.approx(f(x + 1e-9), abs=1e-6)
    assert pp(3.0) == pytest.approx(3.0)
    assert pp(6.0) == pytest.approx(-1.0)
    # peak slope of a smootherstep is 15/8 of the mean slope
    assert np.max(d1(np.linspace(1, 3, 2001))) == pytest.approx(1.875 * 3.0 / 2.0, rel=1e-6)


def test_turns_turn_by_exactly_their_angle() -> None:
    prof = build_profiles(LEGS, stationary_s=5.0, duration_s=60.0, limits=LIMITS)
    psi = prof.yaw_rate.antiderivative()
    assert psi(prof.end_s) - psi(0.0) == pytest.approx(math.radians(-270.0), abs=1e-12)


def test_sampled_motion_obeys_the_non_holonomic_constraint() -> None:
    prof = build_profiles(LEGS, stationary_s=5.0, duration_s=100.0, limits=LIMITS)
    mo = sample(
        prof,
        rate_hz=50,
        duration_s=100.0,
        lat0_rad=0.65,
        lon0_rad=2.2,
        h0_m=60.0,
        yaw0_rad=1.0,
        body=Body(roll_per_lat_acc=0.005),
    )
    v_body = np.einsum("nji,nj->ni", np.array([quat_to_dcm(q) for q in mo.q_wxyz]), mo.vel_ned_mps)
    assert np.abs(v_body[:, 1:]).max() < 1e-12
    assert v_body[:, 0].min() >= 0.0
    assert mo.vel_ned_mps[: 5 * 50].max() == 0.0  # at rest first
    # the hill returns to the starting height; the turn leans the body out (left, roll < 0)
    assert mo.h_m[-1] == pytest.approx(60.0, abs=1e-6)
    assert mo.h_m.max() == pytest.approx(65.0, abs=1e-6)
    turning = np.abs(mo.w_nb_b_radps[:, 2]) > 0.3
    assert np.all(mo.rpy_rad[turning, 0] > 0.0)  # a left turn rolls the body right


def test_a_hill_too_steep_for_its_straight_is_refused() -> None:
    with pytest.raises(ValueError, match="too steep"):
        build_profiles([Leg("straight", 3.0, 10.0, hill_m=20.0)], 0.0, 20.0, LIMITS)


REVERSING = [
    Leg("turn", speed_mps=-1.8, angle_deg=90.0, radius_m=5.0),
    Leg("straight", speed_mps=-1.5, duration_s=12.0, hill_m=0.2),
    Leg("stop", duration_s=3.0),
    Leg("straight", speed_mps=8.0, duration_s=10.0),
    Leg("turn", speed_mps=6.0, angle_deg=-90.0, radius_m=20.0),
]


def _motion(
    legs: list[Leg], duration_s: float, body: Body | None = None, **kw: float
) -> tuple[Profiles, Motion]:
    start = kw.pop("start_speed_mps", 0.0)
    prof = build_profiles(legs, 5.0 if start == 0.0 else 0.0, duration_s, LIMITS,
                          start_speed_mps=start)  # fmt: skip
    mo = sample(prof, rate_hz=100, duration_s=duration_s, lat0_rad=0.65, lon0_rad=2.2,
                h0_m=60.0, yaw0_rad=1.0, body=body or Body(roll_per_lat_acc=0.005))  # fmt: skip
    return prof, mo


def _derivatives_match(mo: Motion, rate_hz: int) -> None:
    """Central differences of the velocity and of the attitude match the analytic
    acceleration and body rates (the rates kink where a transition starts or ends)."""
    dt = 1.0 / rate_hz
    vdot = (mo.vel_ned_mps[2:] - mo.vel_ned_mps[:-2]) / (2 * dt)
    assert np.abs(vdot - mo.vdot_ned_mps2[1:-1]).max() < 1e-3
    c = np.array([quat_to_dcm(q) for q in mo.q_wxyz])
    skew = np.einsum("nji,njk->nik", c[1:-1], (c[2:] - c[:-2]) / (2 * dt))
    w = np.stack([skew[:, 2, 1], skew[:, 0, 2], skew[:, 1, 0]], axis=1)
    err = np.abs(w - mo.w_nb_b_radps[1:-1]).max(axis=1)
    assert err.max() < 1e-3
    assert np.percentile(err, 99) < 1e-5


def test_a_reversing_car_heads_opposite_its_course_and_keeps_the_constraint() -> None:
    """Backwards through a 90 deg right turn and over a small hump, a stop, then forwards:
    the velocity stays along body x (negative while reversing), the heading is the course
    plus 180 deg, the turn turns by its angle, and the derivatives are exact."""
    prof, mo = _motion(REVERSING, 60.0)
    c = np.array([quat_to_dcm(q) for q in mo.q_wxyz])
    v_body = np.einsum("nji,nj->ni", c, mo.vel_ned_mps)
    assert np.abs(v_body[:, 1:]).max() < 1e-12
    speed = np.hypot(mo.vel_ned_mps[:, 0], mo.vel_ned_mps[:, 1])
    back, ahead = (v_body[:, 0] < -0.3), (v_body[:, 0] > 0.3)
    assert back.sum() > 10 * 100
    assert ahead.sum() > 10 * 100
    course = np.arctan2(mo.vel_ned_mps[:, 1], mo.vel_ned_mps[:, 0])
    off = np.angle(np.exp(1j * (course - mo.rpy_rad[:, 2])))
    np.testing.assert_allclose(np.abs(off[back]), math.pi, atol=1e-9)
    np.testing.assert_allclose(off[ahead], 0.0, atol=1e-9)
    assert np.flatnonzero(back)[-1] < np.flatnonzero(ahead)[0]  # reversing first
    stopped = np.flatnonzero(speed[np.flatnonzero(back)[-1] : np.flatnonzero(ahead)[0]] == 0.0)
    assert stopped.size >= 3 * 100  # the car rests between the directions
    psi = prof.yaw_rate.antiderivative()
    end_reverse = mo.t_s[np.flatnonzero(back)[-1]]
    assert psi(end_reverse) == pytest.approx(math.radians(90.0), abs=1e-12)
    # reversing up the hump: the height comes back, the nose points down on the way up
    assert mo.h_m[np.flatnonzero(ahead)[0]] == pytest.approx(60.0, abs=1e-6)
    assert mo.h_m.max() == pytest.approx(60.2, abs=1e-6)
    rising = back & (mo.vel_ned_mps[:, 2] < -1e-3)
    assert rising.any()
    assert np.all(mo.rpy_rad[rising, 1] < 0.0)
    # reversing through a right turn, the body leans to the right (out of the turn)
    turning_back = back & (mo.w_nb_b_radps[:, 2] > 0.3)
    assert turning_back.any()
    assert np.all(mo.rpy_rad[turning_back, 0] > 0.0)
    _derivatives_match(mo, 100)


def test_a_rolling_start_moves_from_the_first_sample() -> None:
    """Already at 10 m/s at the first sample, steady (no acceleration there), then a curve;
    the derivatives are exact from the first sample on."""
    legs = [Leg("straight", 10.0, 3.0), Leg("turn", 10.0, angle_deg=90.0, radius_m=40.0)]
    prof, mo = _motion(legs, 30.0, start_speed_mps=10.0)
    assert prof.speed(0.0) == 10.0
    assert np.hypot(*mo.vel_ned_mps[0, :2]) == pytest.approx(10.0, abs=1e-12)
    assert mo.rpy_rad[0, 2] == pytest.approx(1.0, abs=1e-12)
    assert np.abs(mo.vdot_ned_mps2[0]).max() == 0.0
    assert np.hypot(mo.vel_ned_mps[:, 0], mo.vel_ned_mps[:, 1]).min() > 9.99
    _derivatives_match(mo, 100)


def test_legs_without_a_speed_or_a_radius_are_refused() -> None:
    with pytest.raises(FieldError, match="speed_mps"):
        Leg("straight", duration_s=3.0)
    with pytest.raises(FieldError, match="radius_m"):
        Leg("turn", speed_mps=-2.0, angle_deg=90.0, radius_m=0.0)


# a passenger car on a fair road: 0.5 deg of sideslip and 0.3 deg of pitch per m/s^2, 1 cm of
# road profile (issue 26: the constraint a real car breaks)
REAL_CAR = Body(roll_per_lat_acc=0.005, sideslip_per_lat_acc=0.009, pitch_per_long_acc=0.005,
                road_rms_m=0.01, road_seed=3)  # fmt: skip


def test_a_real_car_slips_in_turns_and_heaves_on_the_road_with_exact_derivatives() -> None:
    """Sideslip, suspension pitch and road heave break the non-holonomic constraint by what
    real cars show (lateral body velocity 0.05-0.3 m/s RMS in turns, a few cm/s vertical),
    while the path, the course and the exactness of the IMU's inputs stay."""
    legs = [*LEGS, Leg("turn", speed_mps=12.0, angle_deg=90.0, radius_m=40.0)]
    _, ideal = _motion(legs, 120.0)
    _, mo = _motion(legs, 120.0, REAL_CAR)
    _derivatives_match(mo, 100)
    c = np.array([quat_to_dcm(q) for q in mo.q_wxyz])
    v_body = np.einsum("nji,nj->ni", c, mo.vel_ned_mps)
    turning = np.abs(mo.vel_ned_mps[:, :2]).max(axis=1) > 1.0
    turning &= np.abs(ideal.w_nb_b_radps[:, 2]) > 0.1
    lateral = float(np.sqrt(np.mean(v_body[turning, 1] ** 2)))
    assert 0.05 < lateral < 0.3, lateral
    # into the turn: a right turn (yaw rate > 0) slips the velocity to the body's left
    right = turning & (ideal.w_nb_b_radps[:, 2] > 0.1)
    assert np.all(v_body[right, 1] < 0.0)
    moving = np.hypot(mo.vel_ned_mps[:, 0], mo.vel_ned_mps[:, 1]) > 1.0
    vertical = float(np.sqrt(np.mean(v_body[moving, 2] ** 2)))
    assert 0.01 < vertical < 0.1, vertical
    # the path is the idealised car's: the same course and horizontal track, the road's
    # heave (cm) on the height
    np.testing.assert_allclose(mo.vel_ned_mps[:, :2], ideal.vel_ned_mps[:, :2], atol=1e-12)
    np.testing.assert_allclose(mo.lat_rad, ideal.lat_rad, atol=1e-12)
    assert 0.005 < np.abs(mo.h_m - ideal.h_m).max() < 0.1
    assert np.abs(mo.rpy_rad[:, 2] - ideal.rpy_rad[:, 2]).max() > np.radians(1.0)
    # at rest nothing moves
    still = np.hypot(mo.vel_ned_mps[:, 0], mo.vel_ned_mps[:, 1]) == 0.0
    assert np.abs(v_body[still]).max() == 0.0
