"""Real sky: the one SPP solver and the tight filters' observation model on real RINEX.

Two receivers of ``../shared/data/corpus_2026`` (read in place; skipped when absent), each
ingested as a user would (``navreplay ingest OBS NAV...``, the RINEX reader filling the
satellite states of ``gnss_obs`` from the broadcast ephemeris), then measured against its
reference:

- ``rinex_static_mosaicx5_2024``: Septentrio mosaic-X5, RINEX 3.04, 300 s at 1 Hz, open sky,
  surveyed position (ellipsoidal height); mixed navigation file.
- ``rinex_urban_hk_tst2019``: u-blox L1 receiver in a car in Tsim Sha Tsui (Hong Kong), RINEX
  3.03, 1760 s, GPS (``.19n``) and BeiDou (``.19b``) navigation files given together; NovAtel
  SPAN reference at 1 Hz over 484 s of it.
- ``android_gnsslogger_2016``: a static phone's raw GPS measurements (GnssLogger) and the
  RINEX 2 navigation file; no surveyed position, so its own fixes are the reference.

Figures (GPS L1 C/A; only GPS has an orbit model in ``ingest.gnss.ephemeris``: the readers
count and leave out the rows and navigation records of the other systems):

- SPP (``ingest.gnss.spp.solve``) on the ``gnss_obs`` observables as the filters correct them
  (``estimation.ins.inputs.corrected_observables``: satellite clock, broadcast Klobuchar)
  minus the standard tropospheric delay (``spp.tropo_delay_m``, as ``ingest.gnss.fixcheck``
  does when a table has none), elevation mask 10 deg as the filters' default: horizontal and
  vertical error against the reference (RMS, 95th percentile, max), epochs solved, satellites
  used (median);
- residuals of ``pseudorange_h`` / ``pseudorange_rate_h`` (``estimation.ins.models.gnss``)
  evaluated at the reference position and velocity, the clock bias / drift estimated per
  epoch (least squares: the epoch's mean residual): RMS per file.

What the figures say (measured 2026-12-03):

- static: horizontal RMS 3.2 m, a steady 3.2 m northward offset, and RTKLIB's ``pntpos``
  (pyrtklib, same files, same satellites) finds the same to 0.3 m. It is the ionosphere: the
  broadcast Klobuchar model removes ~12 m median at 17:20 local time near the 2024 solar
  maximum, and the dual-frequency iono-free combination (C1C/C2W, same satellites, same
  solver; checked by hand, not here) lands 0.3 m north of the survey, 1.2 m horizontal RMS.
  Without any tropospheric model (what the filters get: the RINEX reader writes no
  ``tropo_delay_m``) the height is 4.4 m high instead of 2.2 m low, and the pseudorange
  residual RMS at the survey is 2.6 m instead of 1.6 m. RTKLIB with every system of the
  mixed navigation file (44 satellites) gets 2.6 m horizontal, 1.0 m vertical RMS.
- Hong Kong: a median of 6 GPS satellites between high-rises; reflected (NLOS) signals give
  residuals of tens of metres (RMS 21 m at the reference); SPP horizontal RMS 27 m, vertical
  81 m. RTKLIB: 26 m horizontal RMS over the 189 epochs its residual test accepts, 8 m with
  BeiDou added (140 epochs). The bounds below sit ~1.5x above our figures.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import pyarrow as pa
import pymap3d
import pytest

from navreplay.ingest.api import ingest
from navreplay.ingest.gnss import spp
from navreplay.ingest.gpstime import NS_PER_S, NS_PER_WEEK
from navreplay.ingest.schema import TableName
from navreplay.ingest.tables import read_table
from navreplay.pipeline.estimation.ins.inputs import corrected_observables
from navreplay.pipeline.estimation.ins.models import gnss as gm
from navreplay.pipeline.estimation.ins.models.ins import (
    FULL_DIM,
    X_CB,
    X_CD,
    X_H,
    X_LAT,
    X_LON,
    X_Q,
    X_VEL,
)

REPO = Path(__file__).resolve().parents[3]
DATA = REPO.parent / "shared" / "data" / "corpus_2026"
MASK_DEG = 10.0

F64 = npt.NDArray[np.float64]
Bools = npt.NDArray[np.bool_]


@dataclass(frozen=True)
class Sky:
    """A file's ``gnss_obs`` and its reference at the observation epochs.

    Attributes:
        obs: the ingested table; epoch: epoch index per row; epoch_t_ns: the epochs;
        llh: reference latitude, longitude (deg), height (m) per epoch;
        vel_ned: reference velocity per epoch, m/s; covered: epochs the reference covers;
        report: the ingest report.
    """

    obs: pa.Table
    epoch: npt.NDArray[np.int64]
    epoch_t_ns: npt.NDArray[np.int64]
    llh: F64
    vel_ned: F64
    covered: Bools
    report: dict[str, Any]


def _ingest(tmp: Path, *names: str) -> tuple[pa.Table, dict[str, Any]]:
    logs = [DATA / n for n in names]
    missing = [p.name for p in logs if not p.is_file()]
    if missing:
        pytest.skip(f"{', '.join(missing)} absent from {DATA} (../shared/data is read in place)")
    result = ingest(logs, tmp / "tables")
    table = read_table(tmp / "tables" / "gnss_obs.parquet", TableName.GNSS_OBS).table
    return table, result.report


def _epochs(obs: pa.Table) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    t = np.asarray(obs.column("t_ns").to_numpy(), dtype=np.int64)
    epoch, first = spp.epoch_index(t)
    return epoch, t[first]


@pytest.fixture(scope="module")
def static(tmp_path_factory: pytest.TempPathFactory) -> Sky:
    obs, report = _ingest(
        tmp_path_factory.mktemp("static"),
        "rinex_static_mosaicx5_2024.obs",
        "rinex_static_mosaicx5_2024.nav",
    )
    text = (DATA / "rinex_static_mosaicx5_2024_truth.txt").read_text().split()
    epoch, et = _epochs(obs)
    llh = np.tile([float(v) for v in text[:3]], (et.size, 1))
    return Sky(obs, epoch, et, llh, np.zeros((et.size, 3)), np.ones(et.size, bool), report)


@pytest.fixture(scope="module")
def urban(tmp_path_factory: pytest.TempPathFactory) -> Sky:
    obs, report = _ingest(
        tmp_path_factory.mktemp("urban"),
        "rinex_urban_hk_tst2019.obs",
        "rinex_urban_hk_tst2019.19n",
        "rinex_urban_hk_tst2019.19b",
    )
    epoch, et = _epochs(obs)
    llh, vel, covered = _span_reference(et, 0.0)
    return Sky(obs, epoch, et, llh, vel, covered, report)


def _span_reference(epoch_t_ns: npt.NDArray[np.int64], shift_s: float) -> tuple[F64, F64, Bools]:
    """The SPAN reference (GPS week, seconds of week, lat, lon, h) at the epochs shifted by
    ``shift_s``: position interpolated in ECEF, velocity from its differences; and the epochs
    it covers."""
    ref = np.loadtxt(DATA / "rinex_urban_hk_tst2019_truth.csv", delimiter=",")
    t_ref = ref[:, 0] * (NS_PER_WEEK / NS_PER_S) + ref[:, 1]  # GPS seconds
    t = epoch_t_ns / NS_PER_S + shift_s
    covered = (t >= t_ref[0]) & (t <= t_ref[-1])
    x, y, z = pymap3d.geodetic2ecef(ref[:, 2], ref[:, 3], ref[:, 4])
    ecef = np.column_stack([np.interp(t, t_ref, c) for c in (x, y, z)])
    v_ecef = np.column_stack([np.interp(t, t_ref, np.gradient(c, t_ref)) for c in (x, y, z)])
    llh = np.column_stack(pymap3d.ecef2geodetic(*ecef.T))
    vel = np.column_stack(pymap3d.ecef2nedv(*v_ecef.T, llh[:, 0], llh[:, 1]))
    return llh, vel, covered


def _col(table: pa.Table, name: str) -> F64:
    return np.asarray(table.column(name).to_numpy(zero_copy_only=False), dtype=np.float64)


@dataclass(frozen=True)
class SppFigures:
    h_rms: float
    h_p95: float
    h_max: float
    v_rms: float
    v_p95: float
    v_max: float
    solved: int
    epochs: int
    sats_median: float


def _spp(sky: Sky) -> spp.EpochFix:
    """``spp.solve`` on the epochs (module docstring: corrections, mask)."""
    obs = sky.obs
    pr, _ = corrected_observables(obs)
    elev = _col(obs, "elevation_deg")
    pr = pr - spp.tropo_delay_m(np.radians(elev), sky.llh[sky.epoch, 2])
    pr[elev < MASK_DEG] = np.nan
    sat = np.column_stack([_col(obs, f"sat_{a}_m") for a in "xyz"])
    return spp.solve(sat, pr, sky.epoch, sky.epoch_t_ns.size)


def _used(sky: Sky, fix: spp.EpochFix) -> npt.NDArray[np.int64]:
    """Satellites used per epoch (above the mask, not rejected)."""
    above = _col(sky.obs, "elevation_deg") >= MASK_DEG
    return np.bincount(sky.epoch[fix.used & above], minlength=sky.epoch_t_ns.size)


def spp_figures(sky: Sky) -> SppFigures:
    fix = _spp(sky)
    ok = fix.solved & sky.covered
    ref = sky.llh[ok]
    e, n, u = pymap3d.ecef2enu(*fix.ecef_m[ok].T, ref[:, 0], ref[:, 1], ref[:, 2])
    hz, vt = np.hypot(e, n), np.abs(u)
    used = _used(sky, fix)
    return SppFigures(
        float(np.sqrt(np.mean(hz**2))),
        float(np.percentile(hz, 95)),
        float(hz.max()),
        float(np.sqrt(np.mean(vt**2))),
        float(np.percentile(vt, 95)),
        float(vt.max()),
        int(ok.sum()),
        int(sky.covered.sum()),
        float(np.median(used[ok])),
    )


def model_residuals(sky: Sky, *, tropo: bool) -> tuple[F64, F64]:
    """Residuals of the observed pseudoranges and rates (m, m/s) against ``pseudorange_h``
    and ``pseudorange_rate_h`` at the reference, after each epoch's least-squares clock
    bias and drift; rows above the mask where the reference covers the epoch (NaN where an
    observable is missing). ``tropo``: subtract ``spp.tropo_delay_m`` (the filters do not:
    the RINEX reader writes no ``tropo_delay_m``)."""
    obs = sky.obs
    pr, rate = corrected_observables(obs)
    elev = _col(obs, "elevation_deg")
    if tropo:
        pr = pr - spp.tropo_delay_m(np.radians(elev), sky.llh[sky.epoch, 2])
    sat = np.column_stack(
        [_col(obs, f"sat_{a}_m") for a in "xyz"] + [_col(obs, f"sat_v{a}_mps") for a in "xyz"]
    )
    X = np.zeros(FULL_DIM)
    X[X_Q] = 1.0
    ant, C, lever, w = np.zeros(gm.AN_DIM), np.zeros((3, 3)), np.zeros(3), np.zeros(3)
    pr_h, rate_h = np.full(pr.size, np.nan), np.full(pr.size, np.nan)
    rows = np.flatnonzero(sky.covered[sky.epoch] & (elev >= MASK_DEG))
    last = -1
    for j in rows.tolist():
        k = int(sky.epoch[j])
        if k != last:
            X[X_LAT], X[X_LON] = np.radians(sky.llh[k, :2])
            X[X_H] = sky.llh[k, 2]
            X[X_VEL : X_VEL + 3] = sky.vel_ned[k]
            gm.antenna(X, lever, w, C, ant)
            last = k
        pr_h[j] = gm.pseudorange_h(ant, X, sat[j])  # X_CB = 0: the clock comes next
        rate_h[j] = gm.pseudorange_rate_h(ant, X, sat[j])
    assert X[X_CB] == 0.0
    assert X[X_CD] == 0.0
    out = []
    for y in (pr - pr_h, rate - rate_h):
        good = np.isfinite(y)
        n = np.bincount(sky.epoch[good], minlength=sky.epoch_t_ns.size)
        mean = np.bincount(sky.epoch[good], y[good], sky.epoch_t_ns.size) / np.maximum(n, 1)
        out.append(np.where(good, y - mean[sky.epoch], np.nan))
    return out[0], out[1]


def _rms(x: F64) -> float:
    x = x[np.isfinite(x)]
    return float(np.sqrt(np.mean(x * x)))


def test_static_open_sky_gps_spp_meets_metre_level_accuracy(static: Sky) -> None:
    f = spp_figures(static)
    assert f.solved == f.epochs == 301
    assert f.sats_median >= 8
    # measured 3.2 / 3.4 / 3.6 m horizontal and 2.3 / 2.9 / 3.2 m vertical: the Klobuchar
    # residual of a solar-maximum afternoon (module docstring); a wrong orbit, clock, time
    # tag or Sagnac term costs tens of metres and more
    assert f.h_rms < 5.0
    assert f.h_p95 < 6.0
    assert f.h_max < 7.0
    assert f.v_rms < 4.5
    assert f.v_p95 < 5.5
    assert f.v_max < 6.0


def _rtklib_spp(names: tuple[str, ...]) -> F64:
    """RTKLIB's ``pntpos`` (pyrtklib) on the files, GPS only, broadcast Klobuchar,
    Saastamoinen troposphere, 10 deg mask: [GPS s, solved, x, y, z, satellites] per epoch."""
    rtk = pytest.importorskip("pyrtklib")
    nav, obs, sta = rtk.nav_t(), rtk.obs_t(), rtk.sta_t()
    for name in names:
        assert rtk.readrnx(str(DATA / name), 1, "", obs, nav, sta) == 1
    rtk.sortobs(obs)
    rtk.uniqnav(nav)
    opt = rtk.prcopt_default
    opt.navsys = rtk.SYS_GPS
    opt.ionoopt, opt.tropopt = rtk.IONOOPT_BRDC, rtk.TROPOPT_SAAS
    opt.elmin = np.radians(MASK_DEG)
    sol, ssat = rtk.sol_t(), rtk.Arr1Dssat_t(rtk.MAXSAT)
    azel, msg, week = rtk.Arr1Ddouble(2 * rtk.MAXOBS), rtk.Arr1Dchar(128), rtk.Arr1Dint(1)
    out, i = [], 0
    while i < obs.n:
        j = i
        while j < obs.n and abs(rtk.timediff(obs.data[j].time, obs.data[i].time)) < 1e-3:
            j += 1
        ok = rtk.pntpos(obs.data[i], j - i, nav, opt, sol, azel, ssat[0], msg)
        tow = rtk.time2gpst(sol.time, week)
        out.append((week[0] * 604_800 + tow, ok, sol.rr[0], sol.rr[1], sol.rr[2], sol.ns))
        i = j
    return np.asarray(out, dtype=np.float64)


def test_static_spp_agrees_with_rtklib_epoch_by_epoch(static: Sky) -> None:
    """An independent SPP on the same files lands within decimetres of ours: the 3 m offset
    from the survey is in the data (the ionosphere), not in the solver or the orbits."""
    ref = _rtklib_spp(("rinex_static_mosaicx5_2024.obs", "rinex_static_mosaicx5_2024.nav"))
    fix = _spp(static)
    assert ref.shape[0] == static.epoch_t_ns.size
    assert np.all(ref[:, 1] == 1)
    # RTKLIB stamps its solution with the receiver clock removed: within a millisecond
    np.testing.assert_allclose(ref[:, 0], static.epoch_t_ns / NS_PER_S, atol=1e-3, rtol=0)
    np.testing.assert_array_equal(ref[:, 5], _used(static, fix))  # the same satellites
    lat, lon, _ = static.llh[0]
    e, n, u = pymap3d.ecef2enuv(*(fix.ecef_m - ref[:, 2:5]).T, lat, lon)
    # measured at most 0.27 m horizontal and 0.62 m vertical apart (0.43 m on average: our
    # exponential troposphere against Saastamoinen; RTKLIB also weights by elevation)
    assert float(np.max(np.hypot(e, n))) < 0.5
    assert float(np.max(np.abs(u))) < 1.0


def test_static_residuals_of_the_tight_model_at_the_surveyed_position(static: Sky) -> None:
    pr, rate = model_residuals(static, tropo=True)
    pr_filter, rate_filter = model_residuals(static, tropo=False)
    # measured 1.56 m (2.7 m 95 %) with the standard troposphere, 2.63 m as the filters see
    # it (no tropospheric delay in the table): that delay is most of what is left
    assert _rms(pr) < 2.5
    assert _rms(pr_filter) < 4.0
    assert _rms(pr) < 0.7 * _rms(pr_filter)
    # Doppler of a static antenna: measured 0.011 m/s RMS (0.023 m/s 95 %), every row
    assert np.isfinite(rate).sum() == np.isfinite(pr).sum() == 2709
    assert _rms(rate) < 0.05
    np.testing.assert_array_equal(rate, rate_filter)  # rates carry no troposphere


def test_urban_canyon_gps_spp_is_bounded_by_its_multipath(urban: Sky) -> None:
    f = spp_figures(urban)
    assert f.epochs == 484  # the receiver epochs (at .997 / .001 s) inside the 484 s of SPAN
    # epochs with fewer than four GPS satellites above 10 deg are not solved: 465 of 484
    assert f.solved >= 0.93 * f.epochs
    assert f.sats_median >= 5
    # measured 27 m horizontal RMS (61 m 95 %, 102 m max) and 81 m vertical RMS (157 m 95 %,
    # 552 m max): L1 GPS alone between high-rises, reflected signals tens of metres long
    # (module docstring); RTKLIB's pntpos on the same files: 26 m horizontal RMS on the 189
    # epochs its residual test accepts. A correct SPP, not a good one: bounds ~1.5x these
    assert f.h_rms < 40.0
    assert f.h_p95 < 90.0
    assert f.h_max < 150.0
    assert f.v_rms < 120.0
    assert f.v_p95 < 240.0
    assert f.v_max < 800.0


def test_urban_residuals_of_the_tight_model_at_the_span_reference(urban: Sky) -> None:
    pr, rate = model_residuals(urban, tropo=True)
    # measured 20.7 m RMS and a median |residual| of 8.8 m (reflections pull each epoch's
    # least-squares clock too); Doppler 1.33 m/s RMS, median 0.30 m/s (reflected signals'
    # Doppler differs from the direct one by up to twice the car's speed, 4-10 m/s here)
    assert _rms(pr) < 30.0
    assert float(np.nanmedian(np.abs(pr))) < 12.0
    assert np.isfinite(rate).sum() > 0.95 * np.isfinite(pr).sum()
    assert _rms(rate) < 2.0
    assert float(np.nanmedian(np.abs(rate))) < 0.5


def test_urban_observations_and_reference_share_one_time_scale(urban: Sky) -> None:
    """The residuals are smallest with the reference at the epochs' own GPS time; read as
    UTC (18 s off in 2019) or a second off, the car is elsewhere."""

    def median_abs(shift_s: float) -> tuple[float, float]:
        llh, vel, covered = _span_reference(urban.epoch_t_ns, shift_s)
        sky = Sky(urban.obs, urban.epoch, urban.epoch_t_ns, llh, vel, covered, urban.report)
        pr, rate = model_residuals(sky, tropo=True)
        return float(np.nanmedian(np.abs(pr))), float(np.nanmedian(np.abs(rate)))

    pr0, rate0 = median_abs(0.0)
    for shift in (-18.0, -1.0, 1.0, 18.0):
        pr_s, rate_s = median_abs(shift)
        assert pr_s > pr0, shift
        assert rate_s > rate0, shift
    assert median_abs(18.0)[0] > 1.5 * pr0


def _file_report(sky: Sky, name: str) -> dict[str, Any]:
    return next(f for f in sky.report["files"] if f["name"] == name)


def test_systems_without_an_orbit_model_are_counted_not_used(static: Sky, urban: Sky) -> None:
    """GPS only: the other systems' rows and navigation records are named and counted."""
    for sky in (static, urban):
        svs = set(np.asarray(sky.obs.column("sv").to_numpy(zero_copy_only=False)).tolist())
        assert {s[0] for s in svs} == {"G"}
    hk = _file_report(urban, "rinex_urban_hk_tst2019.obs")
    assert hk["counters"]["rows_BeiDou_excluded"] == 14_335
    assert "no orbit model for BeiDou (14335)" in hk["streams"][0]["detail"]
    bds_nav = _file_report(urban, "rinex_urban_hk_tst2019.19b")["streams"][0]
    assert bds_nav["count"] == 0
    assert "BeiDou 356" in bds_nav["detail"]
    mixed = _file_report(static, "rinex_static_mosaicx5_2024.obs")["counters"]
    assert {k for k in mixed if k.startswith("rows_")} == {
        f"rows_{s}_excluded" for s in ("Galileo", "GLONASS", "BeiDou", "QZSS")
    }


