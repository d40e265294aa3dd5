"""The car test beds of issue 21 (rolling start, reversing out of a parking bay, stop-and-go):
each drive is what its name says, the truth is exact (the noise-free IMU integrates onto it,
the non-holonomic constraint holds), the files are written by the CLI, and the descriptors
repeat the simulated sensors."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest
import yaml

from navreplay.ingest.config import load_dataset_config
from navreplay.ingest.meta import read_meta
from navreplay.pipeline.cli import main
from navreplay.pipeline.nav import earth
from navreplay.pipeline.nav import mechanization as mech
from navreplay.pipeline.nav.rotations import euler_to_dcm, euler_to_quat
from navreplay.pipeline.params import Params
from navreplay.pipeline.synth import DATASETS, SynthResult, car_drives
from tests.pipeline.synth.conftest import REPO


def _np(table: pa.Table, *names: str) -> np.ndarray:
    cols = [np.asarray(table.column(n).to_numpy(), dtype=np.float64) for n in names]
    return cols[0] if len(cols) == 1 else np.stack(cols, axis=-1)


def _drive(params: Params, name: str, *, noise_free: bool = True, seed: int = 1) -> SynthResult:
    campus = dataclasses.replace(params.synth.seoul_campus, noise_free=noise_free)
    return car_drives.simulate(name, campus, params.synth.car_drives[name], seed=seed)


@pytest.fixture(scope="module")
def clean(repo_params: Params) -> dict[str, SynthResult]:
    return {name: _drive(repo_params, name) for name in car_drives.DRIVES}


def _speed_along_body_x(truth: pa.Table) -> tuple[np.ndarray, np.ndarray]:
    """Signed speed along body x and the body-frame velocity (N, 3)."""
    rpy = _np(truth, "roll_rad", "pitch_rad", "yaw_rad")
    v = _np(truth, "vel_n_mps", "vel_e_mps", "vel_d_mps")
    v_body = np.array([euler_to_dcm(*a).T @ b for a, b in zip(rpy, v, strict=True)])
    return v_body[:, 0], v_body


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """(start, end) of every run of True in ``mask``."""
    edges = np.flatnonzero(np.diff(np.concatenate(([0], mask.astype(np.int8), [0]))))
    return list(zip(edges[::2].tolist(), edges[1::2].tolist(), strict=True))


def test_params_yaml_holds_the_drives_and_the_registry_makes_them(repo_params: Params) -> None:
    assert set(repo_params.synth.car_drives) == set(car_drives.DRIVES)
    for name in car_drives.DRIVES:
        assert DATASETS[name] == car_drives.__name__


def test_the_rolling_start_moves_from_the_first_sample(
    clean: dict[str, SynthResult], repo_params: Params
) -> None:
    truth = clean["car_rolling_start"].tables["truth"]
    u, _ = _speed_along_body_x(truth)
    rate = repo_params.synth.seoul_campus.imu_rate_hz
    assert u[0] == pytest.approx(10.0, abs=1e-9)
    assert u[: 60 * rate].min() > 9.0  # no standstill in the first minute
    yaw = np.unwrap(_np(truth, "yaw_rad"))
    assert yaw[10 * rate] - yaw[0] > math.radians(45.0)  # a curve soon after the start
    fixes = clean["car_rolling_start"].tables["gnss"]
    assert np.hypot(*_np(fixes, "vel_n_mps", "vel_e_mps")[0]) == pytest.approx(10.0, abs=0.1)


def test_the_car_reverses_out_of_the_bay_then_drives_forwards(
    clean: dict[str, SynthResult], repo_params: Params
) -> None:
    drive = repo_params.synth.car_drives["car_parking_reverse"]
    rate = repo_params.synth.seoul_campus.imu_rate_hz
    truth = clean["car_parking_reverse"].tables["truth"]
    u, _ = _speed_along_body_x(truth)
    rest = int(drive.stationary_s * rate)
    assert np.abs(u[: rest + 1]).max() == 0.0
    back, ahead = u < -0.3, u > 0.3
    first_back, last_back, first_ahead = (
        int(np.flatnonzero(back)[0]),
        int(np.flatnonzero(back)[-1]),
        int(np.flatnonzero(ahead)[0]),
    )
    assert rest < first_back < last_back < first_ahead  # reverses first, then forwards
    assert 1.5 <= -u.min() <= 2.0  # walking pace backwards
    between = u[last_back:first_ahead]  # comes to rest before driving off
    still = np.flatnonzero(between == 0.0)
    assert still.size >= 3 * rate
    assert np.all(between[: still[0]] < 0.0)
    assert np.all(between[still[-1] + 1 :] > 0.0)
    yaw = np.unwrap(_np(truth, "yaw_rad"))
    assert yaw[first_ahead] - yaw[0] == pytest.approx(math.radians(90.0), abs=1e-9)
    course = np.arctan2(*_np(truth, "vel_e_mps", "vel_n_mps").T)
    off = np.angle(np.exp(1j * (course - yaw)))
    np.testing.assert_allclose(np.abs(off[back]), math.pi, atol=1e-9)
    np.testing.assert_allclose(off[ahead], 0.0, atol=1e-9)


def test_stop_and_go_stops_creeps_and_accelerates(
    clean: dict[str, SynthResult], repo_params: Params
) -> None:
    rate = repo_params.synth.seoul_campus.imu_rate_hz
    truth = clean["car_stop_and_go"].tables["truth"]
    u, _ = _speed_along_body_x(truth)
    assert u.min() >= 0.0
    stops = [(a, b) for a, b in _runs(u == 0.0) if a > 0 and b < u.size]  # not the first rest
    lengths = [(b - a) / rate for a, b in stops]
    assert len(stops) >= 4
    assert min(lengths) >= 5.0
    assert max(lengths) <= 31.0
    moves = _runs(u > 0.0)
    peaks = [float(u[a:b].max()) for a, b in moves]
    assert sum(p < 2.0 for p in peaks) >= 1  # creeping
    assert sum(p >= 6.0 for p in peaks) >= 3  # short accelerations
    accel = np.diff(u) * rate
    assert np.abs(accel).max() <= repo_params.synth.seoul_campus.max_accel_mps2 + 1e-6


@pytest.mark.parametrize("name", car_drives.DRIVES)
def test_truth_is_exact_the_imu_integrates_onto_it(
    clean: dict[str, SynthResult], name: str, repo_params: Params
) -> None:
    """Noise-free IMU through the strapdown mechanization from the first truth state: the
    whole drive within decimetres (the seoul_campus drive: ~0.24 m after 15 minutes); the
    body velocity has no lateral or vertical part."""
    result = clean[name]
    imu, truth = result.tables["imu"], result.tables["truth"]
    drive = repo_params.synth.car_drives[name]
    rate = repo_params.synth.seoul_campus.imu_rate_hz
    assert truth.num_rows == imu.num_rows == drive.duration_s * rate + 1
    _, v_body = _speed_along_body_x(truth)
    assert np.abs(v_body[:, 1:]).max() < 1e-9
    lat, lon = np.radians(_np(truth, "lat_deg")), np.radians(_np(truth, "lon_deg"))
    alt = _np(truth, "alt_m")
    x0 = np.zeros(mech.NAV_DIM)
    x0[:3] = lat[0], lon[0], alt[0]
    x0[mech.I_VN : mech.I_VN + 3] = _np(truth, "vel_n_mps", "vel_e_mps", "vel_d_mps")[0]
    x0[mech.I_QW :] = euler_to_quat(*_np(truth, "roll_rad", "pitch_rad", "yaw_rad")[0])
    out = mech.integrate(
        x0,
        imu.column("t_ns").to_numpy(),
        _np(imu, "acc_x_mps2", "acc_y_mps2", "acc_z_mps2"),
        _np(imu, "gyro_x_radps", "gyro_y_radps", "gyro_z_radps"),
        1,
    )
    rm, rn = earth.radii(lat[0])
    north = (out[:, 0] - lat) * (rm + alt[0])
    east = (out[:, 1] - lon) * (rn + alt[0]) * math.cos(lat[0])
    assert np.hypot(north, east).max() < 0.3
    assert np.abs(out[:, 2] - alt).max() < 0.1
    vel = out[:, mech.I_VN : mech.I_VN + 3]
    assert np.abs(vel - _np(truth, "vel_n_mps", "vel_e_mps", "vel_d_mps")).max() < 0.01


def test_drives_draw_their_own_noise_reproducibly(repo_params: Params) -> None:
    a = _drive(repo_params, "car_stop_and_go", noise_free=False, seed=3)
    b = _drive(repo_params, "car_stop_and_go", noise_free=False, seed=3)
    c = _drive(repo_params, "car_parking_reverse", noise_free=False, seed=3)
    for table in ("imu", "gnss", "gnss_obs", "truth"):
        assert a.tables[table].equals(b.tables[table])
    gyro_a = _np(a.tables["imu"], "gyro_x_radps")[:100]
    gyro_c = _np(c.tables["imu"], "gyro_x_radps")[:100]
    assert not np.array_equal(gyro_a, gyro_c)  # both at rest there: only the noise differs


def test_dataset_descriptors_repeat_the_simulated_sensors(repo_params: Params) -> None:
    p = repo_params.synth.seoul_campus
    for name in car_drives.DRIVES:
        cfg = load_dataset_config(REPO / "datasets" / name / "dataset.yaml")
        assert cfg.id == name
        assert cfg.platform == "ground"
        assert cfg.imu.noise == p.imu.noise_model()
        assert cfg.gnss.lever_arm_m == p.lever_arm_m
        assert cfg.logs == (f"raw/{name}.mcap", f"raw/{name}.obs", f"raw/{name}.nav")
        assert set(cfg.required) == {"imu", "gnss", "gnss_obs", "truth"}


def test_the_cli_writes_each_drive(tmp_path: Path) -> None:
    data = yaml.safe_load((REPO / "params.yaml").read_text())
    for drive in data["synth"]["car_drives"].values():
        drive["duration_s"] = 30.0
    params = tmp_path / "params.yaml"
    params.write_text(yaml.safe_dump(data))
    for name in car_drives.DRIVES:
        out = tmp_path / name
        assert main(["synth", name, "--out", str(out), "--params", str(params)]) == 0
        files = sorted(p.name for p in out.iterdir())
        assert files == sorted(
            ["reference", *(f"{name}.{x}" for x in ("bag", "mcap", "nav", "obs"))]
        )
        meta = read_meta(out / "reference")
        assert meta.dataset == name
        assert meta.tables["imu"] == meta.tables["truth"] == 3001
