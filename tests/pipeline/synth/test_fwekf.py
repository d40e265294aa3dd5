"""Paper 004's reference motion (eq. 33), its IMU/GPS in both noise cases, and the tlog."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from pymavlink import mavutil

from navreplay.ingest.config import load_dataset_config
from navreplay.ingest.tables import read_table
from navreplay.pipeline.nav.earth import radii
from navreplay.pipeline.nav.mechanization import integrate
from navreplay.pipeline.params import load_params
from navreplay.pipeline.synth import fwekf

REPO = Path(__file__).resolve().parents[3]
PAPER = fwekf.FwekfReferenceParams()
SHORT = dataclasses.replace(PAPER, motion_s=20.0, alignment_s=5.0)


def test_params_yaml_holds_the_papers_cases() -> None:
    assert load_params(REPO / "params.yaml").synth.fwekf_reference == PAPER
    assert PAPER.c_s == pytest.approx(20.0 / math.pi)
    n = PAPER.noise
    assert (n.gyro_radps, n.accel_mps2, n.pos_m, n.vel_mps) == (0.0003, 0.003, 10.0, 0.2)


def test_eq_33_position_velocity_and_acceleration_are_consistent_and_start_at_rest() -> None:
    t = np.linspace(0.0, 80.0, 8001)
    dist, speed, accel = fwekf.motion(PAPER, t)
    at_rest = t <= PAPER.alignment_s
    assert not dist[at_rest].any()
    assert not speed[at_rest].any()
    assert not accel[at_rest].any()
    np.testing.assert_allclose(np.gradient(dist, t)[1:-1], speed[1:-1], atol=2e-3)
    np.testing.assert_allclose(np.gradient(speed, t)[1:-1], accel[1:-1], atol=2e-3)
    tau = t - PAPER.alignment_s
    c = 20.0 / math.pi
    moving = ~at_rest
    np.testing.assert_allclose(accel[moving], 3.0 * np.sin(tau[moving] / c) ** 2, atol=1e-12)
    # after each full period (20 s) a = 0 and v = 30 m/s more: the mean acceleration is 1.5
    for k in (1, 2, 3):
        i = np.searchsorted(t, PAPER.alignment_s + 20.0 * k)
        assert accel[i] == pytest.approx(0.0, abs=1e-12)
        assert speed[i] == pytest.approx(30.0 * k)
        assert dist[i] == pytest.approx(0.75 * (20.0 * k) ** 2)


def test_truth_moves_north_along_the_meridian_by_the_eq_33_distance() -> None:
    tr = fwekf.trajectory(SHORT)
    lat = tr["lat_rad"]
    rm, _ = radii(0.5 * (lat[0] + lat[-1]))
    north = (lat - lat[0]) * (rm + SHORT.origin.alt_m)
    np.testing.assert_allclose(north, tr["dist_m"], atol=1e-4)
    assert np.ptp(tr["lon_rad"]) == 0.0
    np.testing.assert_allclose(tr["vel_ned_mps"][:, 1:], 0.0)


def test_forward_integration_of_the_noise_free_imu_follows_the_truth() -> None:
    """Free-inertial drift over the full 80 s: 2.5e-5 m, 4e-6 m/s (measured). The residual
    is the mechanization's linear interpolation of the sin^2 acceleration between samples."""
    tr = fwekf.trajectory(PAPER)
    x0 = np.concatenate(
        [
            [tr["lat_rad"][0], tr["lon_rad"][0], tr["alt_m"][0]],
            tr["vel_ned_mps"][0],
            tr["q_wxyz"][0],
        ]
    )
    t_ns = np.rint(tr["t_s"] * 1e9).astype(np.int64)
    out = integrate(x0, t_ns, tr["acc_mps2"], tr["gyro_radps"], 1)
    rm, rn = radii(tr["lat_rad"][-1])
    h = PAPER.origin.alt_m
    dn = (out[:, 0] - tr["lat_rad"]) * (rm + h)
    de = (out[:, 1] - tr["lon_rad"]) * (rn + h) * np.cos(tr["lat_rad"])
    assert np.hypot(dn, de).max() < 1e-4
    assert np.abs(out[:, 2] - h).max() < 1e-6
    assert np.abs(out[:, 3:6] - tr["vel_ned_mps"]).max() < 1e-5


