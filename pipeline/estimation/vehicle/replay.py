"""Vehicle-model filters (paper 003): canonical tables in, a ``VehicleRunResult`` out.

Inputs: the ``vehicle`` table (wheel speed, steering angle, yaw rate) and GPS fixes (the
``gnss`` table: position, and NED velocity for speed and course where present). Positions
become north/east metres of a local map (``nav.local.LocalFrame``) at the first usable fix.

Logs without a steering angle (smartLoc: speed and yaw rate only) drive each model with a
*virtual* steering angle, the one for which that model's steady-state yaw rate equals the
measured one: ``atan(L r / v)`` for the kinematic model, ``r D / (v (c1 - c2 b / a))`` for the
dynamic one (``vehicle.model``). The yaw rate is then an input and is not fused again as a
measurement (that would count it twice).

The schedule is the union of the vehicle samples and the fixes; the filter starts at the first
fix that can give a heading (GPS course above ``course_min_speed_mps``, or two fixes at least
``init.align_distance_m`` apart) and outputs on a grid of ``output_interval_s``.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pyarrow as pa

from navreplay.pipeline.distributions import chi2_ppf
from navreplay.pipeline.errors import DivergenceError
from navreplay.pipeline.estimation.core import gating as gt
from navreplay.pipeline.estimation.core import runlog as rl
from navreplay.pipeline.estimation.core import tables as tb
from navreplay.pipeline.estimation.core.contract import Backend
from navreplay.pipeline.estimation.core.runlog import RunLog
from navreplay.pipeline.estimation.core.tables import ReplayInputError
from navreplay.pipeline.estimation.vehicle import kernel as kv
from navreplay.pipeline.estimation.vehicle import model as vm
from navreplay.pipeline.estimation.vehicle.config import VehicleFilterParams
from navreplay.pipeline.nav.earth import F64, I64
from navreplay.pipeline.nav.local import LocalFrame

log = logging.getLogger(__name__)

MAX_STEER_RAD = 0.6


@dataclass
class VehicleRunResult:
    """One vehicle-filter run.

    Attributes:
        filter, backend: names. t_ns (K,), x (K, 5), P (K, 5, 5): outputs (``vehicle.model``).
        aux: (K,) probability of the dynamic model (IMM) or the model in use (1 = dynamic).
        origin: the local map of X (north) and Y (east).
        inn_i, inn_f: innovation rows (``core.gating``; streams ``vehicle.kernel``).
        events: skipped inputs, rejections, repairs, divergence.
        steer_source: ``steering`` (logged) or ``yaw_rate`` (virtual steering).
        init: how the filter started.
    """

    filter: str
    backend: str
    t_ns: I64
    x: F64
    P: F64
    aux: F64
    origin: LocalFrame
    inn_i: I64
    inn_f: F64
    events: list[tb.Event]
    steer_source: str
    init: dict[str, Any] = field(default_factory=dict)
    status: str = "ok"
    failure: str | None = None
    runtime_s: float = 0.0
    duration_s: float = 0.0


@dataclass(frozen=True)
class VehicleData:
    """The arrays of one run (``vehicle.kernel`` layouts) and the local map."""

    veh_t: I64
    veh: F64
    fix_t: I64
    fix: F64
    origin: LocalFrame
    steer_source: str
    events: tuple[tb.Event, ...]


def virtual_steering(v_mps: F64, r_radps: F64, vp: F64) -> tuple[F64, F64]:
    """Per-model steering whose steady-state yaw rate is ``r`` (kinematic, dynamic), rad."""
    v = np.maximum(v_mps, vm.V_MIN)
    wheelbase = vp[vm.VP_LF] + vp[vm.VP_LR]
    d_kin = np.arctan(wheelbase * r_radps / v)
    d_dyn = np.empty_like(v)
    for k in range(v.size):
        a, b, c1d, c2d, _ = vm.dyn_coefficients(float(v[k]), vp)
        gain = c1d - c2d * b / a  # steady state: beta = -b/a delta, r = v_cg gain delta
        d = r_radps[k] / (v[k] * gain)
        for _ in range(4):  # the state's speed is the CG speed v_whl / cos(beta)
            d = r_radps[k] * math.cos(-b / a * d) / (v[k] * gain)
        d_dyn[k] = d
    clip = MAX_STEER_RAD
    return np.clip(d_kin, -clip, clip), np.clip(d_dyn, -clip, clip)


def vehicle_vector(params: VehicleFilterParams) -> F64:
    """``vehicle.model`` packing of the car's parameters."""
    v = params.vehicle
    out = np.empty(vm.VP_DIM)
    out[vm.VP_LF], out[vm.VP_LR], out[vm.VP_M] = v.cg_to_front_m, v.cg_to_rear_m, v.mass_kg
    out[vm.VP_CF] = v.cornering_stiffness_front_npr
    out[vm.VP_CR] = v.cornering_stiffness_rear_npr
    return out


