"""A minimal reader of the smartLoc text files for the tests (until ingest's libRSF reader lands).

Same conversions as ``ingest/readers/librsf.py`` (branch ingest-misc): odometry forward speed
and yaw rate (FLU -> FRD: the yaw rate changes sign), pseudoranges with the satellite ECEF
positions rotated from the transmit-time frame to the receive-time frame (omega_E * tau), the
ground truth ECEF -> WGS-84. Time base: seconds from the start of the run (recorder).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow as pa

from ingest.schema import from_columns
from pipeline.nav.earth import OMEGA_IE, ecef_to_geodetic

C_MPS = 299_792_458.0
SYSTEMS = {1: "G", 2: "S", 4: "R", 8: "E", 16: "J", 32: "C"}


def _rows(path: Path, kind: str) -> np.ndarray:
    lines = [ln.split()[1:] for ln in path.read_text().splitlines() if ln.startswith(kind + " ")]
    return np.array(lines, dtype=np.float64)


def load(folder: Path) -> dict[str, pa.Table]:
    """``vehicle``, ``gnss_obs`` and ``truth`` canonical tables of the Berlin run."""
    inp = folder / "Berlin_Potsdamer_Platz_Input.txt"
    gt = folder / "Berlin_Potsdamer_Platz_GT.txt"
    od = _rows(inp, "odom3")
    pr = _rows(inp, "pseudorange3")
    tr = _rows(gt, "point3")
    t_od = np.round(od[:, 0] * 1e9).astype(np.int64)
    vehicle = from_columns(
        "vehicle",
        {"t_ns": t_od, "speed_mps": od[:, 1], "steer_rad": np.full(len(od), np.nan),
         "yaw_rate_radps": -od[:, 6]},
    )  # fmt: skip
    t_pr = np.round(pr[:, 0] * 1e9).astype(np.int64)
    sat = pr[:, 3:6].copy()
    # transmit-time ECEF -> receive-time ECEF (tau from the coarse range to the truth's area)
    ref = tr[0, 1:4]
    tau = np.linalg.norm(sat - ref, axis=1) / C_MPS
    th = OMEGA_IE * tau
    x = sat[:, 0] * np.cos(th) + sat[:, 1] * np.sin(th)
    y = -sat[:, 0] * np.sin(th) + sat[:, 1] * np.cos(th)
    sv = [
        f"{SYSTEMS.get(int(s), 'X')}{int(i) % 100:02d}"
        for i, s in zip(pr[:, 6], pr[:, 7], strict=True)
    ]
    gnss_obs = pa.table({
        "t_ns": pa.array(t_pr, pa.int64()), "sv": pa.array(sv, pa.string()),
        "pseudorange_m": pr[:, 1], "pseudorange_std_m": np.sqrt(pr[:, 2]),
        "sat_x_m": x, "sat_y_m": y, "sat_z_m": sat[:, 2],
        "elevation_deg": pr[:, 8], "cn0_dbhz": pr[:, 9],
    })  # fmt: skip
    geo = np.array([ecef_to_geodetic(*p) for p in tr[:, 1:4]])
    truth = from_columns(
        "truth",
        {"t_ns": np.round(tr[:, 0] * 1e9).astype(np.int64), "lat_deg": np.degrees(geo[:, 0]),
         "lon_deg": np.degrees(geo[:, 1]), "alt_m": geo[:, 2]},
    )  # fmt: skip
    return {"vehicle": vehicle, "gnss_obs": gnss_obs, "truth": truth}
