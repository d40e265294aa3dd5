"""The truth table at an estimate's times, and the estimate's errors against it.

Shared by the run metrics (``metrics``), the outage-window metrics (``ins.tracks``) and
the experiments: ``truth_at`` interpolates the truth to given times, ``error_states`` gives
truth minus estimate in the filter's error coordinates, ``position_truth`` whether a truth
table has positions (the metrics need no more; velocity and attitude errors are NaN where the
truth lacks them).
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa
from scipy.spatial.transform import Rotation

from navreplay.pipeline.estimation.core.tables import _ANGLES, truth_at
from navreplay.pipeline.estimation.ins.models import ins
from navreplay.pipeline.estimation.ins.outputs import (
    BIAS_COLUMNS,
    CLOCK_COLUMNS,
    extra_state_columns,
)
from navreplay.pipeline.estimation.ins.replay import RunResult
from navreplay.pipeline.nav.earth import E2, F64, A

_NAV_TRUTH = ("lat_deg", "lon_deg", "alt_m", "vel_n_mps", "vel_e_mps", "vel_d_mps")


def error_states(result: RunResult, truth: pa.Table) -> tuple[np.ndarray, F64, list[str]]:
    """Truth-minus-estimate in the filter's error coordinates (``models.ins``); velocity or
    attitude errors are NaN where the truth has no such columns (a simulator's ``SIM``).

    Returns:
        (mask of the estimate rows with truth, errors (K, k), names of the k states covered:
        position, velocity, attitude always; biases and clock when the truth has them).
    """
    inside, tr = truth_at(truth, result.t_ns)
    x = result.x[inside]
    lat, h = x[:, ins.X_LAT], x[:, ins.X_H]
    s2 = np.sin(lat) ** 2
    rn = A / np.sqrt(1.0 - E2 * s2)
    rm = rn * (1.0 - E2) / (1.0 - E2 * s2)
    dlon = np.angle(np.exp(1j * (np.radians(tr["lon_deg"]) - x[:, ins.X_LON])))
    cols = [
        (np.radians(tr["lat_deg"]) - lat) * (rm + h),
        dlon * (rn + h) * np.cos(lat),
        -(tr["alt_m"] - h),
    ]
    names = ["pos_n", "pos_e", "pos_d"]
    missing = np.full(len(lat), np.nan)
    for j, axis in enumerate("ned"):
        v = tr.get(f"vel_{axis}_mps")
        cols.append(v - x[:, ins.X_VEL + j] if v is not None else missing)
        names.append(f"vel_{axis}")
    if all(a in tr for a in _ANGLES) and len(lat):
        r_true = Rotation.from_euler("ZYX", np.column_stack([tr[a] for a in _ANGLES[::-1]]))
        q = x[:, ins.X_Q : ins.X_Q + 4]
        r_est = Rotation.from_quat(q[:, [1, 2, 3, 0]])
        att = (r_true * r_est.inv()).as_rotvec()
        cols += [att[:, 0], att[:, 1], att[:, 2]]
    else:
        cols += [missing, missing, missing]
    names += ["att_n", "att_e", "att_d"]
    # the truth has a receiver clock, but no fix errors to compare the loose states with
    extra = BIAS_COLUMNS + (CLOCK_COLUMNS if extra_state_columns(result) == CLOCK_COLUMNS else ())
    if all(c[0] in tr for c in extra):
        for col, xi, _, _ in extra:
            cols.append(tr[col] - x[:, xi])
            names.append(col)
    return inside, np.column_stack(cols) if cols else np.zeros((0, 0)), names


def position_truth(truth: pa.Table) -> bool:
    """Whether the truth has positions (velocity and attitude may be missing)."""
    cols = _NAV_TRUTH[:3]
    return all(c in truth.column_names and truth.column(c).null_count < len(truth) for c in cols)
