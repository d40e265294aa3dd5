"""A navigation solution (the canonical ``estimator``/``truth`` layout) as a TUM trajectory.

The TUM RGB-D format, which evo (``evo_traj tum``, ``evo_ape tum``) and most SLAM tools read:
one pose per line, ``timestamp tx ty tz qx qy qz qw``, space-separated, ``#`` comments.

- timestamp: the row's ``t_ns`` in seconds (the table's time base, GPS time for most logs);
- position: WGS-84 ECEF metres. Every export shares that frame, so any two of them (a run
  and the truth, two runs, a run and the onboard estimate) compare in evo without an
  alignment or an origin to agree on (``evo_ape tum ref.tum est.tum`` is the 3-D position
  error); ``evo_traj --align_origin`` plots them from the first pose;
- orientation: the body FRD frame w.r.t. ECEF (the quaternion maps body vectors into ECEF),
  Hamilton, scalar last as TUM orders it; identity where the table has no attitude.

Rows without a finite position are left out. The file is written atomically.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow as pa
from scipy.spatial.transform import Rotation

from navreplay.ingest.atomic import atomic_write_text
from navreplay.ingest.ecef import c_ned_ecef, ecef_from_geodetic

HEADER = "# timestamp tx ty tz qx qy qz qw (WGS-84 ECEF m; body FRD w.r.t. ECEF; navreplay)\n"


def _col(table: pa.Table, name: str) -> np.ndarray:
    if name not in table.column_names:
        return np.full(table.num_rows, np.nan)
    return np.asarray(table.column(name).to_numpy(zero_copy_only=False), dtype=np.float64)


def tum_text(table: pa.Table) -> str:
    """The TUM lines of a navigation-solution table (see the module docstring)."""
    t = np.asarray(table.column("t_ns").to_numpy(), dtype=np.int64)
    lat, lon, alt = (_col(table, c) for c in ("lat_deg", "lon_deg", "alt_m"))
    ok = np.isfinite(lat) & np.isfinite(lon) & np.isfinite(alt)
    t, lat, lon, alt = t[ok], lat[ok], lon[ok], alt[ok]
    xyz = ecef_from_geodetic(lat, lon, alt)
    rpy = np.column_stack([_col(table, c)[ok] for c in ("roll_rad", "pitch_rad", "yaw_rad")])
    rpy[~np.isfinite(rpy).all(axis=1)] = 0.0
    # C_ecef_body = C_ned_ecef^T C_ned_body, with C_ned_body from ZYX Euler angles
    c_ned_body = Rotation.from_euler("ZYX", rpy[:, ::-1]).as_matrix()
    c_ecef_body = np.einsum("nji,njk->nik", c_ned_ecef(lat, lon), c_ned_body)
    q = Rotation.from_matrix(c_ecef_body).as_quat()  # x, y, z, w
    q[q[:, 3] < 0] *= -1.0  # one sign, so that the same pose prints the same
    lines = [HEADER]
    for k in range(t.size):
        sec, nsec = divmod(int(t[k]), 1_000_000_000)
        x, y, z = xyz[k]
        qx, qy, qz, qw = q[k]
        lines.append(
            f"{sec}.{nsec:09d} {x:.4f} {y:.4f} {z:.4f} {qx:.9f} {qy:.9f} {qz:.9f} {qw:.9f}\n"
        )
    return "".join(lines)


def write_tum(path: Path, table: pa.Table) -> int:
    """Write ``table`` as a TUM trajectory at ``path``; returns the number of poses."""
    text = tum_text(table)
    atomic_write_text(path, text)
    return text.count("\n") - 1
