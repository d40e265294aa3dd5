"""The multirotor_flight and bench_static datasets: exact truth, a multirotor's attitude,
heading apart from the course, the tlog through ingest, the magnetometer in the raw log."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow.parquet as pq
import pytest
from pymavlink import mavutil

from navreplay.ingest.api import ingest
from navreplay.ingest.config import input_paths, load_dataset_config
from navreplay.ingest.meta import read_meta
from navreplay.ingest.tables import read_table
from navreplay.pipeline.cli import main
from navreplay.pipeline.nav.earth import radii
from navreplay.pipeline.nav.mechanization import integrate
from navreplay.pipeline.params import load_params
from navreplay.pipeline.synth import DATASETS, multirotor
from navreplay.pipeline.synth.imu import ideal_imu
from navreplay.pipeline.synth.multirotor_params import MultirotorFlightParams
from navreplay.pipeline.synth.trajectory import Motion

REPO = Path(__file__).resolve().parents[3]
PARAMS = MultirotorFlightParams()
SEED = 20261122


@pytest.fixture(scope="module")
def motion() -> Motion:
    return multirotor.flight_motion(PARAMS)


@pytest.fixture(scope="module")
def phases() -> dict[str, tuple[float, float]]:
    """Each named phase's first start and last end (the hovers recur)."""
    out: dict[str, tuple[float, float]] = {}
    for ph in multirotor.build_profiles(PARAMS.flight).phases:
        start = out.get(ph.name, (ph.start_s, ph.end_s))[0]
        out[ph.name] = (start, ph.end_s)
    return out


def during(motion: Motion, span: tuple[float, float]) -> np.ndarray:
    return (motion.t_s >= span[0]) & (motion.t_s <= span[1])


def test_params_yaml_holds_the_defaults_and_the_registry_both_datasets() -> None:
    assert load_params(REPO / "params.yaml").synth.multirotor_flight == PARAMS
    assert DATASETS["multirotor_flight"] == DATASETS["bench_static"] == multirotor.__name__
    with pytest.raises(ValueError, match="not 'car_speed_ramp'"):
        multirotor.write_dataset("car_speed_ramp", load_params(REPO / "params.yaml").synth, REPO)


def test_the_flight_has_its_phases_in_order_with_their_numbers(
    motion: Motion, phases: dict[str, tuple[float, float]]
) -> None:
    names = [p.name for p in multirotor.build_profiles(PARAMS.flight).phases]
    assert names == [
        "ground",
        "take-off",
        "hover",
        "yaw in place",
        "hover",
        "sideways",
        "hover",
        "backwards",
        "hover",
        "figure eights",
        "hover",
        "landing",
        "landed",
    ]
    assert motion.t_s[-1] == 177.0
    assert motion.t_s.size == 177 * 200 + 1
    speed = np.linalg.norm(motion.vel_ned_mps, axis=1)
    h = motion.h_m - PARAMS.origin.alt_m
    for still in ("ground", "landed"):
        sel = during(motion, phases[still])
        assert speed[sel].max() == 0.0
        assert np.abs(h[sel]).max() < 1e-9
        assert np.abs(motion.rpy_rad[sel, :2]).max() < 1e-12
    hover = during(motion, (phases["take-off"][1], phases["yaw in place"][0]))
    assert h[hover] == pytest.approx(10.0, abs=1e-6)
    side = during(motion, phases["sideways"])
    assert speed[side].max() == pytest.approx(4.0, abs=1e-9)
    assert speed[during(motion, phases["backwards"])].max() == pytest.approx(3.0, abs=1e-9)
    a, b = phases["figure eights"]
    ramp = PARAMS.flight.eight_ramp_s
    at_speed = during(motion, (a + ramp, b - ramp))
    assert 3.0 < speed[at_speed].min() < 4.0
    assert speed[at_speed].max() == pytest.approx(8.0, abs=0.01)
    # the eights end where they began, and the flight lands where it took off
    i, j = np.searchsorted(motion.t_s, [a, b])
    assert motion.lat_rad[j] == pytest.approx(motion.lat_rad[i], abs=1e-12)
    assert motion.lon_rad[j] == pytest.approx(motion.lon_rad[i], abs=1e-12)
    tilt = np.degrees(np.arccos(np.cos(motion.rpy_rad[:, 0]) * np.cos(motion.rpy_rad[:, 1])))
    assert 10.0 < tilt.max() < 20.0


