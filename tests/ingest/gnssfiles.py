"""GNSS test fixtures: a short synthesized drive, and its observations as RINEX 2.11 / 3.04.

The GPS-only RINEX 3.04 files come from the project's writer (``ingest.writers.rinex``).
RINEX has no third-party writer in Python, so the variants the readers must also handle
(mixed systems, event epochs, blank fields, RINEX 2.11 with continuation lines and multi-line
records) are written here by hand; every fixture is also read by georinex in the tests, which
vouches for its being valid RINEX.
"""

from __future__ import annotations

import dataclasses
import functools
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from navreplay.ingest.gnss.ephemeris import C_MPS, LAMBDA_L1_M
from navreplay.ingest.gpstime import calendar_from_gps
from navreplay.ingest.writers import rinex

REPO = Path(__file__).resolve().parents[2]
GLONASS = ("R01", "R08", "R13", "R20", "R22", "R24")


@functools.cache
def short_drive(duration_s: float = 25.0, seed: int = 11) -> Any:
    """A short ``seoul_campus_cw`` drive (10 s at rest, then driving), cached per session."""
    from navreplay.pipeline.params import load_params
    from navreplay.pipeline.synth.seoul_campus import simulate

    params = load_params(REPO / "params.yaml").synth.seoul_campus
    short = dataclasses.replace(params, duration_s=duration_s, stationary_s=10.0)
    return simulate(short, seed=seed, variant="cw")


def station(synth: Any) -> rinex.Station:
    from navreplay.pipeline.synth.files import _station

    return _station("drive", synth.tables)