def test_noisy_case_has_the_papers_sigmas_and_the_noise_free_case_none() -> None:
    raw = fwekf.raw_tables(PAPER, seed=4)
    imu, clean = raw["imu"], raw["truth_imu"]
    for axis in "xyz":
        acc_err = imu[f"acc_{axis}_mps2"].to_numpy() - clean[f"acc_{axis}_mps2"].to_numpy()
        gyro_err = imu[f"gyro_{axis}_radps"].to_numpy() - clean[f"gyro_{axis}_radps"].to_numpy()
        n = acc_err.size
        assert acc_err.std() == pytest.approx(0.003, rel=4 * math.sqrt(0.5 / n))
        assert gyro_err.std() == pytest.approx(0.0003, rel=4 * math.sqrt(0.5 / n))
    gnss, truth = raw["gnss"], raw["truth"]
    idx = np.searchsorted(truth["t_ns"].to_numpy(), gnss["t_ns"].to_numpy())
    assert gnss.num_rows == 801
    lat_t = np.radians(truth["lat_deg"].to_numpy()[idx])
    rm, _ = radii(float(lat_t[0]))
    dn = (np.radians(gnss["lat_deg"].to_numpy()) - lat_t) * (rm + PAPER.origin.alt_m)
    dv = gnss["vel_n_mps"].to_numpy() - truth["vel_n_mps"].to_numpy()[idx]
    assert dn.std() == pytest.approx(10.0, rel=0.15)
    assert dv.std() == pytest.approx(0.2, rel=0.15)
    quiet = fwekf.synthesize(PAPER, seed=4, noise_free=True)
    imu_q = quiet.tables["imu"]
    np.testing.assert_allclose(
        imu_q["acc_x_mps2"].to_numpy(), clean["acc_x_mps2"].to_numpy(), atol=1e-6
    )
    assert quiet.sensors.imu_noise is None