def test_phone_spp_centres_on_the_phones_own_fixes(tmp_path: Path) -> None:
    """``android_gnsslogger_2016`` (a static phone, no surveyed position): SPP on its raw
    GPS pseudoranges centres where the phone's own fixes do; the scatter is the phone's.

    Measured: 200 of 200 epochs solved, 9 satellites (median), scatter about the median
    9.2 m horizontal and 10.4 m vertical RMS (raw, unsmoothed phone pseudoranges); the
    median lies 0.7 m horizontally and 5.3 m vertically from the median of the phone's
    fixes (207, reported accuracy 2.6 m)."""
    obs, _ = _ingest(tmp_path, "android_gnsslogger_2016.txt", "android_gnsslogger_2016.16n")
    fixes = read_table(tmp_path / "tables" / "gnss.parquet", TableName.GNSS).table
    epoch, et = _epochs(obs)
    phone = np.array([np.median(_col(fixes, c)) for c in ("lat_deg", "lon_deg", "alt_m")])
    sky = Sky(obs, epoch, et, np.tile(phone, (et.size, 1)), np.zeros((et.size, 3)), et > 0, {})
    fix = _spp(sky)
    assert int(fix.solved.sum()) >= 0.95 * et.size
    assert float(np.median(_used(sky, fix)[fix.solved])) >= 7
    centre = np.median(fix.ecef_m[fix.solved], axis=0)
    e, n, u = pymap3d.ecef2enu(*centre, *phone)
    assert float(np.hypot(e, n)) < 3.0
    assert abs(float(u)) < 10.0
    de, dn, du = pymap3d.ecef2enu(*fix.ecef_m[fix.solved].T, *pymap3d.ecef2geodetic(*centre))
    assert _rms(np.hypot(de, dn)) < 15.0
    assert _rms(du) < 16.0