def prepare(tables: Mapping[str, pa.Table], params: VehicleFilterParams, name: str) -> VehicleData:
    """The data barrier: vehicle samples and fixes as kernel arrays (NaN rows skipped)."""
    for need in ("vehicle", "gnss"):
        if need not in tables or tables[need].num_rows == 0:
            raise ReplayInputError(f"filter {name} needs the {need!r} table, which is absent")
    vt = tables["vehicle"]
    t = np.asarray(vt.column("t_ns").to_numpy(), dtype=np.int64)
    speed = tb.float_column(vt, "speed_mps")
    steer = tb.float_column(vt, "steer_rad")
    yaw = tb.float_column(vt, "yaw_rate_radps")
    events: list[tb.Event] = []
    ok = np.isfinite(speed) & (np.isfinite(steer) | np.isfinite(yaw))
    for k in np.flatnonzero(~ok):
        events.append(tb.Event(int(t[k]), "skip_invalid", "vehicle"))
    order = np.argsort(t[ok], kind="stable")
    t, speed, steer, yaw = t[ok][order], speed[ok][order], steer[ok][order], yaw[ok][order]
    keep = np.r_[True, np.diff(t) > 0]
    t, speed, steer, yaw = t[keep], speed[keep], steer[keep], yaw[keep]
    vp = vehicle_vector(params)
    veh = np.zeros((t.size, kv.VH_COLS))
    veh[:, kv.VH_V] = speed
    if np.isfinite(steer).any():
        source = "steering"
        steer = np.where(np.isfinite(steer), steer, 0.0)
        veh[:, kv.VH_D_KIN] = veh[:, kv.VH_D_DYN] = steer
        veh[:, kv.VH_YAW] = np.where(np.isfinite(yaw), yaw, 0.0)
        veh[:, kv.VH_YAW_OK] = np.isfinite(yaw).astype(float)
    else:
        source = "yaw_rate"
        veh[:, kv.VH_D_KIN], veh[:, kv.VH_D_DYN] = virtual_steering(speed, yaw, vp)
    fix_t, fix, origin = _fixes(tables["gnss"], params)
    return VehicleData(t, veh, fix_t, fix, origin, source, tuple(events))


def _fixes(table: pa.Table, params: VehicleFilterParams) -> tuple[I64, F64, LocalFrame]:
    g = params.gnss
    t = np.asarray(table.column("t_ns").to_numpy(), dtype=np.int64)
    lat, lon = tb.float_column(table, "lat_deg"), tb.float_column(table, "lon_deg")
    fix_type = tb.float_column(table, "fix_type", 0.0)
    pos_ok = np.isfinite(lat) & np.isfinite(lon) & (fix_type >= 2)
    vn, ve = tb.float_column(table, "vel_n_mps"), tb.float_column(table, "vel_e_mps")
    vel_ok = np.isfinite(vn) & np.isfinite(ve) & (fix_type >= 2)
    if not pos_ok.any():
        raise ReplayInputError("the gnss table has no usable position fix")
    k0 = int(np.flatnonzero(pos_ok)[0])
    alt = tb.float_column(table, "alt_m")
    origin = LocalFrame(
        float(lat[k0]), float(lon[k0]), float(alt[k0]) if np.isfinite(alt[k0]) else 0.0
    )
    n, e, _ = origin.to_ned(lat, lon, origin.alt_m)
    h_acc, s_acc = tb.float_column(table, "h_acc_m"), tb.float_column(table, "speed_acc_mps")
    sig_pos = np.maximum(
        np.where(np.isfinite(h_acc), h_acc, g.pos_sigma_default_m), g.pos_sigma_floor_m
    )
    sig_v = np.maximum(
        np.where(np.isfinite(s_acc), s_acc, g.vel_sigma_default_mps), g.vel_sigma_floor_mps
    )
    speed = np.hypot(vn, ve)
    fix = np.zeros((t.size, kv.FX_COLS))
    fix[:, kv.FX_N], fix[:, kv.FX_E] = n, e
    fix[:, kv.FX_SPEED], fix[:, kv.FX_COURSE] = speed, np.arctan2(ve, vn)
    fix[:, kv.FX_SIG_POS], fix[:, kv.FX_SIG_SPEED] = sig_pos, sig_v
    fix[:, kv.FX_SIG_COURSE] = sig_v / np.maximum(speed, g.course_min_speed_mps)
    fix[:, kv.FX_POS_OK] = pos_ok
    fix[:, kv.FX_SPEED_OK] = vel_ok & g.use_speed
    fix[:, kv.FX_COURSE_OK] = vel_ok & (speed >= g.course_min_speed_mps) & g.use_course
    fix[~np.isfinite(fix)] = 0.0
    usable = pos_ok | vel_ok
    order = np.argsort(t[usable], kind="stable")
    return t[usable][order], np.ascontiguousarray(fix[usable][order]), origin


