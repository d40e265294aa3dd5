"""The filterpy reference backend of the vehicle-model filters.

``run_vehicle_filterpy`` takes exactly the arguments of ``vehicle.kernel.run_vehicle`` and
fills the same outputs. The model (``vehicle.model``: ``step``, ``step_jac``,
``process_noise``, measurements) and the bookkeeping (row layout, gating, recording,
positive-definiteness, NaN barrier: ``vehicle.kernel`` and ``core.gating``) are the same
code; filterpy does the estimator arithmetic:

- each model is a filterpy ``ExtendedKalmanFilter`` whose ``predict_x`` runs the model's
  ``step`` (filterpy's own ``predict`` then applies ``P = F P F^T + Q``) and whose ``update``
  fuses the accepted rows (Joseph form, filterpy's);
- ``vehicle_imm`` is filterpy's ``IMMEstimator`` over the two EKFs (mixing, mode
  probabilities, combination). A stop without an accepted measurement is an IMM update with
  unit likelihoods (mode probabilities follow the Markov chain only).

The loop runs in Python one stop at a time: it is the slow reference the compiled kernel is
checked against.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter, IMMEstimator

from navreplay.pipeline.estimation.core import gating as gt
from navreplay.pipeline.estimation.core import linalg as la
from navreplay.pipeline.estimation.core import runlog as rl
from navreplay.pipeline.estimation.core.runlog import RunLog
from navreplay.pipeline.estimation.vehicle import kernel as kv
from navreplay.pipeline.estimation.vehicle import model as vm
from navreplay.pipeline.nav.earth import F64


class _ModelEKF(ExtendedKalmanFilter):  # type: ignore[misc]
    """filterpy's EKF on one vehicle model; the prediction sub-steps run the shared model."""

    def __init__(self, model: int, x0: F64, P0: F64, vs: kv.VehicleSettings) -> None:
        super().__init__(dim_x=vm.NX, dim_z=1)
        self.model = model
        self.x = x0.copy()
        self.P = P0.copy()
        self.vp, self.max_step_s = vs.vp, vs.max_step_s
        self.noise = vm.ProcessNoise(np.array([vs.sig_wheel_speed_mps, vs.sig_steer_rad]), vs.q)
        self.u = np.zeros(kv.VH_COLS)
        self.dt = 0.0
        self.pending: tuple[F64, F64, F64, F64] | None = None
        self._lik = 1.0

    @property
    def likelihood(self) -> float:
        return self._lik

    def predict_x(self, u: Any = 0) -> None:
        """One sub-step of the model (``F`` and ``Q`` were set for this state by ``predict``)."""
        xn = np.empty(vm.NX)
        vm.step(self.model, self.x, self.u[kv.VH_V], self._delta(), self._h, self.vp, xn)
        self.x = xn

    def _delta(self) -> float:
        return float(self.u[kv.VH_D_KIN] if self.model == vm.KINEMATIC else self.u[kv.VH_D_DYN])

    def predict(self, u: Any = None) -> None:
        """Propagate over ``self.dt`` in the kernel's sub-steps (filterpy predict per step)."""
        dt = self.dt
        if dt <= 0.0:
            return
        max_step = self.max_step_s
        n_sub = max(1, math.ceil(dt / max_step - 1e-9))
        self._h = dt / n_sub
        F, Q = np.empty((vm.NX, vm.NX)), np.empty((vm.NX, vm.NX))
        for _ in range(n_sub):
            x = np.ascontiguousarray(self.x, dtype=float)
            vm.step_jac(self.model, x, self.u[kv.VH_V], self._delta(), self._h, self.vp, F)
            vm.process_noise(
                self.model, x, self.u[kv.VH_V], self._delta(), self._h, self.vp, self.noise, Q
            )
            self.F, self.Q = F.copy(), Q.copy()
            super().predict()
        P = np.ascontiguousarray(self.P)
        la.symmetrize(P, vm.NX)
        self.P = P

    def update(self, z: Any = None, *args: Any, **kwargs: Any) -> None:
        """Fuse the rows staged in ``pending`` (z, hx, H, R), if any (the driver has set the
        likelihood)."""
        if self.pending is None:
            return
        za, hx, Ha, Ra = self.pending
        self.pending = None
        super().update(za, HJacobian=lambda _x: Ha, Hx=lambda _x: hx, R=Ra)
        self.x = np.asarray(self.x, dtype=float).reshape(vm.NX)


