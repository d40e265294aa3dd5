"""libRSF text (the smartLoc datasets): synthetic files written as plain text round-trip, the
satellite positions are moved into the receive-time ECEF frame, text faults (catalogue cases 18,
19, 21, 29-33) are counted with line numbers, and the real Berlin Potsdamer Platz run
(../shared/data) gives its SOURCE.txt figures: 20,038 pseudoranges in 1,372 epochs, 1,372
odometry and 1,372 ground-truth epochs."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pymap3d
import pytest

from navreplay.ingest.api import IngestOptions, IngestResult, ingest, inspect
from navreplay.ingest.detect import Format, detect
from navreplay.ingest.errors import CorruptLogError
from navreplay.ingest.gnss.ephemeris import C_MPS, rotate_earth
from navreplay.ingest.readers.gnss.librsf import coarse_positions

SMARTLOC = (
    Path(__file__).resolve().parents[3] / "shared" / "data" / "smartloc_berlin_potsdamer_platz"
)
INPUT = SMARTLOC / "Berlin_Potsdamer_Platz_Input.txt"
GT = SMARTLOC / "Berlin_Potsdamer_Platz_GT.txt"

RX = np.array(pymap3d.geodetic2ecef(52.507, 13.374, 77.0))
CLOCK_M = {1: 123.4, 4: -56.7}  # per constellation (GPS, GLONASS)
SATS = [  # (id, system, azimuth deg, elevation deg)
    (2, 1, 10.0, 60.0),
    (5, 1, 100.0, 35.0),
    (12, 1, 200.0, 20.0),
    (24, 1, 290.0, 50.0),
    (307, 4, 45.0, 25.0),
    (318, 4, 160.0, 70.0),
    (322, 4, 250.0, 40.0),
]


def _receive_frame_sat(az: float, el: float, rng: float = 22e6) -> np.ndarray:
    e, n, u = pymap3d.aer2enu(az, el, rng)
    return np.array(pymap3d.enu2ecef(e, n, u, 52.507, 13.374, 77.0))


def _epochs(n_epochs: int = 20, dt: float = 0.2) -> tuple[list[str], np.ndarray]:
    """Input lines (odometry first, then pseudoranges, as smartLoc orders them) and the
    receive-frame satellite positions they encode."""
    lines: list[str] = []
    truth = np.zeros((n_epochs, len(SATS), 3))
    for k in range(n_epochs):
        t = k * dt
        lines.append(f"odom3 {t:.14g} 5.0 0 0 0 0 0.1 0.0025 0.0009 0.0009 4e-06 4e-06 4e-06")
        for j, (sid, system, az, el) in enumerate(SATS):
            sat = _receive_frame_sat(az + 0.01 * k, el)
            truth[k, j] = sat
            rng = float(np.linalg.norm(sat - RX))
            sent = rotate_earth(sat[None, :], np.array([-rng / C_MPS]))[0]  # transmit frame
            pr = rng + CLOCK_M[system]
            lines.append(
                f"pseudorange3 {t:.14g} {pr:.6f} 25 {sent[0]:.6f} {sent[1]:.6f} {sent[2]:.6f} "
                f"{sid} {system} {el:.3f} 45"
            )
    return lines, truth


def _write(path: Path, lines: list[str]) -> Path:
    path.write_text("\n".join(lines) + "\n")
    return path


def test_librsf_text_is_detected_from_its_content(tmp_path: Path) -> None:
    lines, _ = _epochs(2)
    assert detect(_write(tmp_path / "run.dat", lines)).format == Format.LIBRSF
    gt = _write(
        tmp_path / "gt.txt", [f"point3 {k * 0.2:.1f} 1 2 3 0 0 0 0 0 0 0 0 0" for k in range(5)]
    )
    assert detect(gt).format == Format.LIBRSF
    assert detect(_write(tmp_path / "x.csv", ["a b c", "1 2 3"])).format == Format.CSV


def test_pseudoranges_round_trip_into_the_receive_time_frame(tmp_path: Path) -> None:
    lines, truth = _epochs()
    out = tmp_path / "out"
    result = ingest([_write(tmp_path / "Input.txt", lines)], out)
    assert result.tables == {"gnss_obs": 20 * len(SATS), "vehicle": 20}
    assert result.report["time_base"]["base"] == "recorder"
    obs = pd.read_parquet(out / "gnss_obs.parquet")
    assert list(obs["sv"][: len(SATS)]) == ["G02", "G05", "G12", "G24", "R07", "R18", "R22"]
    order = np.argsort([f"{'G' if s == 1 else 'R'}{i % 100:02d}" for i, s, _, _ in SATS])
    expected = truth[:, order].reshape(-1, 3)
    np.testing.assert_allclose(obs[["sat_x_m", "sat_y_m", "sat_z_m"]], expected, atol=1e-3)
    rng = np.linalg.norm(obs[["sat_x_m", "sat_y_m", "sat_z_m"]].to_numpy() - RX, axis=1)
    clock = np.where(obs["sv"].str.startswith("G"), CLOCK_M[1], CLOCK_M[4])
    np.testing.assert_allclose(obs["pseudorange_m"] - clock, rng, atol=1e-3)
    assert (obs["sat_clock_m"] == 0.0).all()
    np.testing.assert_allclose(obs["pseudorange_std_m"], 5.0)
    assert obs[["sat_vx_mps", "azimuth_deg", "pseudorange_rate_mps"]].isna().all().all()
    assert obs["t_ns"].iloc[-1] == 19 * 200_000_000
    info = result.report["tables"]["gnss_obs"]["info"]
    assert "receive-time ECEF frame" in info["earth_rotation"]


def test_odometry_turn_rate_is_converted_to_frd(tmp_path: Path) -> None:
    lines, _ = _epochs(5)
    result = ingest([_write(tmp_path / "Input.txt", lines)], tmp_path / "out")
    veh = pd.read_parquet(tmp_path / "out" / "vehicle.parquet")
    np.testing.assert_allclose(veh["speed_mps"], 5.0)
    np.testing.assert_allclose(veh["yaw_rate_radps"], -0.1)  # 0.1 rad/s to the left
    np.testing.assert_allclose(veh["speed_std_mps"], 0.05)
    np.testing.assert_allclose(veh["yaw_rate_std_radps"], 0.002)
    assert result.report["tables"]["vehicle"]["frame_conversions"] == ["vehicle: FLU -> FRD"]


def test_coarse_positions_solve_every_epoch_and_fill_thin_ones() -> None:
    sats = np.array([_receive_frame_sat(az, el) for _, _, az, el in SATS])
    systems = np.array([s for _, s, _, _ in SATS])
    pr = np.linalg.norm(sats - RX, axis=1) + np.array([CLOCK_M[s] for s in systems])
    # Epoch 0 complete, epoch 1 with four satellites of two systems (5 unknowns: unsolvable).
    epoch = np.concatenate([np.zeros(len(SATS), np.int64), np.ones(4, np.int64)])
    keep = [0, 1, 4, 5]
    rx = coarse_positions(
        epoch,
        np.vstack([sats, sats[keep]]),
        np.concatenate([pr, pr[keep]]),
        np.concatenate([systems, systems[keep]]),
    )
    np.testing.assert_allclose(rx[0], RX, atol=1e-4)
    np.testing.assert_allclose(rx[1], rx[0])  # taken from the nearest solved epoch


def test_text_faults_are_counted_with_line_numbers(tmp_path: Path) -> None:
    lines, _ = _epochs(30)
    per = 1 + len(SATS)
    lines[3 * per] = lines[3 * per].rsplit(" ", 2)[0]  # case 19: two fields missing (odom3)
    lines[5 * per + 1] = lines[5 * per + 1].replace(" 25 ", " ERR ")  # case 19: not a number
    lines[7 * per] = lines[7 * per].replace(" 5.0 ", " NaN ", 1)  # case 21: NaN stays NaN
    lines[9 * per] = lines[9 * per].replace(" 5.0 ", " inf ", 1)  # case 21: inf -> NaN, counted
    lines.insert(11 * per, "imu 2.2 0 0 9.81 0 0 0")  # a type not converted
    path = _write(tmp_path / "Input.txt", lines)
    path.write_text(path.read_text()[:-5])  # case 18: the last line cut, no newline
    result = ingest([path], tmp_path / "out")
    (f,) = result.report["files"]
    assert f["completeness"] == ["bad_data_skipped", "partial_record_dropped"]
    bad, partial = f["defects"]
    assert bad["offset"] == 3 * per + 1
    assert f"lines {3 * per + 1}, {5 * per + 2}" in bad["reason"]
    assert partial["offset"] == len(lines)
    assert result.tables == {"gnss_obs": 30 * len(SATS) - 2, "vehicle": 29}
    veh = result.report["tables"]["vehicle"]["stats"]
    assert veh["nonfinite"]["speed_mps"] == {"nan": 1, "inf": 1}
    (inv,), _ = inspect([path])
    imu = inv.stream("imu")
    assert imu is not None
    assert imu.table is None
    assert imu.count == 1
    with pytest.raises(CorruptLogError, match=f"line {3 * per + 1}"):
        ingest([path], tmp_path / "strict", options=IngestOptions(strict=True))
    assert not (tmp_path / "strict").exists()


def test_time_faults_reach_the_stream_hygiene(tmp_path: Path) -> None:
    odo = [
        f"odom3 {k * 0.2:.1f} 5.0 0 0 0 0 0.1 0.0025 0.0009 0.0009 4e-06 4e-06 4e-06"
        for k in range(100)
    ]
    odo[10], odo[11] = odo[11], odo[10]  # case 29: swapped neighbours
    odo.insert(20, odo[19])  # case 30: an exact duplicate line
    del odo[51:61]  # case 33: a 2.2 s hole
    result = ingest([_write(tmp_path / "Input.txt", odo)], tmp_path / "out")
    veh = result.report["tables"]["vehicle"]
    assert veh["hygiene"]["reordered"] == 1
    assert veh["hygiene"]["duplicates_exact_dropped"] == 1
    assert veh["stats"]["gaps"]["count"] == 1
    assert veh["stats"]["gaps"]["longest_s"] == pytest.approx(2.2)
    back = odo[:40] + [
        ln.replace(ln.split()[1], f"{float(ln.split()[1]) - 5:.1f}", 1) for ln in odo[40:]
    ]  # case 31: the clock steps back 5 s
    result = ingest([_write(tmp_path / "Back.txt", back)], tmp_path / "back")
    steps = result.report["tables"]["vehicle"]["hygiene"]["clock_steps_backward"]
    assert len(steps) == 1
    assert steps[0]["offset"] == 41
    assert steps[0]["step_s"] == pytest.approx(0.2 - 5.0)  # 0.2 s later, minus 5 s


# ---------------------------------------------------------------------------------- real run
@pytest.fixture(scope="module")
def real(tmp_path_factory: pytest.TempPathFactory) -> tuple[IngestResult, dict[str, pd.DataFrame]]:
    if not SMARTLOC.is_dir():
        pytest.skip(f"shared data not present at {SMARTLOC}")
    out = tmp_path_factory.mktemp("smartloc") / "tables"
    result = ingest([INPUT, GT], out)
    tables = {n: pd.read_parquet(out / f"{n}.parquet") for n in ("gnss_obs", "vehicle", "truth")}
    return result, tables


def test_real_run_counts_rates_and_time_base(
    real: tuple[IngestResult, dict[str, pd.DataFrame]],
) -> None:
    result, t = real
    assert result.tables == {"gnss_obs": 20_038, "vehicle": 1_372, "truth": 1_372}
    obs = t["gnss_obs"]
    assert obs["t_ns"].nunique() == 1_372
    np.testing.assert_array_equal(np.unique(obs["t_ns"]), t["truth"]["t_ns"])
    np.testing.assert_array_equal(t["vehicle"]["t_ns"], t["truth"]["t_ns"])
    report = result.report
    assert report["time_base"]["base"] == "recorder"
    assert [f["completeness"] for f in report["files"]] == [["complete"], ["complete"]]
    for name in ("gnss_obs", "vehicle", "truth"):
        stats = report["tables"][name]["stats"]
        assert stats["rate_hz"] == pytest.approx(5.0, abs=0.01)  # median step 0.2 s
        assert stats["duration_s"] == pytest.approx(282.799, abs=1e-3)
        assert 1_371 / stats["duration_s"] == pytest.approx(4.85, abs=0.01)
    assert t["truth"]["t_ns"].iloc[0] == 0


def test_real_observations_value_ranges(
    real: tuple[IngestResult, dict[str, pd.DataFrame]],
) -> None:
    _, t = real
    obs = t["gnss_obs"]
    counts = obs["sv"].str[0].value_counts().to_dict()
    assert counts == {"G": 11_193, "R": 8_845}
    assert obs.groupby("t_ns").size().between(7, 17).all()
    slots = obs.loc[obs["sv"].str.startswith("R"), "sv"].str[1:].astype(int)
    assert slots.between(1, 24).all()
    assert obs["elevation_deg"].between(1.8, 85.2).all()
    assert obs["cn0_dbhz"].between(10.0, 54.0).all()
    assert obs["pseudorange_std_m"].between(5.0, 14.0).all()
    assert obs["pseudorange_m"].between(19e6, 26e6).all()
    assert (obs["sat_clock_m"] == 0.0).all()
    assert obs["sat_vx_mps"].isna().all()
    truth = t["truth"]
    assert truth["lat_deg"].between(52.5044, 52.5094).all()
    assert truth["lon_deg"].between(13.3719, 13.3759).all()
    assert truth["alt_m"].between(75.5, 79.6).all()
    assert truth[["vel_n_mps", "roll_rad"]].isna().all().all()


def test_real_satellite_positions_fit_better_after_the_earth_rotation(
    real: tuple[IngestResult, dict[str, pd.DataFrame]],
) -> None:
    _, t = real
    raw = np.loadtxt(
        [ln for ln in INPUT.read_text().splitlines() if ln.startswith("pseudorange3")],
        usecols=range(1, 11),
    )
    obs, truth = t["gnss_obs"], t["truth"]
    rx = np.stack(pymap3d.geodetic2ecef(truth["lat_deg"], truth["lon_deg"], truth["alt_m"]), 1)
    epoch_of = {v: i for i, v in enumerate(truth["t_ns"])}

    def residuals(
        t_ns: np.ndarray, sat: np.ndarray, pr: np.ndarray, sys: np.ndarray, clean: np.ndarray
    ) -> float:
        e = np.array([epoch_of[v] for v in t_ns])
        r = pr - np.linalg.norm(sat - rx[e], axis=1)
        frame = pd.DataFrame({"e": e, "s": sys, "r": r})[clean]
        group = frame.groupby(["e", "s"])["r"]
        frame["r"] -= group.transform("median")  # receiver clock, per system
        return float(frame["r"][group.transform("size") > 2].abs().median())

    t_raw = np.rint(raw[:, 0] * 1e9).astype(np.int64)
    clean_raw = (raw[:, 8] > 35) & (raw[:, 9] >= 42)
    before = residuals(t_raw, raw[:, 3:6], raw[:, 1], raw[:, 7], clean_raw)
    clean = ((obs["elevation_deg"] > 35) & (obs["cn0_dbhz"] >= 42)).to_numpy()
    after = residuals(
        obs["t_ns"].to_numpy(),
        obs[["sat_x_m", "sat_y_m", "sat_z_m"]].to_numpy(),
        obs["pseudorange_m"].to_numpy(),
        obs["sv"].str[0].to_numpy(),
        clean,
    )
    assert before == pytest.approx(6.3, abs=0.2)
    assert after == pytest.approx(2.4, abs=0.2)


def test_real_odometry_turns_with_the_ground_truth(
    real: tuple[IngestResult, dict[str, pd.DataFrame]],
) -> None:
    result, t = real
    truth, veh = t["truth"], t["vehicle"]
    n, e, _ = pymap3d.geodetic2ned(
        truth["lat_deg"],
        truth["lon_deg"],
        truth["alt_m"],
        truth["lat_deg"][0],
        truth["lon_deg"][0],
        truth["alt_m"][0],
    )
    sec = truth["t_ns"].to_numpy() * 1e-9
    vn, ve = np.gradient(n, sec), np.gradient(e, sec)
    course_rate = np.gradient(np.unwrap(np.arctan2(ve, vn)), sec)  # clockwise positive
    moving = np.hypot(vn, ve) > 3.0
    assert np.corrcoef(veh["yaw_rate_radps"][moving], course_rate[moving])[0, 1] > 0.85
    assert veh["speed_mps"].between(0.0, 12.0).all()
    (align,) = result.report["time_base"]["alignment"]
    assert align["streams"] == ["vehicle", "truth"]
    assert abs(align["lag_s"]) < 0.05
    assert align["speed_ratio"] == pytest.approx(0.995, abs=0.01)
    assert math.isclose(
        np.median(np.hypot(vn, ve)[moving] / veh["speed_mps"][moving]), 1.0, abs_tol=0.02
    )


def test_a_forward_clock_jump_is_reported_as_a_segment(tmp_path: Path) -> None:
    odo = [
        f"odom3 {k * 0.2 + (3600.0 if k >= 500 else 0.0):.1f} 5.0 0 0 0 0 0.1 0.0025 0.0009 "
        "0.0009 4e-06 4e-06 4e-06"
        for k in range(1000)
    ]  # case 32: the stamps jump one hour ahead after 100 s
    result = ingest([_write(tmp_path / "Input.txt", odo)], tmp_path / "out")
    (segment,) = result.report["tables"]["vehicle"]["stats"]["segments"]
    assert segment["jump_s"] == pytest.approx(3600.2)
    assert segment["offset"] == 501
