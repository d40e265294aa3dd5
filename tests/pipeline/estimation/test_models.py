"""The shared model: error injection, coordinates, Jacobians against finite differences."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pytest
from scipy.linalg import expm

from navreplay.pipeline.estimation.ins.models import ins, ins_errors
from navreplay.pipeline.estimation.ins.models import measurement as me
from navreplay.pipeline.estimation.ins.outputs import euler_covariance, quat_to_euler_batch
from navreplay.pipeline.nav.earth import dcm_ecef_to_ned, geodetic_to_ecef
from navreplay.pipeline.nav.mechanization import LANES, LN_DIM, imu_from_motion
from navreplay.pipeline.nav.rotations import euler_to_quat, quat_to_dcm, quat_to_euler

N = ins.N_TIGHT
# finite-difference steps per error state: m, m/s, rad, m/s^2, rad/s, m, m/s
EPS = np.array([1e-2] * 3 + [1e-3] * 3 + [1e-5] * 3 + [1e-4] * 3 + [1e-6] * 3 + [1e-2, 1e-3])
# larger steps for the dynamics: the response over milliseconds is small
FD_EPS = np.array([1.0] * 3 + [1e-2] * 3 + [1e-4] * 3 + [1e-3] * 3 + [1e-5] * 3 + [1.0, 0.1])


def moving_state() -> np.ndarray:
    X = np.zeros(ins.FULL_DIM)
    X[ins.X_LAT], X[ins.X_LON], X[ins.X_H] = math.radians(37.45), math.radians(126.95), 80.0
    X[ins.X_VEL : ins.X_VEL + 3] = (8.0, -5.0, 0.3)
    X[ins.X_Q : ins.X_Q + 4] = euler_to_quat(0.05, -0.03, 2.3)
    X[ins.X_BA : ins.X_BA + 3] = (0.02, -0.01, 0.03)
    X[ins.X_BG : ins.X_BG + 3] = (1e-3, -2e-3, 5e-4)
    X[ins.X_CB], X[ins.X_CD] = 100.0, 2.0
    return X


def imu_span(X: np.ndarray, n_samples: int, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Constant IMU (turning and accelerating) that includes the state's own biases."""
    f, w = imu_from_motion(X[:10], np.array([0.5, 0.3, -0.1]), np.array([0.01, -0.02, 0.2]))
    t = np.arange(n_samples, dtype=np.int64) * round(dt_s * 1e9)
    return t, np.tile(np.r_[f + X[ins.X_BA : ins.X_BA + 3], w + X[ins.X_BG : ins.X_BG + 3]],
                      (n_samples, 1))  # fmt: skip


STEP = ins.Stepping(1, 0.02, 0.05)


def span_of(t: np.ndarray, imu: np.ndarray, t_end: int) -> ins.ImuSpan:
    """The span from the first sample (its input) to ``t_end``."""
    return ins.ImuSpan(t, imu, 1, 0, imu[0], t_end)


def propagate(X: np.ndarray, t: np.ndarray, imu: np.ndarray, t_end: int) -> np.ndarray:
    Y = X.copy()
    ins.propagate_span(Y, span_of(t, imu, t_end), STEP, ins.span_work(), False)
    return Y


def central_differences(
    X: np.ndarray, eps: np.ndarray, f: Callable[[np.ndarray], np.ndarray]
) -> np.ndarray:
    """Column ``j``: ``(f(X [+] eps_j e_j) - f(X [+] -eps_j e_j)) / (2 eps_j)``, the error-state
    step applied with ``ins.inject``."""
    cols = []
    for j in range(N):
        d = np.zeros(N)
        d[j] = eps[j]
        Xp, Xm = X.copy(), X.copy()
        ins.inject(Xp, d, N)
        ins.inject(Xm, -d, N)
        cols.append((f(Xp) - f(Xm)) / (2 * eps[j]))
    return np.stack(cols, axis=1)


def transition_fd(
    X: np.ndarray, t: np.ndarray, imu: np.ndarray, t_end: int, eps: np.ndarray
) -> np.ndarray:
    """Central differences of the span propagation from ``X`` to ``t_end``."""
    Y0 = propagate(X, t, imu, t_end)
    return central_differences(X, eps, lambda Z: ins.difference(propagate(Z, t, imu, t_end), Y0, N))


