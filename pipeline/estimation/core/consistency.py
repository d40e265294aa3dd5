"""The consistency every family reports: NEES of errors against their covariance, NIS per
measurement stream with its chi-square interval.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from navreplay.pipeline.distributions import chi2_ppf
from navreplay.pipeline.nav.earth import F64


def nees(err: F64, P: F64) -> F64:
    """Per-row NEES ``e^T P^-1 e`` for errors (K, k) and covariances (K, k, k)."""
    sol = np.linalg.solve(P, err[:, :, None])[:, :, 0]
    return np.asarray(np.sum(err * sol, axis=1))


def nis_by_stream(
    inn_i: npt.NDArray[np.int64], inn_f: F64, stream_names: Sequence[str]
) -> dict[str, dict[str, Any]]:
    """Per stream of an innovation log (columns t_ns, stream, sv, dim, accepted / nis, ...):
    count, mean NIS, mean dof, the 95 % interval of the mean, rejections.

    Shared by every filter family (INS, vehicle, cascaded): stream codes index
    ``stream_names``; streams without a block are left out.
    """
    out: dict[str, dict[str, Any]] = {}
    for code, name in enumerate(stream_names):
        sel = inn_i[:, 1] == code
        k = int(sel.sum())
        if k == 0:
            continue
        dof = int(inn_i[sel, 3].sum())
        mean = float(inn_f[sel, 0].mean())
        lo, hi = chi2_ppf(0.025, dof) / k, chi2_ppf(0.975, dof) / k
        out[name] = {
            "count": k,
            "nis_mean": mean,
            "dof_mean": dof / k,
            "nis_bounds_95": [float(lo), float(hi)],
            "consistent": bool(lo <= mean <= hi),
            "rejected": int((inn_i[sel, 4] == 0).sum()),
        }
    return out
