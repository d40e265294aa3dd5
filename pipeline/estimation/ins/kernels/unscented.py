"""The scaled unscented transform (Van der Merwe), as used by the total-state UKF.

Weights and sigma points are those of filterpy's ``MerweScaledSigmaPoints`` (paper 001:
``alpha`` 0.99, ``beta`` 2, ``kappa`` 0), so the compiled UKF and the filterpy reference
draw the same points from the same ``(x, P)``.
"""

from __future__ import annotations

from navreplay.pipeline._jit import njit
from navreplay.pipeline.estimation.ins.kernels.records import RowPrediction
from navreplay.pipeline.estimation.ins.models.ins import to_full
from navreplay.pipeline.estimation.ins.models.measurement import epoch_h
from navreplay.pipeline.nav.earth import F64


@njit(cache=True, error_model="numpy", inline="always")
def sigma_h(
    sig: F64, q_ref: F64, pred: RowPrediction, obs: F64 | None, h_ref: F64, Xw: F64, Z: F64
) -> None:
    """Predicted measurement rows (``pred``, ``obs``) of every sigma point (rows of ``sig``,
    UKF coordinates relative to ``q_ref``) minus ``h_ref`` (``Z[j, :m]``; ``Xw``: scratch
    full state)."""
    n, m = sig.shape[1], pred.m
    for j in range(sig.shape[0]):
        to_full(sig[j], q_ref, n, Xw)
        epoch_h(Xw, pred.rows, m, obs, pred.ref, pred.w_ib_b, pred.lever_b, Z[j])
        for k in range(m):
            Z[j, k] -= h_ref[k]