def run_vehicle_filterpy(  # noqa: PLR0912, PLR0915 - mirrors kernels.vehicle.run_vehicle
    x0: F64, P0: F64, sched: kv.VehicleSchedule, vs: kv.VehicleSettings, log: RunLog,
    out_aux: F64,
) -> int:  # fmt: skip
    """``vehicle.kernel.run_vehicle`` with filterpy's EKF / IMMEstimator doing the arithmetic."""
    t0, u0, stops, veh, fix = sched
    ev_i, ev_f, counts = log.ev_i, log.ev_f, log.counts
    mode = vs.mode
    imm_on = mode == kv.MODE_IMM
    if imm_on:
        filters = [_ModelEKF(j, x0, P0, vs) for j in (vm.KINEMATIC, vm.DYNAMIC)]
        pk, pd = vs.p_stay_kinematic, vs.p_stay_dynamic
        M = np.array([[pk, 1.0 - pk], [1.0 - pd, pd]])
        imm = IMMEstimator(filters, np.array([1.0 - vs.mu0_dynamic, vs.mu0_dynamic]), M)
        aux = float(imm.mu[1])
    else:
        model = vm.DYNAMIC if mode == kv.MODE_DYNAMIC else vm.KINEMATIC
        if mode == kv.MODE_SWITCHED:
            model = int(kv.switch_model(vm.KINEMATIC, u0[kv.VH_V], vs))
        filters = [_ModelEKF(model, x0, P0, vs)]
        aux = float(model)
    u = u0.copy()
    L = np.empty((vm.NX, vm.NX))
    rows = np.empty((kv.M_MAX, 2), np.int64)
    blocks = np.empty((kv.M_MAX, 4), np.int64)
    ms = kv.model_rows(len(filters))
    gw = kv.gate_work(gt.N_STREAMS)
    x, P = x0.copy(), P0.copy()
    kv._record(t0, x, P, aux, log, out_aux)
    t_cur = t0
    for k in range(stops.shape[0]):
        t = int(stops[k, kv.VS_T])
        for f in filters:
            f.dt, f.u = (t - t_cur) * 1e-9, u.copy()
        t_cur = t
        if imm_on:
            imm.predict()
        else:
            filters[0].predict()
        vi = int(stops[k, kv.VS_VEH])
        if vi >= 0:
            u[:] = veh[vi]
        if mode == kv.MODE_SWITCHED and vi >= 0:
            filters[0].model = int(kv.switch_model(filters[0].model, u[kv.VH_V], vs))
        lay = kv.epoch_rows(stops[k], veh, fix, rows, blocks)
        for f in filters:
            f._lik = 1.0
        if lay.m > 0:
            for j, f in enumerate(filters):
                xf = np.ascontiguousarray(f.x, dtype=float)
                kv.epoch_values(f.model, xf, u, lay, sched, vs, ms, j)
            g = 0 if not imm_on or imm.cbar[0] >= imm.cbar[1] else 1
            Ps = np.array([np.asarray(f.P, dtype=float) for f in filters])
            ma = int(kv.gate_with_reset(t, lay, Ps, ms, g, gw, vs, log))
            a = gw.acc[:ma]
            for j, f in enumerate(filters):
                f.P = Ps[j].copy()  # a timeout reset may have changed it
                if ma == 0:
                    continue
                z_f, nu_f = ms.z[j], ms.nu[j]
                f.pending = (z_f[a].copy(), z_f[a] - nu_f[a], ms.H[j][a].copy(),
                             np.diag(ms.r[j][a]))  # fmt: skip
                ll = kv.log_likelihood(nu_f, ms.S[j], gw.acc, ma)
                f._lik = float(kv.likelihood(ll, vs.likelihood_floor))
        if imm_on:
            imm.update(None)
            x, P = np.asarray(imm.x, dtype=float), np.asarray(imm.P, dtype=float)
            aux = float(imm.mu[1])
        else:
            f = filters[0]
            if f.pending is not None:
                f.update()
            x, P = np.asarray(f.x, dtype=float), np.asarray(f.P, dtype=float)
            aux = float(f.model)
        ok = True
        for f in filters:
            Pf = np.ascontiguousarray(f.P, dtype=float)
            ok = bool(gt.keep_pd(Pf, vm.NX, L, t, ev_i, ev_f, counts)) and ok
            f.P = Pf
        if not imm_on:
            P = np.asarray(filters[0].P, dtype=float)
        status = int(kv.check(np.ascontiguousarray(x), np.ascontiguousarray(P), vs)) if ok else 3
        if status != gt.STATUS_OK:
            return int(gt.fail(t, status, ev_i, ev_f, counts))
        if stops[k, kv.VS_OUT] > 0:
            kv._record(t, np.ascontiguousarray(x), np.ascontiguousarray(P), aux, log, out_aux)
        counts[rl.CNT_STOP] = k + 1
    return gt.STATUS_OK