@pytest.fixture(scope="module")
def written(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("fwekf")
    fwekf.write(SHORT, 9, out)
    return out


def read_tlog(path: Path) -> dict[str, list[tuple[float, dict[str, Any]]]]:
    conn = mavutil.mavlink_connection(str(path))
    msgs: dict[str, list[tuple[float, dict[str, Any]]]] = {}
    try:
        while (msg := conn.recv_match()) is not None:
            msgs.setdefault(msg.get_type(), []).append((msg._timestamp, msg.to_dict()))
    finally:
        conn.close()
    return msgs


def test_the_tlog_opens_with_pymavlink_and_holds_the_reference_tables(written: Path) -> None:
    msgs = read_tlog(written / "fwekf_reference.tlog")
    imu = read_table(written / "reference/imu.parquet", "imu").table
    gnss = read_table(written / "reference/gnss.parquet", "gnss").table
    truth = read_table(written / "reference/truth.parquet", "truth").table
    assert len(msgs["HIGHRES_IMU"]) == imu.num_rows == 2501
    assert len(msgs["GPS_RAW_INT"]) == gnss.num_rows == 251
    assert len(msgs["SIMSTATE"]) == len(msgs["SIM_STATE"]) == truth.num_rows
    assert len(msgs["HEARTBEAT"]) == 26
    stamp, first = msgs["HIGHRES_IMU"][0]
    assert stamp == SHORT.start_unix_s
    assert first["time_usec"] == SHORT.start_unix_s * 10**6
    t_us = np.array([m["time_usec"] for _, m in msgs["HIGHRES_IMU"]])
    np.testing.assert_array_equal(t_us * 1000, imu["t_ns"].to_numpy())
    np.testing.assert_array_equal(
        [m["zacc"] for _, m in msgs["HIGHRES_IMU"]], imu["acc_z_mps2"].to_numpy()
    )
    np.testing.assert_array_equal(
        [m["xgyro"] for _, m in msgs["HIGHRES_IMU"]], imu["gyro_x_radps"].to_numpy()
    )
    assert {m["fields_updated"] for _, m in msgs["HIGHRES_IMU"]} == {0x3F}
    gps = [m for _, m in msgs["GPS_RAW_INT"]]
    np.testing.assert_array_equal(
        [g["lat"] for g in gps], np.rint(gnss["lat_deg"].to_numpy() * 1e7)
    )
    np.testing.assert_array_equal(
        [g["lon"] for g in gps], np.rint(gnss["lon_deg"].to_numpy() * 1e7)
    )
    np.testing.assert_array_equal(
        [g["alt_ellipsoid"] for g in gps], np.rint(gnss["alt_m"].to_numpy() * 1e3)
    )
    speed = np.hypot(gnss["vel_n_mps"].to_numpy(), gnss["vel_e_mps"].to_numpy())
    np.testing.assert_allclose([g["vel"] / 100 for g in gps], speed, atol=1e-9)
    assert {(g["fix_type"], g["h_acc"], g["vel_acc"], g["satellites_visible"]) for g in gps} == {
        (3, 10_000, 200, 255)
    }
    cog = np.radians([g["cog"] / 100 for g in gps])
    vel = np.array([g["vel"] / 100 for g in gps])
    np.testing.assert_allclose(vel * np.cos(cog), gnss["vel_n_mps"].to_numpy(), atol=1e-12)
    np.testing.assert_allclose(vel * np.sin(cog), gnss["vel_e_mps"].to_numpy(), atol=1e-12)
    end = gps[-1]  # moving north at 30 m/s with 0.2 m/s noise per axis
    assert min(end["cog"], 36000 - end["cog"]) < 150
    assert end["vel"] == pytest.approx(3000, abs=100)
    sim = [m for _, m in msgs["SIM_STATE"]]
    np.testing.assert_allclose(
        [s["lat_int"] / 1e7 for s in sim], truth["lat_deg"].to_numpy(), atol=0.6e-7
    )
    np.testing.assert_allclose([s["vn"] for s in sim], truth["vel_n_mps"].to_numpy(), rtol=1e-6)
    simstate = [m for _, m in msgs["SIMSTATE"]]
    assert [s["lat"] for s in simstate] == [s["lat_int"] for s in sim]
    assert simstate[0]["zacc"] == pytest.approx(-9.7982, abs=1e-3)  # true specific force


def test_same_seed_gives_byte_identical_files_and_another_seed_other_noise(
    written: Path, tmp_path: Path
) -> None:
    again = tmp_path / "again"
    files = fwekf.write(SHORT, 9, again)
    for path in files:
        assert path.read_bytes() == (written / path.relative_to(again)).read_bytes(), path.name
    other = tmp_path / "other"
    fwekf.write(SHORT, 10, other)
    assert (other / "fwekf_reference.tlog").read_bytes() != (
        written / "fwekf_reference.tlog"
    ).read_bytes()
    a = read_table(written / "reference/truth.parquet", "truth").table
    b = read_table(other / "reference/truth.parquet", "truth").table
    assert a.equals(b)  # the truth does not depend on the seed


@pytest.mark.parametrize("dataset", ["fwekf_reference", "fwekf_reference_noise_free"])
def test_dataset_descriptor_declares_the_tlog_and_the_noise_model(dataset: str) -> None:
    cfg = load_dataset_config(REPO / "datasets" / dataset / "dataset.yaml")
    assert cfg.logs == (f"raw/{dataset}.tlog",)
    assert cfg.imu.topic == "HIGHRES_IMU"
    assert cfg.truth.topic == "SIM_STATE"
    meta = fwekf.sensor_meta(PAPER, noise_free=dataset.endswith("noise_free"))
    if meta.imu_noise is None:
        assert cfg.imu.noise is None
    else:
        assert cfg.imu.noise is not None
        assert cfg.imu.noise.accel_noise_mps2_rthz == pytest.approx(
            meta.imu_noise.accel_noise_mps2_rthz
        )
        assert cfg.imu.noise.gyro_noise_radps_rthz == pytest.approx(
            meta.imu_noise.gyro_noise_radps_rthz
        )
