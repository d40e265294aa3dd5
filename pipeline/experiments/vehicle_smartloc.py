"""Paper 003's vehicle filters on the real smartLoc drive (Berlin, Potsdamer Platz).

smartLoc gives pseudoranges (GPS and GLONASS, satellite ECEF positions, satellite clock and
atmosphere already removed), car odometry (forward speed and yaw rate, no steering angle) and
a reference trajectory, all at about 5 Hz.

**Position fixes.** The vehicle models measure X and Y (paper 003 eq. 20), so each epoch's
pseudoranges become a fix by weighted least squares (``spp_fixes``): receiver ECEF position
plus one clock bias per constellation (GPS and GLONASS clocks differ), weights from the
dataset's pseudorange variances, and a residual test that drops the worst satellite while its
normalized residual exceeds 3 and more than six remain (urban canyon: reflected signals). The
fix's horizontal accuracy is the solution covariance. Fixes rather than pseudoranges in the
filter: the paper's measurement model is a position fix, the models are planar (no height or
clock states), and a tightly coupled variant would need three more states per constellation.
The receiver gives no Doppler, so the GPS speed and course of eq. 20 are absent.

**No steering angle.** Each model is driven by the virtual steering for which its steady-state
yaw rate equals the measured yaw rate (``vehicle.replay.virtual_steering``); the yaw rate is
then an input and not fused again.

**Truth.** The reference gives positions only; its speed (for the speed bands) is the central
difference of consecutive positions.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import replace
from typing import Any

import numpy as np
import pyarrow as pa

from navreplay.ingest.schema import FixType, from_columns
from navreplay.pipeline.estimation.config import FiltersParams
from navreplay.pipeline.estimation.core.contract import Backend
from navreplay.pipeline.estimation.vehicle.config import VEHICLE_FILTERS, VehicleFilterParams
from navreplay.pipeline.estimation.vehicle.metrics import errors, per_band, summarize
from navreplay.pipeline.estimation.vehicle.replay import run_vehicle_filter
from navreplay.pipeline.experiments.gnss_outages import drop_fixes, in_windows, periodic_windows
from navreplay.pipeline.nav.earth import dcm_ecef_to_ned, ecef_to_geodetic, geodetic_to_ecef

SMARTLOC_EDGES_MPS = (0.0, 2.5, 5.0, 10.0)
MIN_SATS = 6
#: the fixes' own covariance ignores multipath and reflections (their error against the
#: reference is ~25 m median where the covariance says ~5 m): floor the fix accuracy and
#: take the initial heading over a longer baseline
FIX_SIGMA_FLOOR_M = 20.0
ALIGN_DISTANCE_M = 60.0
ALIGN_WINDOW_S = 30.0


def smartloc_params(section: VehicleFilterParams) -> VehicleFilterParams:
    """A vehicle filter section adapted to the smartLoc fixes (see ``FIX_SIGMA_FLOOR_M``)."""
    return replace(
        section,
        gnss=replace(section.gnss, pos_sigma_floor_m=FIX_SIGMA_FLOOR_M),
        init=replace(section.init, align_distance_m=ALIGN_DISTANCE_M,
                     align_window_s=ALIGN_WINDOW_S),
    )  # fmt: skip


def _col(t: pa.Table, name: str) -> np.ndarray:
    return np.asarray(t.column(name).to_numpy(zero_copy_only=False), dtype=np.float64)


def _solve(sat: np.ndarray, pr: np.ndarray, w: np.ndarray, sys_idx: np.ndarray, k: int,
           x0: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """Gauss-Newton WLS for [x, y, z, clock per system]; returns (x, covariance, residuals)."""
    x = x0.copy()
    for _ in range(10):
        d = sat - x[:3]
        rng = np.linalg.norm(d, axis=1)
        H = np.zeros((pr.size, 3 + k))
        H[:, :3] = -d / rng[:, None]
        H[np.arange(pr.size), 3 + sys_idx] = 1.0
        res = pr - rng - x[3 + sys_idx]
        N = H.T @ (H * w[:, None])
        step = np.linalg.solve(N, H.T @ (w * res))
        x += step
        if np.linalg.norm(step[:3]) < 1e-4:
            break
    d = sat - x[:3]
    res = pr - np.linalg.norm(d, axis=1) - x[3 + sys_idx]
    return x, np.linalg.inv(N), res


def spp_fixes(gnss_obs: pa.Table) -> pa.Table:
    """A canonical ``gnss`` table of least-squares fixes, one per epoch with enough satellites
    (see the module docstring); epochs that cannot be solved are left out."""
    t = np.asarray(gnss_obs.column("t_ns").to_numpy(), dtype=np.int64)
    sv = np.array(gnss_obs.column("sv").to_pylist())
    sat = np.column_stack([_col(gnss_obs, f"sat_{a}_m") for a in "xyz"])
    pr = _col(gnss_obs, "pseudorange_m")
    std = _col(gnss_obs, "pseudorange_std_m")
    systems = sorted({s[0] for s in sv})
    sys_all = np.array([systems.index(s[0]) for s in sv])
    out: dict[str, list[float]] = {k: [] for k in ("t", "lat", "lon", "alt", "h", "v", "n")}
    x_prev = np.zeros(3 + len(systems))
    for te in np.unique(t):
        sel = np.flatnonzero((t == te) & np.isfinite(pr))
        while sel.size >= MIN_SATS:
            used = sorted(set(sys_all[sel]))
            k = len(used)
            idx = np.searchsorted(used, sys_all[sel])
            x0 = np.r_[x_prev[:3], np.zeros(k)]
            if not np.any(x0[:3]):
                x0[:3] = sat[sel].mean(axis=0) * 6.4e6 / np.linalg.norm(sat[sel].mean(axis=0))
            x, cov, res = _solve(sat[sel], pr[sel], 1.0 / std[sel] ** 2, idx, k, x0)
            z = np.abs(res) / std[sel]
            if z.max() > 3.0 and sel.size > MIN_SATS:
                sel = np.delete(sel, int(np.argmax(z)))
                continue
            lat, lon, alt = ecef_to_geodetic(x[0], x[1], x[2])
            c = dcm_ecef_to_ned(lat, lon)
            q = c @ cov[:3, :3] @ c.T
            out["t"].append(te)
            out["lat"].append(math.degrees(lat))
            out["lon"].append(math.degrees(lon))
            out["alt"].append(alt)
            out["h"].append(math.sqrt(0.5 * (q[0, 0] + q[1, 1])))
            out["v"].append(math.sqrt(q[2, 2]))
            out["n"].append(sel.size)
            x_prev = np.r_[x[:3], np.zeros(len(systems))]
            break
    m = len(out["t"])
    return from_columns(
        "gnss",
        {"t_ns": np.array(out["t"], np.int64), "lat_deg": np.array(out["lat"]),
         "lon_deg": np.array(out["lon"]), "alt_m": np.array(out["alt"]),
         "h_acc_m": np.array(out["h"]), "v_acc_m": np.array(out["v"]),
         "fix_type": np.full(m, FixType.FIX_3D, np.int8), "num_sats": np.array(out["n"], float)},
    )  # fmt: skip


def with_truth_velocity(truth: pa.Table) -> pa.Table:
    """The truth with NED velocity from central differences of its ECEF positions."""
    t = np.asarray(truth.column("t_ns").to_numpy(), dtype=np.int64) * 1e-9
    lat, lon, alt = (
        np.radians(_col(truth, "lat_deg")),
        np.radians(_col(truth, "lon_deg")),
        _col(truth, "alt_m"),
    )
    ecef = np.array([geodetic_to_ecef(a, b, h) for a, b, h in zip(lat, lon, alt, strict=True)])
    v = np.gradient(ecef, t, axis=0)
    ned = np.array([dcm_ecef_to_ned(a, b) @ vv for a, b, vv in zip(lat, lon, v, strict=True)])
    for j, axis in enumerate("ned"):
        name = f"vel_{axis}_mps"
        truth = truth.set_column(truth.column_names.index(name), name, pa.array(ned[:, j]))
    return truth


def smartloc_rows(
    tables: Mapping[str, pa.Table], filters: FiltersParams, *,
    outage: tuple[float, float, float] = (30.0, 60.0, 10.0), backend: Backend = "numba",
) -> list[dict[str, Any]]:  # fmt: skip
    """Per scenario (nominal, outages), filter and speed band: RMS errors against the truth."""
    fixes = spp_fixes(tables["gnss_obs"])
    truth = with_truth_velocity(tables["truth"])
    base = {"vehicle": tables["vehicle"], "gnss": fixes}
    tf = np.asarray(fixes.column("t_ns").to_numpy(), dtype=np.int64)
    windows = periodic_windows(tf, *outage)
    rows: list[dict[str, Any]] = []
    for scen, tabs, win in (("nominal", base, []), ("outages", drop_fixes(base, windows), windows)):
        for name in VEHICLE_FILTERS:
            res = run_vehicle_filter(
                tabs, name, smartloc_params(filters.vehicle(name)), backend=backend
            )
            err = errors(res, truth)
            subsets: dict[str, np.ndarray | None] = {"all": None}
            if win:
                subsets["in_outage"] = in_windows(err["t_ns"], win)
            for subset, mask in subsets.items():
                rows.append({"scenario": scen, "filter": name, "subset": subset,
                             "band_lo_mps": 0.0, "band_hi_mps": math.inf, **summarize(err, mask),
                             "dynamic_share": float(np.mean(res.aux))})  # fmt: skip
                for row in per_band(err, SMARTLOC_EDGES_MPS, mask):
                    rows.append({"scenario": scen, "filter": name, "subset": subset, **row})
    spp_err = errors_of_fixes(fixes, truth)
    rows.append({"scenario": "spp_fixes", "filter": "least_squares", "subset": "all",
                 "band_lo_mps": 0.0, "band_hi_mps": math.inf, "samples": int(spp_err.size),
                 "pos_h_rms_m": float(np.sqrt(np.mean(spp_err**2))),
                 "pos_h_max_m": float(spp_err.max())})  # fmt: skip
    return rows


def errors_of_fixes(fixes: pa.Table, truth: pa.Table) -> np.ndarray:
    """Horizontal error of the least-squares fixes against the truth, m."""
    from navreplay.pipeline.estimation.core.tables import truth_at
    from navreplay.pipeline.nav.local import LocalFrame

    t = np.asarray(fixes.column("t_ns").to_numpy(), dtype=np.int64)
    inside, tr = truth_at(truth, t)
    lat, lon = _col(fixes, "lat_deg")[inside], _col(fixes, "lon_deg")[inside]
    o = LocalFrame(float(lat[0]), float(lon[0]), 0.0)
    n1, e1, _ = o.to_ned(lat, lon, 0.0)
    n2, e2, _ = o.to_ned(tr["lat_deg"], tr["lon_deg"], 0.0)
    return np.asarray(np.hypot(n1 - n2, e1 - e2))