def test_inject_and_difference_are_inverse() -> None:
    X = moving_state()
    dx = np.random.default_rng(1).normal(size=N) * EPS * 300
    Xp = X.copy()
    ins.inject(Xp, dx, N)
    np.testing.assert_allclose(ins.difference(Xp, X, N), dx, rtol=1e-9, atol=1e-12)


def test_ukf_coordinates_round_trip() -> None:
    X = moving_state()
    q_ref = euler_to_quat(0.04, -0.02, 2.25)
    s = np.empty(N)
    ins.from_full(X, q_ref, N, s)
    back = np.empty(ins.FULL_DIM)
    ins.to_full(s, q_ref, N, back)
    np.testing.assert_allclose(back, X, atol=1e-13)
    # the attitude coordinate is the nav-frame rotation from q_ref to q
    assert np.linalg.norm(s[ins.E_ATT : ins.E_ATT + 3]) == pytest.approx(0.05 + 0.0, abs=0.05)


def test_error_dynamics_match_finite_differences_of_the_mechanization() -> None:
    """expm(F T) against central differences of the RK4 propagation over a short span."""
    X = moving_state()
    T = 0.002
    t, imu = imu_span(X, 3, 0.001)
    Phi_fd = transition_fd(X, t, imu, round(T * 1e9), FD_EPS)
    F = np.empty((N, N))
    C = quat_to_dcm(X[ins.X_Q : ins.X_Q + 4])
    ins_errors.error_jacobian(X, C @ (imu[0, :3] - X[ins.X_BA : ins.X_BA + 3]), C, N, F)
    # positions are differences of latitudes: ~1e-9 m of rounding per column, / (2 eps)
    tol = 1e-3 * np.abs(expm(F * T)) + 2e-9 / FD_EPS[None, :] + 1e-10
    bad = np.abs(expm(F * T) - Phi_fd) > tol
    assert not bad.any(), list(zip(*np.nonzero(bad), strict=True))


def test_span_transition_matches_finite_differences_to_second_order() -> None:
    """``transition`` over a 0.1 s span of 10 samples: Phi within the O(T^3) truncation."""
    X = moving_state()
    t, imu = imu_span(X, 12, 0.01)
    out = ins.span_work()
    acc = out.acc
    Y0 = X.copy()
    ins.propagate_span(Y0, span_of(t, imu, 100_000_000), STEP, out, True)
    Phi, Qd = np.empty((N, N)), np.empty((N, N))
    noise = ins_errors.noise_vector(2e-3, 2e-4, 1e-4, 1e-5, 0.1, 0.01, 2.0, 0.2)
    ins_errors.transition(Y0, acc, noise, N, Phi, Qd)
    Phi_fd = transition_fd(X, t, imu, 100_000_000, EPS)
    # third-order terms over 0.1 s at 0.2 rad/s turn rate: ~1 % of the largest couplings
    np.testing.assert_allclose(Phi, Phi_fd, rtol=0.02, atol=2e-3)
    assert np.allclose(Qd, Qd.T)
    assert np.all(np.linalg.eigvalsh(Qd) > -1e-18)


def test_span_integrates_the_receiver_clock() -> None:
    X = moving_state()
    t, imu = imu_span(X, 12, 0.01)
    Y = propagate(X, t, imu, 100_000_000)
    assert Y[ins.X_CB] == pytest.approx(X[ins.X_CB] + 0.1 * X[ins.X_CD])


def sigma_stack(X: np.ndarray, m: int, spread: float) -> np.ndarray:
    """``m`` states around ``X`` (position, velocity, attitude, biases perturbed), unit q."""
    rng = np.random.default_rng(7)
    S = np.tile(X, (m, 1))
    S[1:, :3] += rng.normal(0.0, 1e-6 * spread, (m - 1, 3))
    S[1:, 3:6] += rng.normal(0.0, 0.5 * spread, (m - 1, 3))
    S[1:, 6:10] += rng.normal(0.0, 0.01 * spread, (m - 1, 4))
    S[1:, 10:16] += rng.normal(0.0, 1e-3 * spread, (m - 1, 6))
    S[:, 6:10] /= np.linalg.norm(S[:, 6:10], axis=1)[:, None]
    return S


