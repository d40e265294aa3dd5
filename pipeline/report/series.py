"""Time series a report plots: position error against a reference, with the filter's sigma.

The reference is the ``truth`` table when the dataset has one (interpolated to the estimate's
times, ``estimation.core.tables.truth_at``). Without truth it is the GNSS fixes (the estimate
interpolated to each fix time): outside outages that is a residual, not an error, but inside
an outage window the withheld fixes are the truth (architecture section 5).

Errors are reference minus estimate in local NED metres (the estimate's latitude and height
set the radii of curvature), so ``err_h = hypot(err_n, err_e)``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
import pyarrow as pa

from navreplay.pipeline.estimation.core.tables import truth_at
from navreplay.pipeline.nav.earth import E2, F64, A
from navreplay.pipeline.report.inputs import Run, column, times_ns

#: ``fixes_residual``: against the GNSS fixes, which the filter fused outside outage windows, so
#: a residual there and never an accuracy
Reference = Literal["truth", "fixes_residual"]


@dataclass(frozen=True)
class ErrorSeries:
    """Position error of one run (see the module docstring); all arrays of one length.

    Attributes:
        t_ns: sample times; reference: what the error is measured against.
        err_ned_m: (K, 3) reference minus estimate, NED metres.
        sigma_ned_m: (K, 3) the filter's 1-sigma of the same components.
    """

    t_ns: np.ndarray
    reference: Reference
    err_ned_m: F64
    sigma_ned_m: F64

    @property
    def err_h_m(self) -> F64:
        return np.asarray(np.hypot(self.err_ned_m[:, 0], self.err_ned_m[:, 1]))

    @property
    def err_3d_m(self) -> F64:
        return np.asarray(np.sqrt(np.sum(self.err_ned_m**2, axis=1)))

    @property
    def sigma_h_m(self) -> F64:
        s = self.sigma_ned_m
        return np.asarray(np.hypot(s[:, 0], s[:, 1]))

    def t_s(self, t0_ns: int) -> F64:
        return np.asarray((self.t_ns - t0_ns) / 1e9)


def ned_difference(lat_deg: F64, lon_deg: F64, alt_m: F64, ref: dict[str, F64]) -> F64:
    """``ref`` (columns ``lat_deg``, ``lon_deg``, ``alt_m``) minus the given positions, local
    NED metres (the given latitude and height set the radii of curvature)."""
    lat = np.radians(lat_deg)
    s2 = np.sin(lat) ** 2
    rn = A / np.sqrt(1.0 - E2 * s2)
    rm = rn * (1.0 - E2) / (1.0 - E2 * s2)
    dlon = np.angle(np.exp(1j * np.radians(ref["lon_deg"] - lon_deg)))
    return np.column_stack(
        [
            np.radians(ref["lat_deg"] - lat_deg) * (rm + alt_m),
            dlon * (rn + alt_m) * np.cos(lat),
            -(ref["alt_m"] - alt_m),
        ]
    )


def error_series(run: Run, truth: pa.Table | None, gnss: pa.Table | None) -> ErrorSeries | None:
    """The run's position error against truth, else against the GNSS fixes; None if neither."""
    est = run.estimate
    if est is None or est.num_rows == 0:
        return None
    t = times_ns(est)
    cols = {c: column(est, c) for c in ("lat_deg", "lon_deg", "alt_m")}
    sig = np.column_stack([column(est, c) for c in ("lat_sigma_m", "lon_sigma_m", "alt_sigma_m")])
    if truth is not None and truth.num_rows > 1:
        inside, ref = truth_at(truth, t)
        if inside.any():
            err = ned_difference(
                cols["lat_deg"][inside], cols["lon_deg"][inside], cols["alt_m"][inside], ref
            )
            return ErrorSeries(t[inside], "truth", err, sig[inside])
    if gnss is None or gnss.num_rows == 0:
        return None
    tg = times_ns(gnss)
    ok = (tg >= t[0]) & (tg <= t[-1])
    for c in ("lat_deg", "lon_deg", "alt_m"):
        ok &= np.isfinite(column(gnss, c))
    if not ok.any():
        return None
    tg = tg[ok]
    tf, tgf = t.astype(np.float64), tg.astype(np.float64)
    at = {c: np.interp(tgf, tf, v) for c, v in cols.items()}
    ref = {c: column(gnss, c)[ok] for c in ("lat_deg", "lon_deg", "alt_m")}
    sig_at = np.column_stack([np.interp(tgf, tf, sig[:, j]) for j in range(3)])
    return ErrorSeries(
        tg, "fixes_residual", ned_difference(at["lat_deg"], at["lon_deg"], at["alt_m"], ref), sig_at
    )


def local_en(lat_deg: F64, lon_deg: F64, lat0_deg: float, lon0_deg: float) -> tuple[F64, F64]:
    """East and north metres of points from an origin (equirectangular; plots only)."""
    lat0 = np.radians(lat0_deg)
    s2 = np.sin(lat0) ** 2
    rn = A / np.sqrt(1.0 - E2 * s2)
    rm = rn * (1.0 - E2) / (1.0 - E2 * s2)
    dlon = np.angle(np.exp(1j * np.radians(lon_deg - lon0_deg)))
    return dlon * rn * np.cos(lat0), np.radians(lat_deg - lat0_deg) * rm


def in_windows(t_ns: np.ndarray, windows: list[tuple[int, int]]) -> np.ndarray:
    """Boolean mask of the times inside any ``[start, end)`` window."""
    mask = np.zeros(t_ns.size, bool)
    for a, b in windows:
        mask |= (t_ns >= a) & (t_ns < b)
    return mask
