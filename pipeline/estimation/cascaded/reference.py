"""The filterpy reference backend of the cascaded filters: the same model, filterpy's math.

``FilterpyStepper`` processes a sample exactly as ``cascade.cascade_sample`` does, with
filterpy doing the estimator arithmetic: ``ExtendedKalmanFilter`` (its ``predict_x``
replaced by the model's ``f``, its ``F`` the model's Jacobian; its Joseph-form ``update``
with the model's ``H`` and a heading-wrapping residual) and ``UnscentedKalmanFilter`` with
``MerweScaledSigmaPoints`` (``fx``/``hx`` the model's ``f``/``h``). The hybrid predicts with
filterpy's UKF, overwrites the EKF-mean states with ``f(x_hat)`` and updates with filterpy's
EKF. Everything that is model or bookkeeping is the compiled code the numba backend runs:
the model functions, the control discretization, the measurement front end
(``filters.prepare_update``: rows, gating, resets, logs), positive definiteness and the NaN
barrier (``cascade.finish``).

The unscented mean is taken relative to the central sigma point (``x_mean_fn`` and
``z_mean_fn``; ``numerics.centered_mean_cov`` explains why alpha = 1e-3 needs it). The loop
runs in Python, so this backend is slow; it exists to check the compiled one (tests require
agreement within 1e-6 sigma).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter, MerweScaledSigmaPoints, UnscentedKalmanFilter

from navreplay.pipeline.estimation.cascaded import cascade as cs
from navreplay.pipeline.estimation.cascaded.engine import CascadeSetup, CascadeState, StepperBase
from navreplay.pipeline.estimation.cascaded.filters import (
    EST_EKF,
    EST_UKF,
    Filter,
    Gating,
    Measurement,
    prepare_update,
)
from navreplay.pipeline.estimation.cascaded.model import (
    MODEL_CTL,
    MODEL_NAV,
    NAV_GB,
    NAV_RB,
    NX,
    Z_PSI,
    model_f,
    model_h,
    model_jacobian,
    model_noise,
    wrap_pi,
)
from navreplay.pipeline.estimation.core import gating as gt
from navreplay.pipeline.estimation.core import runlog as rl
from navreplay.pipeline.nav.earth import F64


def centered_mean(sigmas: F64, Wm: F64) -> F64:
    """``x_mean_fn``/``z_mean_fn``: the unscented mean relative to the central point."""
    s = np.asarray(sigmas, dtype=float)
    out: F64 = s[0] + Wm[1:] @ (s[1:] - s[0])
    return out


def _residual(angle_col: int) -> Callable[[F64, F64], F64]:
    """A residual ``a - b`` that wraps component ``angle_col`` (-1: none)."""

    def residual(a: F64, b: F64) -> F64:
        d: F64 = np.asarray(a, dtype=float) - np.asarray(b, dtype=float)
        if angle_col >= 0:
            d[angle_col] = wrap_pi(float(d[angle_col]))
        return d

    return residual


class _ModelEkf(ExtendedKalmanFilter):  # type: ignore[misc]
    """filterpy's EKF whose state prediction is the model's ``f`` (eq. 22-23)."""

    x: Any

    def __init__(self) -> None:
        super().__init__(dim_x=NX, dim_z=1)
        self.fx: Callable[[F64], F64] = lambda x: x

    def predict_x(self, u: Any = 0) -> None:
        self.x = self.fx(np.asarray(self.x, dtype=np.float64))


class _SubFilter:
    """One of the two filters of the cascade on filterpy (``est``: EKF, UKF or hybrid)."""

    def __init__(self, model: int, est: int, setup: CascadeSetup, P0: F64, disc: F64) -> None:
        self.model = model
        self.est = est
        self.setup = setup
        self.disc = disc  # the run's control discretization (``CascadeState.prepare``)
        self.ekf = _ModelEkf()
        self.ekf.x = np.zeros(NX)
        self.ekf.P = P0.copy()
        self.ukf: Any = None
        self.points: Any = None
        if est != EST_EKF:
            a, b, k = setup.ut_params
            self.points = MerweScaledSigmaPoints(NX, alpha=a, beta=b, kappa=k)
            if not (np.allclose(self.points.Wm, setup.settings.ut.wm, rtol=1e-12, atol=0.0)):
                raise ValueError("filterpy's sigma-point weights differ from the kernel's")
            self.ukf = UnscentedKalmanFilter(
                dim_x=NX, dim_z=1, dt=1.0, hx=None, fx=None, points=self.points,
                x_mean_fn=centered_mean, z_mean_fn=centered_mean,
            )  # fmt: skip
            self.ukf.x = np.zeros(NX)
            self.ukf.P = P0.copy()

    @property
    def x(self) -> F64:
        x: F64 = np.asarray(self.ukf.x if self.est == EST_UKF else self.ekf.x, dtype=float)
        return x

    @property
    def cov(self) -> F64:
        P: F64 = np.asarray(self.ukf.P if self.est == EST_UKF else self.ekf.P, dtype=float)
        return P

    def set(self, x: F64, P: F64) -> None:
        """Overwrite the state (after the shared positive-definiteness repair)."""
        for f in (self.ekf, self.ukf):
            if f is not None:
                f.x = np.array(x, dtype=float)
                f.P = np.array(P, dtype=float)

    def predict(self, u: F64, dt: float) -> None:
        s = self.setup.settings
        Q = np.empty((NX, NX))
        model_noise(s.q[self.model], dt, s.noise_interval_s, Q)

        def fx(x: F64, _dt: float = dt) -> F64:
            out = np.empty(NX)
            model_f(self.model, np.asarray(x, dtype=float), u, _dt, s.par, self.disc, out)
            return out

        if self.est == EST_EKF:
            F = np.empty((NX, NX))
            model_jacobian(self.model, self.x, u, dt, s.par, self.disc, F)
            self.ekf.F, self.ekf.Q, self.ekf.fx = F, Q, fx
            self.ekf.predict()
            return
        x_prior = self.x.copy()
        self.ukf.Q = Q
        self.ukf.predict(dt=dt, fx=fx)
        mean_ekf = fx(x_prior)
        for j in np.flatnonzero(s.ekf_mean if self.model == MODEL_NAV else []):
            self.ukf.x[j] = mean_ekf[j]
        self.set(self.ukf.x, self.ukf.P)

    def update(self, t_ns: int, z: F64, st: CascadeState) -> bool:
        """Gate with the shared front end, then let filterpy update with the accepted rows."""
        s = self.setup.settings
        ukf = self.est == EST_UKF
        x, P = self.x.copy(), np.ascontiguousarray(self.cov)
        block_of_row, streams = (
            (cs.NAV_BLOCK_OF_ROW, cs.NAV_STREAMS)
            if self.model == MODEL_NAV
            else (cs.CTL_BLOCK_OF_ROW, cs.CTL_STREAMS)
        )
        meas = Measurement(z, s.r[self.model], block_of_row, streams)
        gating = Gating(s.gate, s.timeout_s, st.imem[cs.I_REJ :])
        ur, acc, ma = prepare_update(t_ns, Filter(self.model, self.est, x, P), meas, gating, s.ut,
                                     st.log)  # fmt: skip
        if ma < 0:
            return False
        m, rows, Hm, rm = ur.m, ur.rows, ur.H, ur.r
        self.set(x, P)  # a timeout reset may have inflated P
        if ma == 0:
            return True
        a = acc[:ma]
        sel = rows[:m][a]
        hits = np.flatnonzero(sel == Z_PSI) if self.model == MODEL_NAV else np.empty(0)
        angle = int(hits[0]) if hits.size else -1
        za, Ra = z[sel], np.diag(rm[a])

        def hx(xs: F64) -> F64:
            out = np.empty(3)
            model_h(self.model, np.asarray(xs, dtype=float), out)
            return out[sel]

        if ukf:
            self.ukf.sigmas_f = self.points.sigma_points(self.ukf.x, self.ukf.P)
            self.ukf.residual_z = _residual(angle)
            self.ukf.update(za, R=Ra, hx=hx)
        else:
            Ha = Hm[a].copy()
            self.ekf.update(za, HJacobian=lambda _x: Ha, Hx=hx, R=Ra, residual=_residual(angle))
            self.set(self.ekf.x, self.ekf.P)
        return True


class FilterpyStepper(StepperBase):
    """``engine.NumbaStepper``'s contract on filterpy (see the module docstring)."""

    backend = "filterpy"

    def __init__(self, setup: CascadeSetup, capacity: int, n_gps: int = 0) -> None:
        super().__init__(setup, capacity, n_gps)
        est = setup.settings.est
        disc = self.state.mem[cs.M_DISC :]
        self.nav = _SubFilter(MODEL_NAV, est, setup, setup.P0[0], disc)
        ctl_est = EST_UKF if est == EST_UKF else EST_EKF
        self.ctl = _SubFilter(MODEL_CTL, ctl_est, setup, setup.P0[1], disc)

    def _nav_predict(self, t_ns: int) -> None:
        st, s = self.state, self.setup.settings
        dt = (t_ns - int(st.imem[cs.I_T_NAV])) * 1e-9
        if dt <= 0.0:
            return
        if dt > s.gap_s:
            gt.record_event(st.ev_i, st.ev_f, st.counts, t_ns, cs.EV_GAP, -1, -1, dt)
        n_sub = max(1, math.ceil(dt / s.max_step_s - 1e-9))
        u = st.mem[cs.M_RADAR : cs.M_GYRO + 1].copy()
        for _ in range(n_sub):
            self.nav.predict(u, dt / n_sub)
        st.imem[cs.I_T_NAV] = t_ns

    def _ctl_predict(self, t_ns: int) -> None:
        st = self.state
        dt = (t_ns - int(st.imem[cs.I_T_CTL])) * 1e-9
        if dt > 0.0:
            self.ctl.predict(st.mem[cs.M_CMD : cs.M_CMD + 1].copy(), dt)
            st.imem[cs.I_T_CTL] = t_ns

    def _finish(self, t_ns: int) -> int:
        st = self.state
        st.x[:NX], st.x[NX:] = self.nav.x, self.ctl.x
        st.P[0], st.P[1] = self.nav.cov, self.ctl.cov
        status = int(cs.finish(t_ns, st.x, st.P, self.setup.settings, st.log))
        self.nav.set(st.x[:NX], st.P[0])
        self.ctl.set(st.x[NX:], st.P[1])
        return status

    def nav_epoch(self, t_ns: int, gps: F64) -> None:
        """A GPS fix between vehicle samples (``cascade_sample`` with ``nav_only``)."""
        if self.status != gt.STATUS_OK or not self.state.imem[cs.I_STARTED]:
            return
        self._nav_predict(t_ns)
        ok = self.nav.update(t_ns, gps, self.state)
        self._set_status(self._finish(t_ns) if ok else self._fail(t_ns))

    def _fail(self, t_ns: int) -> int:
        st = self.state
        return int(gt.fail(t_ns, gt.STATUS_INDEFINITE, st.ev_i, st.ev_f, st.counts))

    def sample(self, t_ns: int, veh: F64, gps: F64) -> None:
        """``cascade.cascade_sample`` on filterpy."""
        if self.status != gt.STATUS_OK:
            return
        t0 = time.perf_counter()
        st = self.state
        if st.imem[cs.I_STARTED] == 0:
            st.imem[cs.I_T_NAV] = st.imem[cs.I_T_CTL] = t_ns
            st.imem[cs.I_STARTED] = 1
        else:
            st.prepare(t_ns)
            self._nav_predict(t_ns)
            self._ctl_predict(t_ns)
        ok = self.nav.update(t_ns, gps, st)
        radar, gyro = float(veh[cs.V_RADAR]), float(veh[cs.V_GYRO])
        if math.isfinite(radar):
            st.mem[cs.M_RADAR] = radar
        if math.isfinite(gyro):
            st.mem[cs.M_GYRO] = gyro
        x1 = self.nav.x
        z2 = np.array([gyro - x1[NAV_GB], radar - x1[NAV_RB], float(veh[cs.V_POT])])
        ok = ok and self.ctl.update(t_ns, z2, st)
        self._set_status(self._finish(t_ns) if ok else self._fail(t_ns))
        if self.status == gt.STATUS_OK:
            k = int(st.counts[rl.CNT_OUT])
            if k < st.out_t.size:
                st.out_t[k], st.out_x[k], st.out_P[k] = t_ns, st.x, st.P
            st.counts[rl.CNT_OUT] = k + 1
            st.counts[rl.CNT_STOP] += 1
        self.wall += time.perf_counter() - t0