def initial_state(
    data: VehicleData, params: VehicleFilterParams
) -> tuple[int, F64, F64, dict[str, Any]] | None:
    """(start time, x0, P0, description) at the first fix that gives a heading, or None."""
    fx, ft = data.fix, data.fix_t
    ini = params.init
    for k in range(ft.size):
        if not fx[k, kv.FX_POS_OK]:
            continue
        heading, sig_h, how = math.nan, math.nan, ""
        if fx[k, kv.FX_COURSE_OK]:
            heading, sig_h, how = fx[k, kv.FX_COURSE], fx[k, kv.FX_SIG_COURSE], "gps_course"
        else:
            heading, sig_h, how = _heading_from_fixes(data, k, ini.align_distance_m,
                                                      ini.align_window_s)  # fmt: skip
        if not math.isfinite(heading):
            continue
        i = int(np.searchsorted(data.veh_t, ft[k], side="right")) - 1
        if i < 0:
            continue
        v = float(data.veh[i, kv.VH_V])
        x0 = np.array([v, 0.0, heading, fx[k, kv.FX_N], fx[k, kv.FX_E]])
        sig = [ini.speed_sigma_mps, ini.slip_sigma_rad, max(sig_h, ini.heading_sigma_floor_rad)]
        sig += [fx[k, kv.FX_SIG_POS]] * 2
        P0 = np.diag(np.square(sig))
        desc = {"t_ns": int(ft[k]), "heading_from": how, "heading_rad": heading,
                "heading_sigma_rad": sig[2]}  # fmt: skip
        return int(ft[k]), x0, P0, desc
    return None


def _heading_from_fixes(
    data: VehicleData, k: int, min_dist_m: float, window_s: float
) -> tuple[float, float, str]:
    """Heading from the displacement between fix ``k`` and an earlier fix, or NaN.

    The pair must be at least ``min_dist_m`` apart by the wheel odometer, at most
    ``window_s`` apart in time, and the fixes' displacement must agree with the odometer
    distance within half of it (a straight stretch with fixes that are not outliers).
    """
    fx, ft = data.fix, data.fix_t
    vt, v = data.veh_t, data.veh[:, kv.VH_V]
    odo = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(vt) * 1e-9)])
    at_k = float(np.interp(ft[k], vt, odo))
    for j in range(k - 1, -1, -1):
        if (ft[k] - ft[j]) * 1e-9 > window_s:
            break
        if not fx[j, kv.FX_POS_OK]:
            continue
        travelled = at_k - float(np.interp(ft[j], vt, odo))
        if travelled < min_dist_m:
            continue
        dn, de = fx[k, kv.FX_N] - fx[j, kv.FX_N], fx[k, kv.FX_E] - fx[j, kv.FX_E]
        dist = math.hypot(dn, de)
        if abs(dist - travelled) > 0.5 * travelled:
            continue
        sig = math.hypot(fx[k, kv.FX_SIG_POS], fx[j, kv.FX_SIG_POS]) / dist
        return math.atan2(de, dn), sig, "fix_displacement"
    return math.nan, math.nan, ""


def schedule(t0: int, data: VehicleData, output_s: float) -> I64:
    """Stops after ``t0``: every vehicle sample and fix, with output flags on the grid."""
    vt = data.veh_t[data.veh_t > t0]
    ft = data.fix_t[data.fix_t > t0]
    all_t = np.union1d(vt, ft)
    stops = np.full((all_t.size, kv.VS_COLS), -1, dtype=np.int64)
    stops[:, kv.VS_T] = all_t
    for col, ts in ((kv.VS_VEH, data.veh_t), (kv.VS_FIX, data.fix_t)):
        idx = np.searchsorted(ts, all_t)
        hit = (idx < ts.size) & (ts[np.minimum(idx, ts.size - 1)] == all_t)
        stops[hit, col] = idx[hit]
    cell = (all_t - t0) // round(output_s * 1e9)
    stops[:, kv.VS_OUT] = np.r_[cell[0] > 0, np.diff(cell) > 0].astype(np.int64)
    return stops


