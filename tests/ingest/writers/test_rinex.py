"""RINEX writers: georinex reads back exactly the observations and broadcast elements."""

from __future__ import annotations

import warnings
from pathlib import Path

import georinex
import numpy as np
import pyarrow as pa
import pytest

from navreplay.ingest.gnss.ephemeris import LAMBDA_L1_M, Ephemeris, orbit
from navreplay.ingest.gpstime import NS_PER_S, gps_from_calendar
from navreplay.ingest.schema import from_columns
from navreplay.ingest.writers import rinex
from tests.ingest.navfile import read_gps_nav

T0 = gps_from_calendar("2026-11-18T02:30:00")
STATION = rinex.Station("test_marker", (-3047163.5, 4051070.7, 3858082.0))


def _three_decimals(x: np.ndarray) -> np.ndarray:
    return np.array([float(f"{v:.3f}") for v in x])


@pytest.fixture(scope="module")
def obs() -> pa.Table:
    rng = np.random.default_rng(4)
    svs = [["G03", "G11", "G24"], ["G03", "G07", "G11", "G24"], ["G07", "G11"]]
    rows = [(k, sv) for k, group in enumerate(svs) for sv in group]
    n = len(rows)
    doppler = _three_decimals(rng.uniform(-4000, 4000, n))
    cols = {
        "t_ns": np.array([T0 + k * NS_PER_S for k, _ in rows], dtype=np.int64),
        "sv": [sv for _, sv in rows],
        "pseudorange_m": _three_decimals(rng.uniform(2.0e7, 2.5e7, n)),
        "pseudorange_rate_mps": -doppler * LAMBDA_L1_M,
        "cn0_dbhz": _three_decimals(rng.uniform(30, 50, n)),
    }
    for name in ("sat_x_m", "sat_y_m", "sat_z_m"):
        cols[name] = rng.normal(0.0, 1.5e7, n)
    return from_columns("gnss_obs", cols)


def test_observations_read_back_exactly(obs: pa.Table, tmp_path: Path) -> None:
    path = tmp_path / "x.obs"
    rinex.write_obs(path, obs, STATION, interval_s=1.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)  # georinex vs newer xarray, harmless
        ds = georinex.load(path)
    assert ds.attrs["version"] == 3.04
    assert ds.attrs["time_system"] == "GPS"
    assert ds.sizes["time"] == 3
    assert sorted(ds.sv.values.tolist()) == ["G03", "G07", "G11", "G24"]
    t = obs.column("t_ns").to_numpy()
    for i, sv in enumerate(obs.column("sv").to_pylist()):
        k = int((t[i] - T0) // NS_PER_S)
        rec = ds.sel(sv=sv).isel(time=k)
        assert float(rec["C1C"]) == obs.column("pseudorange_m")[i].as_py()
        assert float(rec["S1C"]) == obs.column("cn0_dbhz")[i].as_py()
        rate = -float(rec["D1C"]) * LAMBDA_L1_M
        assert rate == pytest.approx(obs.column("pseudorange_rate_mps")[i].as_py(), abs=1e-9)
    # a satellite absent at an epoch is absent in the file
    assert np.isnan(float(ds.sel(sv="G24").isel(time=2)["C1C"]))
    text = path.read_text().splitlines()
    header_end = text.index(next(x for x in text if x.endswith("END OF HEADER")))
    assert all(len(x) <= 80 for x in text[: header_end + 1])
    assert text[header_end + 1] == "> 2026 11 18 02 30  0.0000000  0  3"


def _ephemeris() -> Ephemeris:
    rng = np.random.default_rng(2)
    n = 6

    def r(x: np.ndarray) -> np.ndarray:
        return np.array([float(f"{v:.12E}") for v in x])

    return Ephemeris.from_columns(
        prn=np.array([1, 5, 12, 1, 5, 12]),
        toc_ns=np.repeat([T0, T0 + 7200 * NS_PER_S], 3),
        toe_ns=np.repeat([T0, T0 + 7200 * NS_PER_S], 3),
        af0_s=r(rng.normal(0, 1e-4, n)),
        af1_sps=r(rng.normal(0, 1e-12, n)),
        af2_sps2=np.zeros(n),
        tgd_s=r(rng.normal(0, 5e-9, n)),
        sqrt_a_sqrtm=r(5153.6 + rng.normal(0, 0.1, n)),
        e=r(rng.uniform(0.0, 0.02, n)),
        i0_rad=r(0.96 + rng.normal(0, 0.01, n)),
        idot_radps=r(rng.normal(0, 1e-10, n)),
        omega0_rad=r(rng.uniform(-3, 3, n)),
        omega_dot_radps=r(-8e-9 + rng.normal(0, 1e-10, n)),
        arg_perigee_rad=r(rng.uniform(-3, 3, n)),
        m0_rad=r(rng.uniform(-3, 3, n)),
        delta_n_radps=r(rng.normal(4e-9, 1e-10, n)),
        cuc_rad=r(rng.normal(0, 1e-6, n)),
        cus_rad=r(rng.normal(0, 1e-6, n)),
        crc_m=r(rng.normal(200, 50, n)),
        crs_m=r(rng.normal(0, 50, n)),
        cic_rad=r(rng.normal(0, 1e-7, n)),
        cis_rad=r(rng.normal(0, 1e-7, n)),
        iode=np.array([10, 11, 12, 13, 14, 15]),
        iodc=np.array([10, 11, 12, 13, 14, 15]),
        health=np.zeros(n),
        accuracy_m=np.full(n, 2.0),
        fit_interval_h=np.full(n, 4.0),
        transmit_sow_s=np.repeat([-1800.0, 5400.0], 3),
    )


def test_navigation_records_read_back_exactly(tmp_path: Path) -> None:
    eph = _ephemeris()
    path = tmp_path / "x.nav"
    rinex.write_nav(path, eph)
    back = read_gps_nav(path)  # georinex's reading
    order = np.lexsort((back.toe_ns, back.prn))
    want = np.lexsort((eph.toe_ns, eph.prn))
    for name in Ephemeris._fields:
        np.testing.assert_array_equal(
            getattr(back, name)[order], getattr(eph, name)[want], err_msg=name
        )
    t = T0 + 1234 * NS_PER_S
    np.testing.assert_array_equal(orbit(back, order, t).pos_m, orbit(eph, want, t).pos_m)


def test_writing_twice_gives_identical_bytes(obs: pa.Table, tmp_path: Path) -> None:
    for k in range(2):
        rinex.write_obs(tmp_path / f"{k}.obs", obs, STATION, interval_s=1.0)
        rinex.write_nav(tmp_path / f"{k}.nav", _ephemeris())
    assert (tmp_path / "0.obs").read_bytes() == (tmp_path / "1.obs").read_bytes()
    assert (tmp_path / "0.nav").read_bytes() == (tmp_path / "1.nav").read_bytes()


def test_non_gps_satellites_are_refused(tmp_path: Path) -> None:
    table = from_columns(
        "gnss_obs",
        {
            "t_ns": np.array([T0]),
            "sv": ["R01"],
            "pseudorange_m": [2e7],
            "sat_x_m": [0.0],
            "sat_y_m": [0.0],
            "sat_z_m": [0.0],
        },
    )
    with pytest.raises(ValueError, match="only GPS"):
        rinex.write_obs(tmp_path / "r.obs", table, STATION, interval_s=1.0)
