"""The onboard EKF's test ratios and innovations joined to its estimate, each record of the
same core nearest in time (ArduPilot XKF4 and XKF3 onto XKF1; PX4 1.9 ekf2_innovations)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from navreplay.ingest.api import ingest
from navreplay.ingest.schema import ESTIMATOR_INNOVATIONS, ESTIMATOR_TEST_RATIOS
from navreplay.ingest.tables import read_table
from tests.ingest.mavlogs import df_drive, mav, tlog_drive

SHARED = Path(__file__).resolve().parents[3] / "shared" / "data"
XKF3 = (45, "QBcccccc", "TimeUS,C,IVN,IVE,IVD,IPN,IPE,IPD")
XKF4 = (46, "QBcccc", "TimeUS,C,SV,SP,SH,SM")


def test_xkf3_and_xkf4_join_the_estimate_of_their_core(tmp_path: Path) -> None:
    log = df_drive(seconds=2.0)  # XKF1 of cores 0 and 1 every 100 ms from TimeUS 50 s (+30 us)
    log.fmt("XKF3", XKF3)
    log.fmt("XKF4", XKF4)
    for i in range(20):
        t = 50_000_000 + i * 100_000 + 40
        for core in (0, 1):  # core 1's values are ten times core 0's: a mix-up would show
            k = 10 if core else 1
            log.write("XKF3", t + core, core, k * i, -k * i, 5 * k, 2 * k, -2 * k, 30 * k)
            log.write("XKF4", t + core, core, 10 * k, 20, 30, 40)
    out = tmp_path / "out"
    ingest([log.save(tmp_path / "f.bin")], out)
    est = read_table(out / "estimator.parquet", "estimator").table.to_pandas()
    assert set(ESTIMATOR_INNOVATIONS) <= set(est.columns)
    assert set(ESTIMATOR_TEST_RATIOS) <= set(est.columns)
    np.testing.assert_allclose(est["innov_vel_n_mps"], np.arange(20) * 0.01)  # cm/s -> m/s
    np.testing.assert_allclose(est["innov_vel_e_mps"], -np.arange(20) * 0.01)
    np.testing.assert_allclose(est["innov_pos_d_m"], 0.30)
    np.testing.assert_allclose(est["test_ratio_vel"], 0.10)  # core 0's, not core 1's
    np.testing.assert_allclose(est["test_ratio_mag"], 0.40)


@pytest.mark.parametrize(
    ("rel", "matched"),
    [
        ("uob_flightlab_ardupilot_bin/2023-07-06_10-12-18.bin", 981),  # XKF3 with every XKF1
        ("corpus_2026/ap_copter33_2015_log171.bin", 2383),  # EKF3 with every EKF1
        ("corpus_2026/px4_v190_fmuv3_flight.ulg", 144),  # ekf2_innovations at 5 Hz of ~10
    ],
)
def test_real_logs_carry_the_onboard_innovations(tmp_path: Path, rel: str, matched: int) -> None:
    path = SHARED / rel
    if not path.is_file():
        pytest.skip(f"real data not present: {path} (../shared/data is read in place)")
    ingest([path], tmp_path / "out")
    est = read_table(tmp_path / "out" / "estimator.parquet", "estimator").table.to_pandas()
    vel_n = est["innov_vel_n_mps"].dropna()
    assert len(vel_n) == matched
    # a healthy EKF's innovations centre on zero and stay within a few m/s and metres
    assert abs(vel_n.mean()) < 0.15
    assert est[list(ESTIMATOR_INNOVATIONS)].abs().max().max() < 20.0


def test_tlog_ekf_status_report_gives_the_test_ratios(tmp_path: Path) -> None:
    log = tlog_drive()  # GLOBAL_POSITION_INT + ATTITUDE every 100 ms over 4 s
    link = mav()
    gpi = [i for i, n in enumerate(log.names) if n == "GLOBAL_POSITION_INT"]
    for k, i in enumerate(gpi):
        flags = 0 if k < 5 else 0x1FF  # no solution for the first half second
        report = link.ekf_status_report_encode(flags, 0.01 * k, 0.2, 0.3, 0.4, 0.0)
        log.add(log.stamps_us[i] + 1_000, link, report)
    order = np.argsort(log.stamps_us, kind="stable")
    records = log.records()
    path = log.write(tmp_path / "f.tlog", [records[i] for i in order])
    ingest([path], tmp_path / "out")
    est = read_table(tmp_path / "out" / "estimator.parquet", "estimator").table.to_pandas()
    assert len(est) == len(gpi)
    assert est["test_ratio_vel"].iloc[:5].isna().all()  # flags 0: no ratio, not a zero
    np.testing.assert_allclose(est["test_ratio_vel"].iloc[5:], 0.01 * np.arange(5, len(gpi)),
                               rtol=1e-6)  # fmt: skip
    np.testing.assert_allclose(est["test_ratio_mag"].iloc[5:], 0.4, rtol=1e-6)
    assert est["roll_rad"].notna().all()  # the attitude join still holds


def test_a_real_bench_tlog_reports_its_ekf_test_ratios(tmp_path: Path) -> None:
    path = SHARED / "corpus_2026" / "ap_copter34_bench_2016_tlog.log"
    if not path.is_file():
        pytest.skip(f"real data not present: {path} (../shared/data is read in place)")
    ingest([path], tmp_path / "out")
    est = read_table(tmp_path / "out" / "estimator.parquet", "estimator").table.to_pandas()
    assert est["test_ratio_vel"].notna().sum() == 24  # of 26 estimates; the first two precede it
    assert est[list(ESTIMATOR_TEST_RATIOS)].max().max() < 0.1  # on the bench, nothing rejected