def make_settings(name: str, params: VehicleFilterParams) -> kv.VehicleSettings:
    """The kernel's settings of vehicle filter ``name``."""
    n, s, im = params.noise, params.switching, params.imm
    q = np.array([n.speed_psd_m2ps3, n.slip_psd_rad2ps, n.heading_psd_rad2ps,
                  n.position_psd_m2ps, n.position_psd_m2ps])  # fmt: skip
    gate = np.array([math.inf] + [chi2_ppf(params.gate_probability, d) for d in (1, 2, 3)])
    return kv.VehicleSettings(
        vp=vehicle_vector(params),
        q=q,
        gate=gate,
        mode=int(kv.MODE_NAMES[name]),
        max_step_s=float(params.max_step_s),
        v_up_mps=float(s.speed_up_mps),
        v_down_mps=float(s.speed_down_mps),
        sig_wheel_speed_mps=float(n.wheel_speed_sigma_mps),
        sig_steer_rad=float(n.steer_sigma_rad),
        sig_yaw_rate_radps=float(n.yaw_rate_sigma_radps),
        p_stay_kinematic=float(im.p_stay_kinematic),
        p_stay_dynamic=float(im.p_stay_dynamic),
        mu0_dynamic=float(im.mu0_dynamic),
        max_pos_sigma_m=float(params.max_pos_sigma_m),
        likelihood_floor=float(im.likelihood_floor),
        timeout_s=float(params.gate_timeout_s),
    )


KernelFn = Callable[..., int]


def _kernel(backend: Backend) -> KernelFn:
    if backend == "numba":
        return kv.run_vehicle
    from navreplay.pipeline.estimation.vehicle.reference import run_vehicle_filterpy

    return run_vehicle_filterpy


def run_vehicle_filter(
    tables: Mapping[str, pa.Table],
    name: str,
    params: VehicleFilterParams,
    *,
    backend: Backend = "numba",
) -> VehicleRunResult:
    """Replay vehicle filter ``name`` (a key of ``vehicle.kernel.MODE_NAMES``).

    Raises:
        ReplayInputError: no vehicle or gnss table, or no fix to start from.
        DivergenceError: the filter diverged and ``on_divergence`` is ``raise``.
    """
    t_wall = time.perf_counter()
    data = prepare(tables, params, name)
    start = initial_state(data, params)
    if start is None:
        raise ReplayInputError(f"filter {name}: no GPS fix gives an initial heading")
    t0, x0, P0, desc = start
    stops = schedule(t0, data, params.output_interval_s)
    i0 = int(np.searchsorted(data.veh_t, t0, side="right")) - 1
    n_out = int(stops[:, kv.VS_OUT].sum()) + 1
    n_inn = len(stops) * kv.M_MAX
    n_ev = n_inn + 2 * len(stops) + 16
    sched = kv.VehicleSchedule(int(t0), data.veh[i0].copy(), stops, data.veh, data.fix)
    vs = make_settings(name, params)
    kernel = _kernel(backend)

    def run(log_: RunLog) -> tuple[int, F64]:
        out_aux = np.zeros(log_.capacity()[0])
        return kernel(x0, P0, sched, vs, log_, out_aux), out_aux

    first = RunLog.allocate(n_out, n_inn, n_ev, vm.NX, vm.NX)
    (code, out_aux), log_ = first.run_growing(run)
    out_t, out_x, out_P, inn_i, inn_f, ev_i, ev_f, counts = log_
    k_out, k_inn, k_ev = log_.wanted()
    events = list(data.events) + [
        tb.Event(
            int(ev_i[j, 0]),
            gt.EVENT_NAMES.get(int(ev_i[j, 1]), str(ev_i[j, 1])),
            kv.STREAM_NAMES[ev_i[j, 2]] if ev_i[j, 2] >= 0 else "",
            "",
            float(ev_f[j]),
        )
        for j in range(k_ev)
    ]
    events.sort(key=lambda e: e.t_ns)
    status, failure = "ok", None
    if code != gt.STATUS_OK:
        failure = f"{gt.STATUS_TEXT[int(code)]} at t_ns={int(counts[rl.CNT_T_FAIL])}"
        status = "diverged"
        if params.on_divergence == "raise":
            raise DivergenceError(f"filter {name} ({backend}) diverged: {failure}")
        log.warning("filter %s diverged: %s", name, failure)
    return VehicleRunResult(
        filter=name,
        backend=backend,
        t_ns=out_t[:k_out],
        x=out_x[:k_out],
        P=out_P[:k_out],
        aux=out_aux[:k_out],
        origin=data.origin,
        inn_i=inn_i[:k_inn],
        inn_f=inn_f[:k_inn],
        events=events,
        steer_source=data.steer_source,
        init=desc,
        status=status,
        failure=failure,
        runtime_s=time.perf_counter() - t_wall,
        duration_s=(int(out_t[k_out - 1]) - t0) * 1e-9 if k_out else 0.0,
    )