@pytest.mark.parametrize(
    ("case", "substeps", "t_end"),
    [
        ("100 Hz span, 1 substep", 1, 100_000_000),
        ("10 substeps, span ends between samples", 10, 95_000_000),
        ("IMU gap: an interval split into max-step RK4 steps", 1, 400_000_000),
    ],
)
def test_sigma_points_propagated_together_equal_one_at_a_time(
    case: str, substeps: int, t_end: int
) -> None:
    """``propagate_sigmas`` (the UKF's vectorized lanes) ends every state bitwise where
    ``propagate_span`` takes it alone, accumulator included, for 35 states."""
    X = moving_state()
    t, imu = imu_span(X, 40, 0.01)
    imu = imu + np.random.default_rng(3).normal(0.0, 0.05, imu.shape)
    if "gap" in case:
        t[12:] += 250_000_000  # 0.26 s without samples
    S = sigma_stack(X, 35, 1.0)
    lanes = np.arange(35, dtype=np.int64)[::-1].copy()  # lane order is free; lanes[0] accumulates
    ref = S.copy()
    span, step = span_of(t, imu, t_end), ins.Stepping(substeps, 0.02, 0.05)
    out_ref = ins.span_work()
    for j in lanes:
        out_j = out_ref if j == lanes[0] else ins.span_work()
        i_ref = ins.propagate_span(ref[j], span, step, out_j, j == lanes[0])
    got = S.copy()
    out = ins.span_work()
    Y = np.full(LN_DIM * LANES, np.nan)  # no lane may read what it did not write
    i = ins.propagate_sigmas(got, lanes, 35, span, step, out, Y)
    assert i == i_ref
    assert np.array_equal(got, ref), np.abs(got - ref).max()
    assert np.array_equal(out.acc, out_ref.acc)
    assert np.array_equal(out.u_end, out_ref.u_end)
    assert not np.array_equal(got[0], S[0])


def test_sigma_lanes_fall_back_to_exact_trigonometry_when_latitude_moves_far() -> None:
    """A lane whose latitude moves 1e-3 rad or more within an interval (here 7 km/s north
    over a 1 s gap) takes math.sin/cos as the scalar mechanization does: still bitwise equal."""
    X = moving_state()
    X[ins.X_VEL] = 7000.0
    t, imu = imu_span(X, 3, 1.0)
    S = sigma_stack(X, 5, 1.0)
    S[1:, ins.X_VEL] = 50.0  # the other lanes stay near their reference
    lanes = np.arange(5, dtype=np.int64)
    ref = S.copy()
    span, step = span_of(t, imu, 2_000_000_000), ins.Stepping(1, 2.0, 5.0)
    for j in lanes:
        ins.propagate_span(ref[j], span, step, ins.span_work(), False)
    got = S.copy()
    ins.propagate_sigmas(got, lanes, 5, span, step, ins.span_work(), np.zeros(LN_DIM * LANES))
    assert abs(got[0, ins.X_LAT] - S[0, ins.X_LAT]) > 1e-3
    assert np.array_equal(got, ref)


def test_propagate_sigmas_refuses_more_states_than_lanes() -> None:
    X = moving_state()
    t, imu = imu_span(X, 12, 0.01)
    S = np.tile(X, (LANES + 1, 1))
    with pytest.raises(ValueError, match="1 to mechanization"):
        ins.propagate_sigmas(S, np.arange(LANES + 1, dtype=np.int64), LANES + 1,
                             span_of(t, imu, 100_000_000), STEP, ins.span_work(),
                             np.zeros(LN_DIM * LANES))  # fmt: skip


