"""``navreplay analyze`` on every real log of ../shared/data (skipped when it is absent).

Each log is analyzed as a new user would: in a subprocess, from an empty directory, with the
built-in parameters, ``lc_ekf`` under ``nominal`` and ``outage_60s`` (fitted to the log).
The table says what each must give: the exit status, the status of each run, the words of
the reason when a run cannot be trusted or made, and for the runs that finish the accuracy
against the truth (or the fixes where the log has none). None may print a traceback.

Where the outcome is not an estimate, the reason is the log's (a bench log without a fix, a
truncated log, an IMU logged at 8.6 Hz integrating 4 ms of every 116) or the filters' current
limit, said in the run. A multirotor takes its heading from motion (``heading``) and its
compass: the PX4 SITL flight with truth gets one from before take-off, the 2023 ArduCopter
flight from its compass at arming. Where the log has an onboard estimator, ingest measures
how late the fixes are against it (``gnss latency``, 0.16-0.24 s on the SITL flights and the
2015 ArduCopter) and the filters apply each fix at its epoch: the SITL flights' errors against
their truth fell from 0.38 to 0.07 m (PX4) and 2.96 to 0.90 m (VTOL). The 2015 ArduCopter
flight ends in a crash (35 rad/s, 11 g, then upside down at rest): the tumble ends the
estimate, and the vehicle never moves again for a second alignment. The 2015 PX4 log does not
say what vehicle it is, so its heading comes from the course. The Husky robot never moves fast
enough for a course from neighbouring fixes (they carry no velocity, and differenced 0.4 s
apart their speed noise is 1.4 m/s against its 1 m/s), and at 1 m/s its accelerations give a
heading from motion no better than 9 degrees: it starts from the course of fixes differenced
over 9-20 s (``alignment._slow_course``), 2.6 m RMS of its fixes (whose errors, without a
receiver velocity to learn them from, are taken as correlated over 30 s).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

import pytest

DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data"


@dataclass(frozen=True)
class Expect:
    """What ``analyze`` gives on a log.

    Attributes:
        rc: exit status.
        status: scenario -> status of the lc_ekf run ("skipped" for a filter that cannot
            run on the log at all).
        reason: words every run that is not ok or inconsistent gives (or the error's).
        reference, max_rms_m: what the finished runs' nominal error is measured against
            (the truth, or the fixes it fused: a residual), and its bound.
        onboard_max_m: where the log has an onboard estimate, the bound of the nominal run's
            horizontal RMS difference from it.
        onboard_tests: the log records the onboard EKF's innovation test ratios.
    """

    rc: int
    status: dict[str, str] = field(default_factory=dict)
    reason: str = ""
    reference: str = ""
    max_rms_m: float = 0.0
    onboard_max_m: float | None = None
    onboard_tests: bool = False


ROBOT = Expect(0, {"nominal": "ok", "outage_60s": "ok"}, "", "fixes_residual", 3.0)
# The Husky drive comes in five containers that ingest to identical tables
# (tests/ingest/test_robot_localization.py), so an analysis of each would repeat one result:
# the ROS 1 bag (a file) and the rosbag2 sqlite3 folder (a directory given as the log) stand
# for them.
LOGS: dict[str, tuple[str, Expect]] = {
    "husky_ros1_bag": ("robot_localization/test1.bag", ROBOT),
    "husky_rosbag2_sqlite3": ("robot_localization/derived/test1_rosbag2_sqlite3", ROBOT),
    "comma2k19": (
        "comma2k19_example_segment/original",
        Expect(0, {"nominal": "ok", "outage_60s": "ok"}, "", "truth", 6.0),
    ),
    "comma2k19_csv_copies": (
        "comma2k19_example_segment/derived_csv",
        Expect(2, reason="nor a comma2k19 segment"),  # CSVs need a dataset.yaml
    ),
    # the ArduCopter flight (IMU logged at 25 Hz): the heading from its compass at arming,
    # held still by the zero-velocity updates until take-off; 0.8 m RMS of its fixes, but the
    # velocity innovations are larger than the filter's covariance says (inconsistent, not ok)
    "ardupilot_copter_2023": (
        "uob_flightlab_ardupilot_bin/2023-07-06_10-12-18.bin",
        Expect(
            0,
            {"nominal": "inconsistent", "outage_60s": "inconsistent"},
            "",
            "fixes_residual",
            1.5,
            0.6,
            onboard_tests=True,
        ),
    ),
    "sitl_vtol_tlog": (
        "uavlogviewer_sitl_tlog/vtol.tlog",
        Expect(0, {"nominal": "ok", "outage_60s": "ok"}, "", "truth", 1.5, 0.5),
    ),
    "px4_sample_no_gnss": (
        "pyulog_samples/sample.ulg",
        Expect(3, {"nominal": "skipped"}, "loose coupling needs GNSS fixes"),
    ),
    "px4_sample_static": (
        "pyulog_samples/sample_log_small.ulg",
        Expect(3, {"nominal": "not_aligned", "outage_60s": "skipped"}, "never aligned"),
    ),
    "ardupilot_copter_2015_timems": (
        "corpus_2026/ap_copter33_2015_log171.bin",
        Expect(0, {"nominal": "ok", "outage_60s": "ok"}, "", "fixes_residual", 1.5, 1.5, True),
    ),
    "ardupilot_copter_2024_truncated": (
        "corpus_2026/ap_copter462_2024_trunc80k.bin",
        Expect(3, {"nominal": "not_aligned", "outage_60s": "skipped"}, "never aligned"),
    ),
    "ardupilot_plane_2022_no_imu": (
        "corpus_2026/ap_plane423_2022_ground_noimu.bin",
        Expect(3, {"nominal": "skipped"}, "no IMU stream"),
    ),
    "ardupilot_copter_2016_bench_tlog": (
        "corpus_2026/ap_copter34_bench_2016_tlog.log",
        Expect(3, {"nominal": "skipped"}, "no GPS fix in the log: 26 GPS records"),
    ),
    # a multirotor whose log does not say so (platform unknown, so the course starts it): the
    # heading from motion, 69 deg from the course there, overrules it; 2.7 m RMS of its fixes
    "px4_2015_sdlog2": (
        "corpus_2026/px4_sdlog2_2015_purdue.px4log",
        Expect(0, {"nominal": "inconsistent", "outage_60s": "ok"}, "", "fixes_residual", 4.0),
    ),
    "px4_v190_low_rate_imu": (
        "corpus_2026/px4_v190_fmuv3_flight.ulg",
        Expect(3, {"nominal": "skipped"}, "only 3.4 % of the time is measured"),
    ),
    # a multirotor: the heading from motion (its course is not its heading), from before
    # take-off; 0.07 m against the simulator's truth with the fixes' 0.16 s latency (0.38 m
    # without); the zero-velocity updates on the ground after landing find the vertical
    # velocity off by more than their 0.02 m/s sigma allows (inconsistent: one of two 10 s
    # windows at a mean NIS of 6.1 per dof); with the 10 s outage it aligns 0.2 s earlier
    # and its standstill windows pass (ok)
    "px4_v190_sitl": (
        "corpus_2026/px4_v190_sitl_truth.ulg",
        Expect(0, {"nominal": "inconsistent", "outage_60s": "ok"}, "", "truth", 0.2, 0.4, True),
    ),
}


# what the summary says the log itself said (``report.events.summary``)
LOG_SAYS = {
    "ardupilot_copter_2015_timems": "the log says: modes LOITER > ACRO; 1 error (EKF check: "
    "error 2)",
    "ardupilot_copter_2023": "the log says: modes LOITER > RTL; vibration up to 51.6 m/s^2",
    "sitl_vtol_tlog": "the log says: modes QLOITER > CIRCLE > GUIDED > QLAND; vibration up to",
}


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(LOGS))
def test_analyze_gives_each_real_log_its_outcome(name: str, tmp_path: Path) -> None:
    rel, want = LOGS[name]
    log = DATA / rel
    if not log.exists():
        pytest.skip(f"{log} absent (../shared/data is not beside the checkout)")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    done = subprocess.run(
        [sys.executable, "-m", "navreplay.pipeline.cli", "analyze", str(log), "--filters",
         "lc_ekf", "--scenarios", "nominal,outage_60s", "--out", "out"],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600, check=False,
    )  # fmt: skip
    text = done.stdout + done.stderr
    assert "Traceback" not in text, text
    assert done.returncode == want.rc, text
    if name in LOG_SAYS:
        assert LOG_SAYS[name] in done.stdout, done.stdout
    if want.rc == 2:
        assert want.reason in done.stderr
        assert not (tmp_path / "out").exists()  # nothing half-written
        return
    runs = {r["scenario"]: r for r in
            json.loads((tmp_path / "out/report/tables/runs.json").read_text())
            if r["filter"] == "lc_ekf"}  # fmt: skip
    assert {sc: r["status"] for sc, r in runs.items()} == want.status, text
    nominal = runs["nominal"]
    if nominal["status"] not in ("ok", "inconsistent"):
        assert want.reason in (nominal.get("reason") or ""), nominal
    outage = runs.get("outage_60s")
    if outage is not None and outage["status"] == "skipped" and want.status["nominal"] != "skipped":
        assert "no outage window fits" in outage["reason"]  # a log of a few seconds
    page = (tmp_path / "out/report/index.html").read_text()
    assert '<section id="audit">' in page
    if want.rc == 0:
        assert nominal["reference"] == want.reference
        assert 0.05 < nominal["pos_err_h_rms_m"] < want.max_rms_m
    else:  # the summary's and the report's first words say so
        assert "no filter could run on this log:" in done.stdout.splitlines()[2]
        assert '<p class="verdict bad">No run ended ok' in page
    if want.onboard_max_m is not None:
        _check_onboard(tmp_path / "out", want.onboard_max_m)
        tests = "innovation test ratios</h3>" in page
        assert tests == want.onboard_tests
    else:
        assert not (tmp_path / "out/report/tables/onboard_comparison.csv").exists()


def _check_onboard(out: Path, max_rms_m: float) -> None:
    """The report compares the runs with the log's onboard estimate: the nominal run within
    ``max_rms_m`` of it, and the outage run's drift at its window's end as computed by hand
    from the Parquet files (the onboard sample last inside the window, the run's estimate
    interpolated to it, both to ECEF by pymap3d)."""
    import csv

    import numpy as np
    import pyarrow.parquet as pq
    import pymap3d

    with (out / "report/tables/onboard_comparison.csv").open() as f:
        rows = list(csv.DictReader(f))
    nominal = next(r for r in rows if r["scenario"] == "nominal" and r["scope"] == "run")
    assert 0.01 < float(nominal["pos_h_rms_m"]) < max_rms_m, nominal
    page = (out / "report/index.html").read_text()
    assert '<section id="onboard">' in page
    assert "onboard estimate" in page.split('<section id="track">')[1].split("</section>")[0]
    (win,) = [r for r in rows if r["scenario"] == "outage_60s" and r["scope"] == "window"]
    run = out / "runs/lc_ekf/outage_60s"
    (w,) = json.loads((run / "metrics.json").read_text())["outage_windows"]
    start = int(w["start_t_ns"])
    end = start + round(float(w["duration_s"]) * 1e9)
    ob = pq.read_table(out / "tables/estimator.parquet").to_pandas()
    est = pq.read_table(run / "estimate.parquet").to_pandas()
    last = ob[(ob.t_ns >= start) & (ob.t_ns <= end)].iloc[-1]
    ours = [np.interp(float(last.t_ns), est.t_ns.astype(float), est[c]) for c in
            ("lat_deg", "lon_deg", "alt_m")]  # fmt: skip
    a = np.array(pymap3d.geodetic2ecef(last.lat_deg, last.lon_deg, last.alt_m))
    b = np.array(pymap3d.geodetic2ecef(*ours))
    hand = float(np.linalg.norm(a - b))
    assert float(win["pos_3d_end_m"]) == pytest.approx(hand, rel=1e-4, abs=1e-3)
    assert float(win["pos_3d_max_m"]) >= float(win["pos_3d_end_m"])