def test_velocity_acceleration_and_body_rates_are_the_derivatives_of_the_truth(
    motion: Motion,
) -> None:
    """Position from the integrated velocity matches the exact polynomial one within 1 mm;
    finite differences of velocity and attitude match the analytic acceleration and body rates
    (the rates have kinks where a transition starts or ends, where a central difference is
    off by up to ~1e-3 rad/s: those few samples are excluded from the tight bound)."""
    prof = multirotor.build_profiles(PARAMS.flight)
    kin = multirotor.kinematics(prof, PARAMS.flight, motion.t_s)
    lat0, h0 = motion.lat_rad[0], PARAMS.origin.alt_m
    rm, rn = radii(lat0)
    north = (motion.lat_rad - lat0) * (rm + h0)
    east = (motion.lon_rad - motion.lon_rad[0]) * (rn + h0) * math.cos(lat0)
    down = h0 - motion.h_m
    local = np.stack([north, east, down], axis=1)
    assert np.abs(local - kin.pos).max() < 1e-3
    np.testing.assert_array_equal(kin.vel, motion.vel_ned_mps)
    dt = 1.0 / PARAMS.imu_rate_hz
    # velocity integrated by the trapezoid rule, in metres, against the polynomial position
    steps = 0.5 * (motion.vel_ned_mps[1:] + motion.vel_ned_mps[:-1]) * dt
    trapezoid = np.vstack([np.zeros(3), np.cumsum(steps, axis=0)])
    assert np.abs(trapezoid - kin.pos).max() < 0.01
    vdot = (motion.vel_ned_mps[2:] - motion.vel_ned_mps[:-2]) / (2 * dt)
    assert np.abs(vdot - motion.vdot_ned_mps2[1:-1]).max() < 1e-3
    c = multirotor.dcm_body_to_ned(motion.q_wxyz)
    skew = np.einsum("nji,njk->nik", c[1:-1], (c[2:] - c[:-2]) / (2 * dt))
    w = np.stack([skew[:, 2, 1], skew[:, 0, 2], skew[:, 1, 0]], axis=1)
    err = np.abs(w - motion.w_nb_b_radps[1:-1]).max(axis=1)
    assert err.max() < 2e-3
    assert np.count_nonzero(err > 1e-4) < 40
    assert np.percentile(err, 99) < 2e-5


