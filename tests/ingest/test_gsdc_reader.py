"""GSDC CSVs (real excerpts in ../shared/data, read in place): measurements with Google's
satellite states and corrections into ``gnss_obs``, ground truth into ``truth``."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import numpy.typing as npt
import pyarrow.csv as pacsv
import pyarrow.parquet as pq
import pymap3d
import pytest

from navreplay.ingest.api import IngestOptions, ingest
from navreplay.ingest.errors import CorruptLogError
from navreplay.ingest.gnss import fixcheck
from navreplay.ingest.gnss.ephemeris import C_MPS, OMEGA_E_GPS
from navreplay.ingest.gnss.gsdc import sv_ids

GSDC = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "gnss_lib_py_gsdc_android"


@pytest.fixture(autouse=True)
def _data() -> None:
    if not GSDC.exists():
        pytest.skip(f"real data not present: {GSDC} (../shared/data is read in place)")


def _enu(pos: np.ndarray, lat: np.ndarray, lon: np.ndarray, alt: np.ndarray) -> np.ndarray:
    e, n, u = pymap3d.ecef2enu(pos[:, 0], pos[:, 1], pos[:, 2], lat, lon, alt)
    return np.stack([e, n, u], axis=1)


def test_satellite_ids_follow_rinex() -> None:
    cons = np.array([1, 3, 4, 5, 6, 2, 9])
    svid = np.array([5, 12, 193, 20, 11, 131, 1])
    assert sv_ids(cons, svid).tolist() == ["G05", "R12", "J01", "C20", "E11", "S31", "?01"]


def test_the_2021_derived_pair_solves_onto_its_ground_truth(tmp_path: Path) -> None:
    d = GSDC / "gsdc2021"
    result = ingest([d / "Pixel4_derived.csv", d / "Pixel4_ground_truth.csv"], tmp_path / "out")
    assert result.tables == {"gnss_obs": 148, "truth": 199}  # 198 signals: 35 E5a, 15 L5 out
    counters = result.report["tables"]["gnss_obs"]["counters"]
    assert counters["excluded_signal_GAL_E5A"] == 35
    assert counters["excluded_signal_GPS_L5"] == 15
    assert counters["epochs_restamped"] == 7  # every derived stamp was one epoch late
    obs = pq.read_table(tmp_path / "out" / "gnss_obs.parquet")
    truth = pq.read_table(tmp_path / "out" / "truth.parquet")
    assert np.unique(obs["t_ns"].to_numpy()).size == 7
    assert obs["pseudorange_rate_mps"].null_count == obs.num_rows  # not in the 2021 files
    assert {s[0] for s in obs["sv"].to_pylist()} == {"G", "R", "E"}
    # every epoch now falls on a ground-truth epoch
    assert np.isin(obs["t_ns"].to_numpy(), truth["t_ns"].to_numpy()).all()
    t, pos = fixcheck.solved_positions(obs)
    rows = np.searchsorted(truth["t_ns"].to_numpy(), t)
    lla = (truth[c].to_numpy()[rows] for c in ("lat_deg", "lon_deg", "alt_m"))
    err = _enu(pos, *lla)
    # measured: 8.4 m median horizontal, 0.6 m vertical mean once the hosts' 61 m height
    # correction is applied to the truth (59 m without it)
    assert np.median(np.hypot(err[:, 0], err[:, 1])) < 15.0
    assert abs(np.mean(err[:, 2])) < 10.0


def test_satellites_are_rotated_into_the_receive_time_frame(tmp_path: Path) -> None:
    path = GSDC / "gsdc2022" / "device_gnss.csv"
    result = ingest([path], tmp_path / "out")
    assert result.tables == {"gnss_obs": 118}
    counters = result.report["tables"]["gnss_obs"]["counters"]
    assert counters["excluded_no_satellite_state"] == 80
    assert counters["excluded_signal_GPS_L5"] == counters["excluded_signal_GAL_E5A"] == 18
    obs = pq.read_table(tmp_path / "out" / "gnss_obs.parquet")
    types = pacsv.ConvertOptions(column_types={"SignalType": "string"})
    csv = pacsv.read_csv(path, convert_options=types)
    signal = csv["SignalType"].to_numpy(zero_copy_only=False)
    csv = csv.filter(np.isin(signal, ["GPS_L1", "GAL_E1", "GLO_G1", "BDS_B1I"]))
    # match rows through the ECEF z, which the rotation about z leaves unchanged
    z = obs["sat_z_m"].to_numpy()
    z_csv = csv["SvPositionZEcefMeters"].to_numpy()
    k = np.array([int(np.argmin(np.abs(z_csv - v))) for v in z])
    assert np.unique(k).size == k.size == csv.num_rows

    def col(name: str) -> npt.NDArray[np.float64]:
        values: npt.NDArray[np.float64] = np.asarray(csv[name].to_numpy(), dtype=np.float64)
        return np.asarray(values[k], dtype=np.float64)

    np.testing.assert_array_equal(z, col("SvPositionZEcefMeters"))
    x_csv, y_csv = col("SvPositionXEcefMeters"), col("SvPositionYEcefMeters")
    ours = np.arctan2(obs["sat_y_m"].to_numpy(), obs["sat_x_m"].to_numpy())
    angle = np.arctan2(y_csv, x_csv) - ours
    rx = np.stack([col(f"WlsPosition{a}EcefMeters") for a in "XYZ"], axis=1)
    sat = np.stack([x_csv, y_csv, z], axis=1)
    expected = OMEGA_E_GPS * np.linalg.norm(sat - rx, axis=1) / C_MPS  # about 5e-6 rad
    np.testing.assert_allclose(angle, expected, rtol=1e-9, atol=1e-12)
    # corrections carried over; the pseudorange is on the GPS L1 clock (ISRB removed)
    pr = col("RawPseudorangeMeters") - col("IsrbMeters")
    np.testing.assert_array_equal(obs["pseudorange_m"].to_numpy(), pr)
    np.testing.assert_array_equal(obs["tropo_delay_m"].to_numpy(), col("TroposphericDelayMeters"))
    np.testing.assert_array_equal(obs["cn0_dbhz"].to_numpy(), col("Cn0DbHz"))
    el = obs["elevation_deg"].to_numpy()
    np.testing.assert_allclose(el, col("SvElevationDegrees"), rtol=0, atol=0.05)


def test_the_2022_ground_truth_and_a_truncated_copy(tmp_path: Path) -> None:
    truth_csv = GSDC / "gsdc2022" / "ground_truth.csv"
    result = ingest([GSDC / "gsdc2022" / "device_gnss.csv", truth_csv], tmp_path / "out")
    assert result.tables["truth"] == 200
    assert result.report["time_base"]["base"] == "gps"
    assert result.report["time_base"]["leap_seconds"] == 18
    truth = pq.read_table(tmp_path / "out" / "truth.parquet")
    assert truth["lat_deg"].to_numpy()[0] == 37.395817
    assert truth["yaw_rad"].null_count == 200
    cut = tmp_path / "ground_truth.csv"
    cut.write_bytes(truth_csv.read_bytes()[:-5])
    result = ingest([cut], tmp_path / "cut")
    assert result.tables["truth"] == 199
    (defect,) = result.report["files"][0]["defects"]
    assert defect["kind"] == "truncated"
    assert defect["offset"] == 201
    with pytest.raises(CorruptLogError, match=r"ground_truth\.csv: line 201"):
        ingest([cut], tmp_path / "strict", options=IngestOptions(strict=True))


def test_the_2021_excerpt_with_skipped_epochs_is_restamped_per_epoch(tmp_path: Path) -> None:
    result = ingest([GSDC / "gsdc2021" / "Pixel4XL_derived.csv"], tmp_path / "out")
    assert result.tables["gnss_obs"] == 6966 - 446 - 421 - 14  # less E5a, L5 and J5 signals
    obs = pq.read_table(tmp_path / "out" / "gnss_obs.parquet")
    assert np.unique(obs["t_ns"].to_numpy()).size == 286
    t, pos = fixcheck.solved_positions(obs)
    assert t.size > 280
    # consecutive solutions of a car moving at road speed: no epoch re-stamped by the
    # wrong amount (a second off would show as a jump of the car's speed times a second)
    assert np.median(np.linalg.norm(np.diff(pos, axis=0), axis=1)) < 200.0
