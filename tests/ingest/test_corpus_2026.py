"""The autopilot logs of ``../shared/data/corpus_2026`` (and the older real IMU logs), read in
place and skipped when absent (issue 23): each ingests into tables or is refused with an exact
reason, never a traceback; what a log cannot give an INS/GNSS replay is in ``limits``.

Counts are those of the files (SOURCES.tsv): Copter 3.3 log171 has 3 IMUs at 49 Hz, GPS at 5 Hz
and EKF1; the 2015 PX4 sdlog2 log IMU and IMU1 at 81 Hz and GPS at 5 Hz.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pyarrow.parquet as pq
import pytest

from navreplay.ingest.api import IngestResult, ingest
from navreplay.ingest.timebase import SECONDS_PER_WEEK

DATA = Path(__file__).resolve().parents[3] / "shared" / "data"
CORPUS = DATA / "corpus_2026"
WEEK_NS = SECONDS_PER_WEEK * 10**9


def need(path: Path) -> Path:
    if not path.exists():
        pytest.skip(f"{path} is absent (../shared/data is not beside the checkout)")
    return path


def run(name: str, tmp_path: Path) -> IngestResult:
    return ingest([need(CORPUS / name)], tmp_path / "out")


def frame(tmp_path: Path, table: str) -> Any:
    return pq.read_table(tmp_path / "out" / f"{table}.parquet").to_pandas()


def codes(result: IngestResult) -> dict[str, str]:
    return {lim["code"]: lim["reason"] for lim in result.report["limits"]}


def test_copter33_2015_timems_log(tmp_path: Path) -> None:
    result = run("ap_copter33_2015_log171.bin", tmp_path)
    assert result.tables == {
        "imu": 11916, "gnss": 1198, "estimator": 2383, "mag": 2384, "events": 13,
    }  # fmt: skip
    assert result.report["time_base"]["base"] == "gps"
    assert result.report["limits"] == []
    notes = result.report["files"][0]["inventory_notes"]
    assert notes[0].startswith("TimeMS paired with GPS week/ms")
    assert notes[1].startswith("platform: APM:Copter V3.3-dev (ae3192b8); PX4: 60133536")
    gnss = frame(tmp_path, "gnss")
    assert (gnss["t_ns"] // WEEK_NS == 1871).all()  # November 2015, not moved by 1024 weeks
    assert gnss["lat_deg"][gnss["fix_type"] >= 3].between(-35.37, -35.36).all()  # CMAC
    imu = frame(tmp_path, "imu")
    assert imu["t_ns"].diff().median() == 20_000_000  # TimeMS at 50 Hz
    assert imu["t_ns"].iloc[0] - gnss["t_ns"].iloc[0] == pytest.approx(0, abs=2e9)
    # EKF1 (no ORGN in 2015): placed on the earth from the fixes, it follows them (0.73 m RMS).
    est = frame(tmp_path, "estimator")
    fixed = gnss[gnss["fix_type"] >= 3]
    t = fixed["t_ns"].to_numpy()
    inside = (t >= est["t_ns"].iloc[0]) & (t <= est["t_ns"].iloc[-1])
    dn = (fixed["lat_deg"].to_numpy() - np.interp(t, est["t_ns"], est["lat_deg"]))[inside]
    de = (fixed["lon_deg"].to_numpy() - np.interp(t, est["t_ns"], est["lon_deg"]))[inside]
    rms_m = 111_320 * np.sqrt(np.mean(dn**2 + (de * np.cos(np.radians(-35.36))) ** 2))
    assert rms_m < 1.5


def test_px4_sdlog2_2015_log(tmp_path: Path) -> None:
    result = run("px4_sdlog2_2015_purdue.px4log", tmp_path)
    assert result.tables == {"imu": 5742, "gnss": 354, "mag": 5742}
    notes = result.report["files"][0]["inventory_notes"]
    assert "platform: PX4FMU_V2 44d2c4a1e5c0a044a1cbf69bc1199454f9c0238c" in notes
    assert result.report["time_base"]["base"] == "gps"
    gnss = frame(tmp_path, "gnss")
    assert gnss["lat_deg"].between(40.46, 40.47).all()  # Purdue
    assert gnss["t_ns"].diff().median() == pytest.approx(0.2e9, rel=0.1)  # 5 Hz, not 1 Hz


def test_truncated_2024_log(tmp_path: Path) -> None:
    result = run("ap_copter462_2024_trunc80k.bin", tmp_path)
    entry = result.report["files"][0]
    assert entry["completeness"] == ["partial_record_dropped"]
    assert "at offset 81918 (2 bytes)" in entry["defects"][0]["reason"]
    assert codes(result)["short_overlap"].startswith(
        "IMU samples and 3-D GNSS fixes overlap for 0.20 s (IMU 0.37 s, 10 samples"
    )


def test_bench_tlog_named_log_has_no_fix(tmp_path: Path) -> None:
    result = run("ap_copter34_bench_2016_tlog.log", tmp_path)
    assert result.report["files"][0]["format"] == "tlog"
    assert codes(result)["gnss_no_fix"].startswith(
        "no GPS fix in the log: 26 GPS records (GPS_RAW_INT), all with fix type < 3"
    )


def test_px4_low_rate_profile_imu_is_refused(tmp_path: Path) -> None:
    result = run("px4_v190_fmuv3_flight.ulg", tmp_path)
    assert "imu" not in result.tables
    assert result.tables["gnss"] == 179
    reason = codes(result)["imu_refused"]
    assert "sensor_combined[0] has 341 samples over 39.5 s" in reason
    assert "only 3.4 % of the time is measured" in reason


def test_px4_sitl_truth(tmp_path: Path) -> None:
    result = run("px4_v190_sitl_truth.ulg", tmp_path)
    assert result.tables["truth"] == 610
    gnss, truth = frame(tmp_path, "gnss"), frame(tmp_path, "truth")
    assert gnss["vel_n_mps"].notna().all()  # vel_ned_valid never set by SITL
    t = gnss["t_ns"].to_numpy()
    inside = (t >= truth["t_ns"].iloc[0]) & (t <= truth["t_ns"].iloc[-1])
    for col, tol in (("vel_n_mps", 0.3), ("alt_m", 0.5)):
        ref = np.interp(t[inside], truth["t_ns"], truth[col])
        assert np.sqrt(np.mean((gnss[col].to_numpy()[inside] - ref) ** 2)) < tol, col


def test_static_pyulog_sample(tmp_path: Path) -> None:
    result = ingest([need(DATA / "pyulog_samples" / "sample_log_small.ulg")], tmp_path / "out")
    assert "gnss_static" in codes(result)


LOGS = (
    [
        *(
            f"corpus_2026/{n}"
            for n in sorted(
                p.name
                for p in CORPUS.glob("*.*")
                if p.suffix in (".bin", ".ulg", ".log", ".px4log")
            )
        ),
        "uavlogviewer_sitl_tlog/vtol.tlog",
        "uob_flightlab_ardupilot_bin/2023-07-06_10-12-18.bin",
        "pyulog_samples/sample.ulg",
        "pyulog_samples/sample_log_small.ulg",
    ]
    if CORPUS.is_dir()
    else ["corpus_2026"]
)


@pytest.mark.parametrize("log", LOGS)
def test_cli_ingest_ends_in_tables_or_an_exact_reason(
    log: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # the command's own entry point in this process (a traceback would fail the test here,
    # as it would print one in a shell), without a new interpreter's imports per log
    from navreplay.pipeline.cli import main

    path = need(DATA / log)
    rc = main(["ingest", str(path), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert rc in (0, 2), err[-2000:]
    if rc == 0:
        assert (tmp_path / "out" / "ingest_report.json").is_file()
    else:
        assert f"{path}:" in err  # the error names the file