def test_thrust_lies_along_the_specific_force_and_the_imu_integrates_onto_the_truth(
    motion: Motion,
) -> None:
    """The exact IMU of a multirotor: no horizontal specific force in the body (only the
    Coriolis and transport terms left out of the attitude, ~1e-3 m/s^2); free-inertial
    integration of the noise-free IMU over the whole 177 s stays within 2 cm, 1 mm/s and
    0.001 deg of the truth (measured: 1.0 cm, 0.17 mm/s, 1.6e-4 deg)."""
    acc, gyro = ideal_imu(motion)
    assert np.abs(acc[:, :2]).max() < 2e-3
    assert acc[:, 2].max() < -7.0  # thrust always up, never free fall
    start = (motion.lat_rad, motion.lon_rad, motion.h_m, motion.vel_ned_mps, motion.q_wxyz)
    x0 = np.concatenate([np.atleast_1d(x[0]) for x in start])
    t_ns = np.arange(motion.t_s.size, dtype=np.int64) * (10**9 // PARAMS.imu_rate_hz)
    out = integrate(x0, t_ns, acc, gyro, 1)
    rm, rn = radii(motion.lat_rad[0])
    dn = (out[:, 0] - motion.lat_rad) * (rm + motion.h_m)
    de = (out[:, 1] - motion.lon_rad) * (rn + motion.h_m) * np.cos(motion.lat_rad)
    assert np.hypot(dn, de).max() < 0.02
    assert np.abs(out[:, 2] - motion.h_m).max() < 0.01
    assert np.abs(out[:, 3:6] - motion.vel_ned_mps).max() < 1e-3
    dot = np.clip(np.abs(np.sum(out[:, 6:10] * motion.q_wxyz, axis=1)), 0.0, 1.0)
    assert np.degrees(2 * np.arccos(dot)).max() < 1e-3


def test_the_heading_is_not_the_course(
    motion: Motion, phases: dict[str, tuple[float, float]]
) -> None:
    v = motion.vel_ned_mps
    moving = np.hypot(v[:, 0], v[:, 1]) > 0.5
    course = np.arctan2(v[:, 1], v[:, 0])
    off = np.degrees(multirotor._wrap(course - motion.rpy_rad[:, 2]))
    yaw_deg = np.degrees(motion.rpy_rad[:, 2])
    side = during(motion, phases["sideways"]) & moving
    back = during(motion, phases["backwards"]) & moving
    eights = during(motion, phases["figure eights"]) & moving
    np.testing.assert_allclose(off[side], 90.0, atol=1e-9)
    np.testing.assert_allclose(np.abs(off[back]), 180.0, atol=1e-9)
    assert np.abs(off[eights]).max() > 175.0
    assert np.abs(off[eights]).min() < 5.0
    # the yaw in place: 30 deg on the ground, 210 (-150) after, 120 after the eights
    ground = during(motion, phases["ground"])
    np.testing.assert_allclose(yaw_deg[ground], 30.0, atol=1e-9)
    turn = during(motion, phases["yaw in place"])
    assert np.abs(motion.w_nb_b_radps[turn, 2]).max() == pytest.approx(
        math.radians(15 / 8 * 180 / 8), rel=1e-3
    )
    assert np.hypot(v[turn, 0], v[turn, 1]).max() == 0.0
    assert yaw_deg[np.searchsorted(motion.t_s, phases["sideways"][0])] == pytest.approx(-150.0)
    assert yaw_deg[-1] == pytest.approx(120.0)


def read_tlog(path: Path) -> dict[str, list[dict[str, Any]]]:
    conn = mavutil.mavlink_connection(str(path))
    msgs: dict[str, list[dict[str, Any]]] = {}
    try:
        while (msg := conn.recv_match()) is not None:
            msgs.setdefault(msg.get_type(), []).append(msg.to_dict())
    finally:
        conn.close()
    return msgs


@pytest.fixture(scope="module")
def flight_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("multirotor") / "raw"
    multirotor.write(PARAMS, SEED, out)
    return out


@pytest.fixture(scope="module")
def flight_tlog(flight_dir: Path) -> dict[str, list[dict[str, Any]]]:
    return read_tlog(flight_dir / "multirotor_flight.tlog")


def test_the_tlog_says_quadrotor_armed_and_holds_sim_state_truth(
    flight_tlog: dict[str, list[dict[str, Any]]],
) -> None:
    beats = flight_tlog["HEARTBEAT"]
    assert {(b["type"], b["autopilot"]) for b in beats} == {
        (mavutil.mavlink.MAV_TYPE_QUADROTOR, mavutil.mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA)
    }
    assert all(b["base_mode"] & mavutil.mavlink.MAV_MODE_FLAG_SAFETY_ARMED for b in beats)
    assert len(flight_tlog["HIGHRES_IMU"]) == 177 * 200 + 1
    assert len(flight_tlog["GPS_RAW_INT"]) == 177 * 5 + 1
    assert len(flight_tlog["SIM_STATE"]) == 177 * 50 + 1
    assert "SIMSTATE" not in flight_tlog  # no altitude or velocity: not written
    gps = flight_tlog["GPS_RAW_INT"]
    assert {(g["fix_type"], g["h_acc"], g["v_acc"], g["vel_acc"]) for g in gps} == {
        (3, 1000, 1800, 100)
    }
    assert max(g["vel"] for g in gps) > 700  # cm/s: the eights


def test_the_magnetometer_is_in_the_raw_log(
    flight_tlog: dict[str, list[dict[str, Any]]], motion: Motion
) -> None:
    """HIGHRES_IMU xmag/ymag/zmag (gauss) = C_n^b B_n + hard iron + noise; tilt-compensated,
    it gives the heading less the declination (3.66 deg) on the ground."""
    hi = flight_tlog["HIGHRES_IMU"]
    assert {m["fields_updated"] for m in hi} == {0x1FF}
    mag = np.array([[m["xmag"], m["ymag"], m["zmag"]] for m in hi])
    clean = multirotor.magnetometer(motion, PARAMS, None)
    resid = mag - clean
    assert np.abs(resid.mean(axis=0)).max() < 1e-4
    np.testing.assert_allclose(resid.std(axis=0), PARAMS.mag.noise_gauss, rtol=0.03)
    np.testing.assert_allclose(
        np.linalg.norm(clean - PARAMS.mag.hard_iron_gauss, axis=1), 0.48404, atol=1e-4
    )
    ground = slice(0, 20 * PARAMS.imu_rate_hz)
    m = mag[ground].mean(axis=0) - np.array(PARAMS.mag.hard_iron_gauss)
    roll, pitch, yaw = motion.rpy_rad[0]
    assert abs(roll) < 1e-12
    assert abs(pitch) < 1e-12
    heading = math.degrees(math.atan2(-m[1], m[0])) + PARAMS.mag.declination_deg
    assert heading == pytest.approx(math.degrees(yaw), abs=0.05)
    assert PARAMS.mag.declination_deg == pytest.approx(3.66, abs=0.01)


def test_the_tlog_ingests_as_a_multirotor_with_imu_gnss_mag_and_truth(
    flight_dir: Path, tmp_path: Path
) -> None:
    # without a descriptor, as a user's log: the HEARTBEAT says multirotor
    res = ingest([flight_dir / "multirotor_flight.tlog"], tmp_path / "auto")
    # and its context: the heartbeats' mode and arming (one state each over the flight)
    assert res.tables == {
        "imu": 35401, "gnss": 886, "mag": 35401, "truth": 8851, "events": 2,
    }  # fmt: skip
    platform = read_meta(tmp_path / "auto").sensors.platform
    assert (platform.kind, platform.source) == (
        "multirotor",
        "HEARTBEAT type 2 (MAV_TYPE_QUADROTOR)",
    )
    # through the repository's descriptor: the same tables as the synthesizer's reference
    descriptor = tmp_path / "dataset.yaml"
    descriptor.write_text((REPO / "datasets/multirotor_flight/dataset.yaml").read_text())
    (tmp_path / "raw").symlink_to(flight_dir)
    cfg = load_dataset_config(descriptor)
    assert cfg.platform == "multirotor"
    ingest(input_paths(cfg, descriptor), tmp_path / "tables", config=cfg, config_dir=tmp_path)
    meta = read_meta(tmp_path / "tables")
    assert meta.sensors.platform.kind == "multirotor"
    assert meta.sensors.imu_noise == PARAMS.imu.noise_model()
    assert meta.sensors.lever_arm_m == PARAMS.gnss.lever_arm_m
    for name in ("imu", "gnss"):
        ref = read_table(flight_dir / "reference" / f"{name}.parquet", name).table
        got = pq.read_table(tmp_path / "tables" / f"{name}.parquet")
        for col in ref.column_names:
            np.testing.assert_array_equal(
                got[col].to_numpy(zero_copy_only=False),
                ref[col].to_numpy(zero_copy_only=False),
                err_msg=f"{name}.{col}",
            )
    ref = read_table(flight_dir / "reference/truth.parquet", "truth").table
    got = pq.read_table(tmp_path / "tables/truth.parquet")
    np.testing.assert_array_equal(got["t_ns"].to_numpy(), ref["t_ns"].to_numpy())
    for col, atol in (("lat_deg", 0.6e-7), ("lon_deg", 0.6e-7), ("alt_m", 1e-4)):
        np.testing.assert_allclose(got[col].to_numpy(), ref[col].to_numpy(), rtol=0, atol=atol)
    for col in ("vel_n_mps", "vel_e_mps", "vel_d_mps", "roll_rad", "pitch_rad", "yaw_rad"):
        np.testing.assert_allclose(got[col].to_numpy(), ref[col].to_numpy(), rtol=0, atol=1e-6)
    assert {"gyro_bias_x_radps", "acc_bias_z_mps2"} <= set(ref.column_names)


def test_the_imu_errors_are_consumer_mems(flight_dir: Path) -> None:
    """The turn-on biases are the configured ones (0.15-0.25 deg/s, 0.05-0.08 m/s^2), the
    random walk moves them little, the white noise has the declared density."""
    truth = read_table(flight_dir / "reference/truth.parquet", "truth").table
    gyro_b = np.stack([truth[f"gyro_bias_{a}_radps"].to_numpy() for a in "xyz"], axis=1)
    acc_b = np.stack([truth[f"acc_bias_{a}_mps2"].to_numpy() for a in "xyz"], axis=1)
    np.testing.assert_allclose(np.degrees(gyro_b[0]), PARAMS.turn_on_bias.gyro_dps, atol=1e-12)
    np.testing.assert_allclose(acc_b[0], PARAMS.turn_on_bias.accel_mps2, atol=1e-12)
    assert np.degrees(np.abs(gyro_b - gyro_b[0])).max() < 0.05
    assert np.abs(acc_b - acc_b[0]).max() < 0.02
    imu = read_table(flight_dir / "reference/imu.parquet", "imu").table
    still = slice(0, 20 * PARAMS.imu_rate_hz)  # on the ground: bias, earth rate and noise
    gz = imu["gyro_z_radps"].to_numpy()[still]
    assert gz.std() == pytest.approx(PARAMS.imu.gyro_noise_radps_rthz * math.sqrt(200), rel=0.05)
    earth_z = -7.292115e-5 * math.sin(math.radians(PARAMS.origin.lat_deg))
    assert gz.mean() - earth_z == pytest.approx(math.radians(0.2), abs=math.radians(0.01))


def test_same_seed_same_files(flight_dir: Path, tmp_path: Path) -> None:
    files = multirotor.write(PARAMS, SEED, tmp_path / "again")
    for path in files:
        rel = path.relative_to(tmp_path / "again")
        if path.is_file():
            assert path.read_bytes() == (flight_dir / rel).read_bytes(), rel


@pytest.fixture(scope="module")
def bench_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("bench") / "raw"
    multirotor.write(PARAMS, SEED, out, bench=True)
    return out


def test_bench_log_is_at_rest_without_a_fix(bench_dir: Path) -> None:
    msgs = read_tlog(bench_dir / "bench_static.tlog")
    assert len(msgs["HIGHRES_IMU"]) == 60 * 200 + 1
    assert {
        (g["fix_type"], g["lat"], g["lon"], g["satellites_visible"]) for g in msgs["GPS_RAW_INT"]
    } == {(1, 0, 0, 3)}
    assert not any(
        b["base_mode"] & mavutil.mavlink.MAV_MODE_FLAG_SAFETY_ARMED for b in msgs["HEARTBEAT"]
    )
    truth = read_table(bench_dir / "reference/truth.parquet", "truth").table
    assert np.ptp(truth["lat_deg"].to_numpy()) == 0.0
    np.testing.assert_allclose(
        np.degrees(truth["roll_rad"].to_numpy()), PARAMS.bench.roll_deg, atol=1e-12
    )
    imu = read_table(bench_dir / "reference/imu.parquet", "imu").table
    f = np.stack([imu[f"acc_{a}_mps2"].to_numpy() for a in "xyz"], axis=1).mean(axis=0)
    # roll and pitch of the bench from the mean specific force (within the accel biases)
    assert math.degrees(math.atan2(-f[1], -f[2])) == pytest.approx(PARAMS.bench.roll_deg, abs=1.5)
    mag = np.array([[m["xmag"], m["ymag"], m["zmag"]] for m in msgs["HIGHRES_IMU"]])
    assert np.linalg.norm(mag.mean(axis=0)) == pytest.approx(0.484, abs=0.01)


def test_analyze_on_the_bench_log_says_no_filter_can_run(
    bench_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code = main(["analyze", str(bench_dir / "bench_static.tlog"), "--out", str(tmp_path / "a")])
    out = capsys.readouterr()
    assert code == 3
    assert "Traceback" not in out.out + out.err
    assert "no filter could run on this log:" in out.out
    assert (
        "skipped lc_ekf / *: loose coupling needs GNSS fixes: no GPS fix in the log: 301 GPS "
        "records (GPS_RAW_INT), all with fix type < 3" in out.out
    )
    assert "tight coupling needs pseudoranges and orbits: no raw GNSS observables" in out.out
