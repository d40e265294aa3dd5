"""Attitude conventions: quaternions, DCMs, Euler angles, rotation vectors."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from navreplay.pipeline.nav import rotations as r

angles = st.tuples(st.floats(-3.1, 3.1), st.floats(-1.5, 1.5), st.floats(-3.1, 3.1))


@settings(max_examples=200, deadline=None)
@given(angles)
def test_euler_quaternion_dcm_round_trips(rpy: tuple[float, float, float]) -> None:
    roll, pitch, yaw = rpy
    c = r.euler_to_dcm(roll, pitch, yaw)
    np.testing.assert_allclose(c @ c.T, np.eye(3), atol=1e-12)
    q = r.euler_to_quat(roll, pitch, yaw)
    assert np.linalg.norm(q) == pytest.approx(1.0)
    assert q[0] >= 0.0
    np.testing.assert_allclose(r.quat_to_dcm(q), c, atol=1e-12)
    np.testing.assert_allclose(r.quat_to_euler(q), rpy, atol=1e-9)


def test_yaw_is_heading_clockwise_from_north() -> None:
    c = r.euler_to_dcm(0.0, 0.0, math.pi / 2)  # facing east
    np.testing.assert_allclose(c @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], atol=1e-15)
    c = r.euler_to_dcm(0.0, 0.1, 0.0)  # nose up: forward axis gains an up (negative down) part
    assert (c @ [1.0, 0.0, 0.0])[2] < 0.0


@settings(max_examples=200, deadline=None)
@given(st.tuples(st.floats(-1.8, 1.8), st.floats(-1.8, 1.8), st.floats(-1.8, 1.8)))
def test_rotation_vector_round_trip(v: tuple[float, float, float]) -> None:
    vec = np.array(v)
    if np.linalg.norm(vec) >= math.pi - 1e-6:  # beyond pi the same rotation has a shorter vector
        return
    q = r.rotvec_to_quat(vec)
    np.testing.assert_allclose(r.quat_to_rotvec(q), vec, atol=1e-9)


def test_small_rotation_vector_is_accurate() -> None:
    vec = np.array([1e-9, -2e-9, 3e-10])
    np.testing.assert_allclose(r.quat_to_rotvec(r.rotvec_to_quat(vec)), vec, rtol=1e-6)


def test_quaternion_product_composes_rotations() -> None:
    a = r.euler_to_quat(0.1, 0.2, 0.3)
    b = r.euler_to_quat(-0.4, 0.05, 1.3)
    np.testing.assert_allclose(
        r.quat_to_dcm(r.quat_mul(a, b)), r.quat_to_dcm(a) @ r.quat_to_dcm(b), atol=1e-12
    )


def test_skew_is_cross_product() -> None:
    v, w = np.array([1.0, -2.0, 0.5]), np.array([0.3, 0.7, -1.1])
    np.testing.assert_allclose(r.skew(v) @ w, np.cross(v, w))


@pytest.mark.parametrize(
    ("a", "w"),
    [
        (3.5, 3.5 - 2 * math.pi),
        (-math.pi, math.pi),
        (math.pi, math.pi),
        (0.2, 0.2),
        (-7.0, -7.0 + 2 * math.pi),
    ],
)
def test_wrap_angle(a: float, w: float) -> None:
    assert r.wrap_angle(a) == pytest.approx(w)
