"""Drive profiles and sampled motion: smoothness, exact turn angles, non-holonomic motion."""

from __future__ import annotations

import math

import numpy as np
import pytest

from navreplay.pipeline.nav.rotations import quat_to_dcm
from navreplay.pipeline.synth.profile import ProfileBuilder
from navreplay.pipeline.synth.trajectory import Leg, Limits, build_profiles, sample

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
        roll_per_lat_acc=0.005,
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