def write_pair(out: Path, synth: Any) -> tuple[Path, Path]:
    """``drive.obs`` (RINEX 3.04, the project's writer) and ``drive.nav`` in ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    obs, nav = out / "drive.obs", out / "drive.nav"
    rinex.write_obs(obs, synth.tables["gnss_obs"], station(synth), interval_s=1.0)
    rinex.write_nav(nav, synth.ephemeris)
    return obs, nav


def _f(table: pa.Table, name: str) -> np.ndarray:
    return np.asarray(table.column(name).to_numpy(zero_copy_only=False), dtype=np.float64)


def _field(value: float, lli: str = " ", ssi: str = " ") -> str:
    return f"{value:14.3f}{lli}{ssi}" if np.isfinite(value) else " " * 16


def _calendar(t_ns: int) -> tuple[int, int, int, int, int, float]:
    stamp = calendar_from_gps(t_ns)
    day = stamp.astype("datetime64[D]")
    y, mo, d = (int(x) for x in str(day).split("-"))
    rem = int((stamp - day).astype("timedelta64[ns]").astype(np.int64))
    hh, rem = divmod(rem, 3600 * 10**9)
    mi, rem = divmod(rem, 60 * 10**9)
    return y, mo, d, hh, mi, rem / 1e9


def epochs_of(obs: pa.Table) -> list[tuple[int, list[tuple[str, float, float, float]]]]:
    """(t_ns, [(sv, C1, D1, S1)]) per epoch of a ``gnss_obs`` table."""
    t = obs.column("t_ns").to_numpy()
    sv = [str(s) for s in obs.column("sv").to_pylist()]
    pr, cn0 = _f(obs, "pseudorange_m"), _f(obs, "cn0_dbhz")
    dop = -_f(obs, "pseudorange_rate_mps") / LAMBDA_L1_M
    out: list[tuple[int, list[tuple[str, float, float, float]]]] = []
    for i in range(t.size):
        if not out or out[-1][0] != int(t[i]):
            out.append((int(t[i]), []))
        out[-1][1].append((sv[i], float(pr[i]), round(float(dop[i]), 3), float(cn0[i])))
    return out


def _header(version: str, kind: str, types: list[str], st: rinex.Station, t0: int) -> list[str]:
    x, y, z = st.approx_ecef_m
    yr, mo, d, hh, mi, ss = _calendar(t0)
    lines = [
        f"{version:>9}{'':11}{'OBSERVATION DATA':<20}{kind:<20}RINEX VERSION / TYPE",
        f"{'test':<20}{'navreplay':<20}{'':20}PGM / RUN BY / DATE",
        f"{x:14.4f}{y:14.4f}{z:14.4f}{'':18}APPROX POSITION XYZ",
    ]
    if version.startswith("2"):
        body = f"{len(types):6d}" + "".join(f"{c:>6}" for c in types)
        lines.append(f"{body:<60}# / TYPES OF OBSERV")
    else:
        for sys in ("G", "R", "E"):
            body = f"{sys}  {len(types):3d}" + "".join(f" {c}" for c in types)
            lines.append(f"{body:<60}SYS / # / OBS TYPES")
    lines.append(f"{yr:6d}{mo:6d}{d:6d}{hh:6d}{mi:6d}{ss:13.7f}     GPS         TIME OF FIRST OBS")
    lines.append(f"{'':60}END OF HEADER")
    return [ln + "\n" for ln in lines]


def write_obs3_mixed(
    path: Path, synth: Any, *, event_after: int = 3, header_event: bool = True
) -> dict[str, int]:
    """RINEX 3.04 with GPS, GLONASS and Galileo rows, C1C L1C D1C S1C; every 5th GPS row has
    a blank Doppler; after epoch ``event_after`` an external event (flag 5, no record) and,
    with ``header_event``, header records inside the body (flag 4, two records, blank date);
    a power-failure flag 1 on the next epoch. Returns the counts written."""
    types = ["C1C", "L1C", "D1C", "S1C"]
    eps = epochs_of(synth.tables["gnss_obs"])
    lines = _header("3.04", "M: MIXED", types, station(synth), eps[0][0])
    counts = {"gps": 0, "glonass": 0, "galileo": 0, "blank_doppler": 0, "events": 0}
    for k, (t, sats) in enumerate(eps):
        yr, mo, d, hh, mi, ss = _calendar(t)
        flag = 1 if k == event_after + 1 else 0
        extra = [(s, 2.1e7 + 1000.0 * j, 100.0, 40.0) for j, s in enumerate(GLONASS[:3])]
        extra += [("E11", 2.4e7, -50.0, 44.0)]
        rows = sats + extra
        lines.append(
            f"> {yr:4d} {mo:02d} {d:02d} {hh:02d} {mi:02d}{ss:11.7f}  {flag}{len(rows):3d}\n"
        )
        for sv, pr, doppler, cn0 in rows:
            dop = doppler
            if sv[0] == "G":
                counts["gps"] += 1
                if counts["gps"] % 5 == 0:
                    dop = float("nan")
                    counts["blank_doppler"] += 1
            else:
                counts["glonass" if sv[0] == "R" else "galileo"] += 1
            phase = pr / LAMBDA_L1_M
            text = (
                _field(pr) + _field(phase, "1" if sv == "G05" else " ") + _field(dop) + _field(cn0)
            )
            lines.append(f"{sv}{text}".rstrip() + "\n")
        if k == event_after:
            lines.append(f"> {yr:4d} {mo:02d} {d:02d} {hh:02d} {mi:02d}{ss + 0.5:11.7f}  5  0\n")
            counts["events"] += 1
            if header_event:
                lines.append(f">{'':30}4  2\n")
                lines.append(f"{'event comment':<60}COMMENT\n")
                lines.append(f"{'another':<60}COMMENT\n")
                counts["events"] += 1
    path.write_text("".join(lines))
    return counts


def write_obs2(path: Path, synth: Any) -> dict[str, int]:
    """RINEX 2.11 (mixed): C1 L1 D1 S1 P2 L2 (two lines per satellite), GPS plus six GLONASS
    satellites so that an epoch lists more than 12 (a continuation line). Returns counts."""
    types = ["C1", "L1", "D1", "S1", "P2", "L2"]
    eps = epochs_of(synth.tables["gnss_obs"])
    lines = _header("2.11", "M (MIXED)", types, station(synth), eps[0][0])
    counts = {"gps": 0, "glonass": 0}
    for t, sats in eps:
        yr, mo, d, hh, mi, ss = _calendar(t)
        rows = sats + [(s, 2.2e7 + 500.0 * j, 80.0, 38.0) for j, s in enumerate(GLONASS)]
        ids = "".join(sv for sv, *_ in rows)
        first, rest = ids[:36], ids[36:]
        lines.append(
            f" {yr % 100:02d}{mo:3d}{d:3d}{hh:3d}{mi:3d}{ss:11.7f}  0{len(rows):3d}{first}\n"
        )
        while rest:
            lines.append(f"{'':32}{rest[:36]}\n")
            rest = rest[36:]
        for sv, pr, dop, cn0 in rows:
            counts["gps" if sv[0] == "G" else "glonass"] += 1
            values = [pr, pr / LAMBDA_L1_M, dop, cn0, pr + 3.0, pr / 0.2442102134]
            text = "".join(_field(v) for v in values)
            lines.append(text[:80].rstrip() + "\n")
            lines.append(text[80:].rstrip() + "\n")
    path.write_text("".join(lines))
    return counts


def antenna_ecef(synth: Any, rows: np.ndarray) -> np.ndarray:
    """The true antenna at truth rows ``rows``, moved back by the receiver clock offset
    ``b / c`` along the body velocity (the instant the signals arrived)."""
    from navreplay.pipeline.nav import earth
    from navreplay.pipeline.nav.rotations import euler_to_dcm

    truth = synth.tables["truth"].take(pa.array(rows))
    lat, lon = np.radians(_f(truth, "lat_deg")), np.radians(_f(truth, "lon_deg"))
    alt, clock = _f(truth, "alt_m"), _f(truth, "clock_bias_m")
    rpy = np.stack([_f(truth, c) for c in ("roll_rad", "pitch_rad", "yaw_rad")], axis=1)
    v_ned = np.stack([_f(truth, f"vel_{a}_mps") for a in "ned"], axis=1)
    arm = np.asarray(synth.sensors.lever_arm_m, dtype=np.float64)
    out = np.empty((lat.size, 3))
    for i in range(lat.size):
        c_ne = earth.dcm_ecef_to_ned(lat[i], lon[i]).T
        pos = earth.geodetic_to_ecef(lat[i], lon[i], alt[i]) + c_ne @ (euler_to_dcm(*rpy[i]) @ arm)
        out[i] = pos - clock[i] / C_MPS * (c_ne @ v_ned[i])
    return out


def assert_obs_match(ref: Any, got: Any) -> None:
    """Measurements exact; satellite states to the receiver position's influence (measured
    5e-5 m on the 15-minute drive: a metre of receiver error moves them 1.3e-5 m)."""
    for col in ("t_ns", "sv", "pseudorange_m", "pseudorange_rate_mps", "cn0_dbhz"):
        np.testing.assert_array_equal(
            got[col].to_numpy(zero_copy_only=False), ref[col].to_numpy(zero_copy_only=False), col
        )
    tolerance = {
        "sat_x_m": 2e-4,
        "sat_y_m": 2e-4,
        "sat_z_m": 2e-4,
        "sat_vx_mps": 1e-7,
        "sat_vy_mps": 1e-7,
        "sat_vz_mps": 1e-7,
        "sat_clock_m": 1e-6,
        "sat_clock_drift_mps": 1e-9,
        "elevation_deg": 1e-3,
    }
    for col, atol in tolerance.items():
        np.testing.assert_allclose(got[col].to_numpy(), ref[col].to_numpy(), rtol=0, atol=atol)
    el = np.radians(ref["elevation_deg"].to_numpy())
    d_az = (got["azimuth_deg"].to_numpy() - ref["azimuth_deg"].to_numpy() + 180.0) % 360.0 - 180.0
    assert np.max(np.abs(d_az) * np.cos(el)) < 1e-3
