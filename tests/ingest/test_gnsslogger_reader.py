"""Android GnssLogger logs: a log written from the synthesizer round-trips (pseudoranges,
satellite states, fixes, IMU axes), damaged lines are counted, and the real logs of
``../shared/data`` ingest with their documented counts and a position within metres of the
phone's own fixes."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pyarrow.parquet as pq
import pymap3d
import pytest

from navreplay.ingest.api import IngestOptions, ingest
from navreplay.ingest.errors import CorruptLogError
from navreplay.ingest.gnss import spp
from navreplay.ingest.gnss.ephemeris import C_MPS, orbit, rotate_earth, select
from navreplay.ingest.writers import rinex

from .gnssfiles import assert_obs_match, short_drive
from .gnsslogs import write_gnsslogger
from .navfile import read_gps_nav

SHARED = Path(__file__).resolve().parents[2].parent / "shared" / "data"
ANDROID = SHARED / "gps_measurement_tools" / "android_raw_2016"
GSDC = SHARED / "gnss_lib_py_gsdc_android"


@pytest.fixture(scope="module")
def synth() -> Any:
    return short_drive()


def _log_and_nav(tmp_path: Path, synth: Any) -> tuple[Path, Path, dict[str, int]]:
    log, nav = tmp_path / "gnss_log.txt", tmp_path / "brdc.nav"
    counts = write_gnsslogger(log, synth)
    rinex.write_nav(nav, synth.ephemeris)
    return log, nav, counts


def test_a_log_written_from_the_synthesizer_comes_back(synth: Any, tmp_path: Path) -> None:
    log, nav, counts = _log_and_nav(tmp_path, synth)
    result = ingest([log, nav], tmp_path / "out")
    ref = synth.tables["gnss_obs"]
    assert result.tables["gnss_obs"] == ref.num_rows == counts["gps"]
    got = pq.read_table(tmp_path / "out" / "gnss_obs.parquet")
    np.testing.assert_array_equal(got["t_ns"].to_numpy(), ref["t_ns"].to_numpy())
    np.testing.assert_allclose(
        got["pseudorange_m"].to_numpy(), ref["pseudorange_m"].to_numpy(), rtol=0, atol=1e-6
    )
    exact = (
        ref.drop_columns(["pseudorange_m"]).set_column(2, "pseudorange_m", got["pseudorange_m"])
        if False
        else None
    )
    del exact
    got_exact_pr = got.set_column(
        got.schema.get_field_index("pseudorange_m"), "pseudorange_m", ref["pseudorange_m"]
    )
    assert_obs_match(ref, got_exact_pr)
    for col in ("pseudorange_std_m", "pseudorange_rate_std_mps"):
        np.testing.assert_allclose(got[col].to_numpy(), ref[col].to_numpy(), rtol=1e-9)
    counters = result.report["tables"]["gnss_obs"]["counters"]
    assert counters["excluded_constellation_GLONASS"] == counts["glonass"]
    assert counters["excluded_tow_not_decoded"] == counts["tow_not_decoded"]
    assert counters["excluded_not_l1"] == counts["l5"]
    # Fix: the GPS provider; h_acc from the 68 % radius
    fix = pq.read_table(tmp_path / "out" / "gnss.parquet")
    gref = synth.tables["gnss"]
    assert fix.num_rows == counts["fix"]
    for col in ("lat_deg", "lon_deg", "alt_m"):
        np.testing.assert_array_equal(fix[col].to_numpy(), gref[col].to_numpy())
    np.testing.assert_allclose(fix["h_acc_m"].to_numpy(), gref["h_acc_m"].to_numpy(), rtol=1e-12)
    np.testing.assert_allclose(
        fix["vel_n_mps"].to_numpy(), gref["vel_n_mps"].to_numpy(), rtol=0, atol=1e-9
    )
    assert fix["vel_d_mps"].null_count == fix.num_rows
    # IMU: phone axes back to body FRD, exactly; times on GPS within the ms pairing
    imu, iref = pq.read_table(tmp_path / "out" / "imu.parquet"), synth.tables["imu"]
    assert imu.num_rows == iref.num_rows
    for col in iref.column_names[1:]:
        np.testing.assert_array_equal(imu[col].to_numpy(), iref[col].to_numpy(), err_msg=col)
    assert np.abs(imu["t_ns"].to_numpy() - iref["t_ns"].to_numpy()).max() <= 1_000_000
    assert result.report["tables"]["imu"]["plausibility"]["mounting"]["source"] == "none"
    files = result.report["files"][0]
    assert files["counters"]["lines_not_used"] == counts["status"]


def test_damaged_lines_are_skipped_with_their_line_numbers(synth: Any, tmp_path: Path) -> None:
    log, nav, counts = _log_and_nav(tmp_path, synth)
    lines = log.read_text().splitlines(keepends=True)
    raw = [i for i, ln in enumerate(lines) if ln.startswith("Raw,") and ",16399," in ln]
    lines[raw[3]] = lines[raw[3]].replace(",", ",,", 1)  # one field too many
    fixes = [i for i, ln in enumerate(lines) if ln.startswith("Fix,GPS")]
    lines[fixes[2]] = lines[fixes[2]].replace(".", "co.", 1)  # "-29co.199999" as in a real log
    text = "".join(lines)
    log.write_text(text[:-7])  # the last line cut short
    result = ingest([log, nav], tmp_path / "out")
    report = result.report["files"][0]
    assert sorted(d["kind"] for d in report["defects"]) == ["bad_data_skipped", "truncated"]
    bad = next(d for d in report["defects"] if d["kind"] == "bad_data_skipped")
    assert bad["offset"] == raw[3] + 1
    assert report["counters"]["unreadable_numbers_Fix"] == 1
    assert result.tables["gnss_obs"] == counts["gps"] - 1
    assert result.tables["gnss"] == counts["fix"]  # kept, its latitude NaN (invalid)
    assert result.report["tables"]["gnss"]["stats"]["nonfinite"]["lat_deg"]["nan"] == 1
    with pytest.raises(CorruptLogError, match=rf"gnss_log.txt: line {raw[3] + 1}:"):
        ingest([log, nav], tmp_path / "strict", options=IngestOptions(strict=True))


def test_raw_measurements_without_navigation_are_not_converted(synth: Any, tmp_path: Path) -> None:
    log, _, _ = _log_and_nav(tmp_path, synth)
    result = ingest([log], tmp_path / "out")
    assert set(result.tables) == {"imu", "gnss"}
    streams = {s["key"]: s for s in result.report["files"][0]["streams"]}
    assert "needs the RINEX navigation file" in streams["Raw:GPS"]["detail"]


# ---------------------------------------------------------------------------- real logs
def _skip_without(path: Path) -> None:
    if not path.exists():
        pytest.skip(f"real data not present: {path} (../shared/data is read in place)")


ANDROID_LOGS = [
    ("pseudoranges_log_2016_08_22_14_45_50.txt", "hour2350.16n", 5041, 207, 2055, 200),
    ("pseudoranges_log_2016_06_30_21_26_07.txt", "hour1820.16n", 1379, 216, 1376, 223),
]


@pytest.mark.parametrize(("log", "nav", "raw", "fixes", "rows", "epochs"), ANDROID_LOGS)
def test_the_static_phone_logs_solve_to_within_metres_of_their_fixes(
    tmp_path: Path, log: str, nav: str, raw: int, fixes: int, rows: int, epochs: int
) -> None:
    _skip_without(ANDROID)
    result = ingest([ANDROID / log, ANDROID / nav], tmp_path / "out")
    streams = {s["key"]: s for s in result.report["files"][0]["streams"]}
    assert f"{raw} Raw rows" in streams["Raw:GPS"]["detail"]  # SOURCE.txt counts
    assert result.tables["gnss"] == fixes
    assert result.tables["gnss_obs"] == rows
    counters = result.report["tables"]["gnss_obs"]["counters"]
    assert counters["no_ephemeris"] == 0
    assert sum(v for k, v in counters.items() if k.startswith("excluded_")) == raw - rows
    obs = pq.read_table(tmp_path / "out" / "gnss_obs.parquet")
    fix = pq.read_table(tmp_path / "out" / "gnss.parquet")
    assert np.unique(obs["t_ns"].to_numpy()).size == epochs
    el, az = obs["elevation_deg"].to_numpy(), obs["azimuth_deg"].to_numpy()
    assert el.min() > 0.0
    assert el.max() < 90.0
    assert az.min() >= 0.0
    assert az.max() < 360.0
    # A least-squares position per epoch (elevation >= 10 deg, broadcast iono, a standard
    # troposphere): its mean lies within 10 m of the phone's mean fix (measured 5.7 / 4.6 m).
    use = obs.filter(obs["elevation_deg"].to_numpy() >= 10.0)
    t = use["t_ns"].to_numpy()
    corr = (
        use["pseudorange_m"].to_numpy()
        + use["sat_clock_m"].to_numpy()
        - use["iono_delay_m"].to_numpy()
        - spp.tropo_delay_m(np.radians(use["elevation_deg"].to_numpy()), np.zeros(t.size))
    )
    sat = np.stack([use[f"sat_{a}_m"].to_numpy() for a in "xyz"], axis=1)
    epoch, starts = spp.epoch_index(t)
    sol = spp.solve(sat, corr, epoch, starts.size)
    assert sol.solved.mean() > 0.95
    mean_fix = np.stack(
        pymap3d.geodetic2ecef(
            fix["lat_deg"].to_numpy(), fix["lon_deg"].to_numpy(), fix["alt_m"].to_numpy()
        ),
        axis=1,
    ).mean(axis=0)
    error = np.linalg.norm(sol.ecef_m[sol.solved].mean(axis=0) - mean_fix)
    assert error < 10.0
    # Satellite positions against the navigation file read by georinex, with the transmit
    # time taken from the pseudorange (RTKLIB's way, not the light-time iteration ingest
    # uses) and the Sagnac rotation from the fix: the two agree to millimetres.
    eph = read_gps_nav(ANDROID / nav)
    prn = np.array([int(s[1:]) for s in obs["sv"].to_pylist()])
    t_all = obs["t_ns"].to_numpy()
    travel_s = obs["pseudorange_m"].to_numpy() / C_MPS
    idx = select(eph, prn, t_all)
    first = orbit(eph, idx, t_all, -travel_s)
    st = orbit(eph, idx, t_all, -travel_s - first.clock_s)
    sat_all = np.stack([obs[f"sat_{a}_m"].to_numpy() for a in "xyz"], axis=1)
    tau = np.linalg.norm(st.pos_m - mean_fix, axis=1) / C_MPS
    np.testing.assert_allclose(rotate_earth(st.pos_m, tau), sat_all, rtol=0, atol=0.05)


def test_the_pixel4_log_gives_imu_and_fixes(tmp_path: Path) -> None:
    log = GSDC / "gsdc2021" / "Pixel4_GnssLog.txt"
    _skip_without(log)
    result = ingest([log], tmp_path / "out")
    files = result.report["files"][0]
    notes = " ".join(files["inventory_notes"])
    for kind, n in (
        ("Raw", 29),
        ("Accel", 22),
        ("Gyro", 22),
        ("Mag", 7),
        ("Fix", 5),
        ("Status", 14),
    ):
        assert f"{kind}: {n} records" in notes
    assert result.tables["gnss"] == 2  # the GPS provider's fixes (NLP and FLP are listed only)
    assert files["counters"]["unreadable_numbers_Fix"] == 1  # "-29co.199999" in the NLP fix
    imu = pq.read_table(tmp_path / "out" / "imu.parquet")
    assert 15 <= imu.num_rows <= 22  # accelerometer samples inside the gyro's span
    acc = np.stack([imu[f"acc_{a}_mps2"].to_numpy() for a in "xyz"], axis=1)
    assert np.linalg.norm(acc, axis=1).mean() == pytest.approx(9.8, abs=0.6)