def epoch(X: np.ndarray) -> tuple[np.ndarray, np.ndarray, int, np.ndarray, np.ndarray]:
    """A fix (position + velocity), four satellites, the NHC pair and the standstill rows
    (zero velocity, zero angular rate) at ``X``."""
    rng = np.random.default_rng(0)
    r0 = geodetic_to_ecef(X[0], X[1], X[2])
    obs = np.zeros((4, me.OBS_COLS))
    for k in range(4):
        los_n = np.array([math.cos(0.3 + k), math.sin(0.3 + k), -0.5 - 0.1 * k])
        los_e = dcm_ecef_to_ned(X[0], X[1]).T @ (los_n / np.linalg.norm(los_n))
        obs[k, 0:3] = r0 + 2.2e7 * los_e
        obs[k, 3:6] = rng.normal(size=3) * 2000
        obs[k, me.OB_PR_OK] = obs[k, me.OB_PRR_OK] = 1.0
        obs[k, me.OB_SV] = me.sv_code(f"G{k + 1:02d}")
    fix = np.zeros((1, me.FIX_COLS))
    fix[0, me.FX_POS_DIM], fix[0, me.FX_VEL_DIM] = 3, 3
    rows = np.zeros((40, 2), np.int64)
    blocks = np.zeros((40, 4), np.int64)
    stop = np.array([0, 0, 0, 1, 1, 1])
    m, nb_ = me.epoch_layout(stop, fix, obs, np.array([0, 4]), True, True, rows, blocks)
    assert (m, nb_) == (22, 9)
    assert me.epoch_layout(stop, fix, obs, np.array([0, 4]), True, False, rows, blocks) == (16, 7)
    return rows, obs, m, blocks, fix


@pytest.mark.parametrize(
    ("kind", "tol"),
    [
        ("pos", 1e-6),
        ("vel", 2e-4),
        ("pr", 1e-4),
        ("prr", 2e-4),
        ("nhc", 1e-6),
        ("zupt", 1e-9),
        ("zaru", 1e-9),
    ],
)
def test_measurement_jacobians_match_finite_differences(kind: str, tol: float) -> None:
    """Rows of ``epoch_jac`` against central differences of ``epoch_h`` (the EKF's H).

    The velocity and rate rows neglect the earth rate in the lever-arm term's attitude
    dependence (|w_ie x l| ~ 1e-4 m/s), hence their looser tolerance.
    """
    X = moving_state()
    rows, obs, m, _, _ = epoch(X)
    lever, w = np.array([0.5, -0.3, -1.2]), np.array([0.05, -0.1, 0.4])
    ref = X[:3].copy()
    H = np.zeros((m, N))
    me.epoch_jac(X, rows, m, obs, w, lever, N, H)
    eps = EPS.copy()
    eps[ins.E_ATT : ins.E_ATT + 3] = 1e-4  # 2e7 m pseudoranges: keep rounding below 1e-5

    def h(Z: np.ndarray) -> np.ndarray:
        out = np.zeros(m)
        me.epoch_h(Z, rows, m, obs, ref, w, lever, out)
        return out

    H_fd = central_differences(X, eps, h)
    kinds = {"pos": (0, 1, 2), "vel": (3, 4, 5), "pr": (6,), "prr": (7,), "nhc": (8, 9),
             "zupt": (10, 11, 12), "zaru": (13, 14, 15)}  # fmt: skip
    sel = np.isin(rows[:m, 0], kinds[kind])
    np.testing.assert_allclose(H[sel], H_fd[sel], rtol=1e-4, atol=tol)


def test_euler_covariance_uses_the_exact_euler_jacobian() -> None:
    """A nav-frame rotation phi changes the Euler angles by M^-1 phi (finite differences)."""
    rpy = np.array([[0.1, -0.2, 2.5]])
    q = euler_to_quat(*rpy[0])
    J = np.empty((3, 3))
    for j in range(3):
        phi = np.zeros(3)
        phi[j] = 1e-7
        X = np.zeros(ins.FULL_DIM)
        X[ins.X_Q : ins.X_Q + 4] = q
        ins.inject(X, np.r_[np.zeros(6), phi, np.zeros(6)], ins.N_LOOSE)
        J[:, j] = (np.array(quat_to_euler(X[ins.X_Q : ins.X_Q + 4])) - rpy[0]) / 1e-7
    P = np.diag([1e-4, 4e-4, 9e-4])[None]
    np.testing.assert_allclose(euler_covariance(rpy, P)[0], J @ P[0] @ J.T, rtol=1e-5)
    np.testing.assert_allclose(quat_to_euler_batch(q[None])[0], rpy[0], atol=1e-12)
