"""Partial outages: keep ``k`` satellites inside each window, by a named policy.

The set is chosen at the first epoch of each window from the satellites above the selection
mask, in the order the policy gives (``policy_order``), and kept through the window; a chosen
satellite that disappears is replaced by the next one in that order (satellites that rise
during the window rank after it, highest first). Satellites below the mask are dropped inside
windows too, so exactly ``min(k, visible)`` reach a tightly coupled filter.

``refix`` recomputes the receiver fixes of the windows from the kept pseudoranges and rates by
single-point positioning (``ingest.gnss.spp``), as a receiver tracking only those satellites would
report them: accuracy from the solution covariance, ``num_sats = k``. With fewer than four
satellites a receiver has no fix; those rows are removed by the caller.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
import pyarrow as pa

from navreplay.ingest.gnss import spp
from navreplay.pipeline.estimation.core.tables import float_column
from navreplay.pipeline.estimation.ins.inputs import corrected_observables
from navreplay.pipeline.nav import earth
from navreplay.pipeline.nav.earth import F64, I64
from navreplay.pipeline.scenarios.config import Policy

#: Above this many subsets the DOP policies choose greedily instead of exhaustively.
MAX_SUBSETS = 20_000


@dataclass(frozen=True)
class Selection:
    """The satellites chosen for one window (at its first epoch)."""

    window: int
    svs: tuple[str, ...]
    elevation_deg: tuple[float, ...]
    gdop: float | None  # None below four satellites

    def to_json(self) -> dict[str, object]:
        return {
            "window": self.window,
            "svs": list(self.svs),
            "elevation_deg": [round(e, 2) for e in self.elevation_deg],
            "gdop": self.gdop,
        }


def los_rows(el_deg: F64, az_deg: F64) -> F64:
    """Geometry rows ``[e_n, e_e, e_d, 1]`` (receiver-to-satellite unit vector in NED, clock).

    Shape (n, 4) for n elevations and azimuths in degrees.
    """
    el, az = np.radians(el_deg), np.radians(az_deg)
    return np.column_stack(
        [np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), -np.sin(el), np.ones(el.size)]
    )


def gdop(G: F64) -> float:
    """Geometric DOP of geometry rows G (n >= 4); inf for a singular geometry."""
    N = G.T @ G
    if np.linalg.cond(N) > 1e12:
        return math.inf
    return float(math.sqrt(np.trace(np.linalg.inv(N))))


def _spread(G: F64) -> float:
    """The geometry score the DOP policies optimize: 1/GDOP (n >= 4), else det(G G^T)."""
    if G.shape[0] >= 4:
        d = gdop(G)
        return 0.0 if math.isinf(d) else 1.0 / d
    return float(np.linalg.det(G @ G.T))


def _dop_subset(G: F64, k: int, best: bool) -> list[int]:
    """Indices of the k rows of G with the best (largest) or worst (smallest) spread."""
    n = G.shape[0]
    sign = 1.0 if best else -1.0
    if math.comb(n, k) <= MAX_SUBSETS:
        subsets = itertools.combinations(range(n), k)
        return list(max(subsets, key=lambda s: sign * _spread(G[list(s)])))
    chosen: list[int] = []  # greedy: add the row that improves the score most
    for _ in range(k):
        rest = [j for j in range(n) if j not in chosen]
        chosen.append(max(rest, key=lambda j: sign * _spread(G[[*chosen, j]])))
    return chosen


def policy_order(
    el_deg: F64, az_deg: F64, k: int, policy: Policy, rng: np.random.Generator
) -> list[int]:
    """Order of preference of the candidate satellites (indices into the arrays).

    The first ``k`` are the chosen set: highest or lowest elevation, a random permutation,
    or the subset with the best or worst geometry (``_spread``); the rest follow by
    elevation, highest first (lowest first for ``lowest_elevation``).
    """
    by_el = [int(j) for j in np.argsort(-el_deg, kind="stable")]
    if policy == "highest_elevation":
        return by_el
    if policy == "lowest_elevation":
        return by_el[::-1]
    if policy == "random":
        return [int(j) for j in rng.permutation(el_deg.size)]
    if k == 0 or k >= el_deg.size:
        return by_el
    chosen = _dop_subset(los_rows(el_deg, az_deg), k, best=policy == "best_dop")
    chosen.sort(key=lambda j: -el_deg[j])
    return chosen + [j for j in by_el if j not in chosen]


def select(
    t_ns: I64,
    sv: np.ndarray,
    el_deg: F64,
    az_deg: F64,
    windows: list[tuple[int, int]],
    k: int,
    policy: Policy,
    seed: int,
    mask_deg: float,
) -> tuple[np.ndarray, list[Selection]]:
    """Rows of a ``gnss_obs`` table to keep, and the set chosen per window.

    Args:
        t_ns, sv, el_deg, az_deg: the table's columns (NaN elevation: never kept in windows).
        windows: ``[start, end)`` ns.
        k: satellites to keep; policy, seed: the policy and the random policy's seed.
        mask_deg: selection mask.

    Returns:
        (boolean keep mask over the rows, one ``Selection`` per window with epochs).
    """
    keep = np.ones(t_ns.size, dtype=bool)
    selections: list[Selection] = []
    visible = np.isfinite(el_deg) & (el_deg >= mask_deg)
    for w, (a, b) in enumerate(windows):
        rows = np.flatnonzero((t_ns >= a) & (t_ns < b))
        keep[rows] = False
        if rows.size == 0 or k == 0:
            continue
        first = rows[(t_ns[rows] == t_ns[rows[0]]) & visible[rows]]
        order = policy_order(
            el_deg[first], az_deg[first], k, policy, np.random.default_rng([seed, w])
        )
        rank = {str(sv[first[j]]): r for r, j in enumerate(order)}
        chosen = [first[j] for j in order[:k]]
        G = los_rows(el_deg[chosen], az_deg[chosen])
        selections.append(
            Selection(
                w,
                tuple(str(sv[j]) for j in chosen),
                tuple(float(el_deg[j]) for j in chosen),
                gdop(G) if len(chosen) >= 4 else None,
            )
        )
        for t in np.unique(t_ns[rows]):
            ep = rows[(t_ns[rows] == t) & visible[rows]]
            late = len(rank) + np.argsort(np.argsort(-el_deg[ep], kind="stable"))
            score = np.array([rank.get(str(sv[j]), late[i]) for i, j in enumerate(ep)])
            keep[ep[np.argsort(score, kind="stable")[:k]]] = True
    return keep, selections


def refix(fix_t_ns: I64, obs: pa.Table, x0_ecef: F64) -> tuple[np.ndarray, dict[str, F64]]:
    """Single-point fixes at ``fix_t_ns`` from the observations of the same epochs.

    Args:
        fix_t_ns: times of the fixes to recompute (each must equal an epoch of ``obs``).
        obs: the kept ``gnss_obs`` rows.
        x0_ecef: (len(fix_t_ns), 3) initial receiver positions (the original fixes).

    Returns:
        (ok mask, columns of the ``gnss`` table for the ok rows: lat_deg, lon_deg, alt_m,
        vel_{n,e,d}_mps, h_acc_m, v_acc_m, speed_acc_mps, num_sats).
    """
    t = np.asarray(obs.column("t_ns").to_numpy(), dtype=np.int64)
    sat = np.column_stack([float_column(obs, f"sat_{a}_m") for a in "xyz"])
    sat_v = np.column_stack([float_column(obs, f"sat_v{a}_mps") for a in "xyz"])
    pr, prr = corrected_observables(obs)
    sig = float_column(obs, "pseudorange_std_m", 3.0)
    sig_r = float_column(obs, "pseudorange_rate_std_mps", 0.1)
    n = fix_t_ns.size
    cols = {
        c: np.full(n, math.nan)
        for c in ("lat_deg", "lon_deg", "alt_m", "vel_n_mps", "vel_e_mps", "vel_d_mps")
    }
    cols |= {c: np.full(n, math.nan) for c in ("h_acc_m", "v_acc_m", "speed_acc_mps")}
    cols["num_sats"] = np.zeros(n)
    ok = np.zeros(n, dtype=bool)
    for i, tf in enumerate(fix_t_ns):
        r = np.flatnonzero((t == tf) & np.isfinite(pr))
        if r.size < 4:
            continue
        x0 = np.append(x0_ecef[i], 0.0)
        x, cov, _, conv = spp.solve_position(sat[r], pr[r], 1.0 / sig[r] ** 2, x0, 10, 1e-4)
        if not conv:
            continue
        lat, lon, h = earth.ecef_to_geodetic(x[0], x[1], x[2])
        c_en = earth.dcm_ecef_to_ned(lat, lon)
        q_ned = c_en @ cov[:3, :3] @ c_en.T
        cols["lat_deg"][i], cols["lon_deg"][i], cols["alt_m"][i] = (
            math.degrees(lat),
            math.degrees(lon),
            h,
        )
        cols["h_acc_m"][i] = math.sqrt(0.5 * (q_ned[0, 0] + q_ned[1, 1]))
        cols["v_acc_m"][i] = math.sqrt(q_ned[2, 2])
        cols["num_sats"][i] = r.size
        rv = r[np.isfinite(prr[r]) & np.isfinite(sat_v[r]).all(axis=1)]
        if rv.size >= 4:
            v, cov_v = spp.solve_velocity(sat[rv], sat_v[rv], prr[rv], 1.0 / sig_r[rv] ** 2, x[:3])
            v_ned = c_en @ v[:3]
            cols["vel_n_mps"][i], cols["vel_e_mps"][i], cols["vel_d_mps"][i] = v_ned
            cols["speed_acc_mps"][i] = math.sqrt(np.trace(c_en @ cov_v[:3, :3] @ c_en.T) / 3.0)
        ok[i] = True
    return ok, cols
