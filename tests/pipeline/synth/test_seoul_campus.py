"""seoul_campus: exact truth (the IMU integrates back onto it, SPP lands on the antenna),
non-holonomic motion, error statistics that match the configured model, determinism."""

from __future__ import annotations

import dataclasses
import itertools
import math
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest

from navreplay.ingest.config import load_dataset_config
from navreplay.ingest.gnss import spp
from navreplay.ingest.gnss.ephemeris import C_MPS, Ephemeris, select, transmit_state
from navreplay.ingest.writers import rinex
from navreplay.pipeline.nav import earth
from navreplay.pipeline.nav import mechanization as mech
from navreplay.pipeline.nav.rotations import euler_to_dcm, euler_to_quat
from navreplay.pipeline.params import Params
from navreplay.pipeline.synth import SynthResult
from navreplay.pipeline.synth.seoul_campus import SeoulCampusParams, route, simulate
from tests.ingest.navfile import read_gps_nav
from tests.pipeline.synth.conftest import REPO

BIAS_COLUMNS = {
    "acc_bias_x_mps2",
    "acc_bias_y_mps2",
    "acc_bias_z_mps2",
    "gyro_bias_x_radps",
    "gyro_bias_y_radps",
    "gyro_bias_z_radps",
    "clock_bias_m",
    "clock_drift_mps",
}


@pytest.fixture(scope="module", params=["cw", "ccw"])
def full_clean(request: pytest.FixtureRequest, seoul: SeoulCampusParams) -> SynthResult:
    """The whole default drive, noise-free."""
    return simulate(dataclasses.replace(seoul, noise_free=True), seed=1, variant=request.param)


def _np(table: pa.Table, *names: str) -> np.ndarray:
    cols = [np.asarray(table.column(n).to_numpy(), dtype=np.float64) for n in names]
    return cols[0] if len(cols) == 1 else np.stack(cols, axis=-1)


def _antenna_ecef(truth: pa.Table, lever_arm: tuple[float, float, float]) -> np.ndarray:
    lat, lon = np.radians(_np(truth, "lat_deg")), np.radians(_np(truth, "lon_deg"))
    alt, rpy = _np(truth, "alt_m"), _np(truth, "roll_rad", "pitch_rad", "yaw_rad")
    out = np.empty((lat.size, 3))
    for i in range(lat.size):
        c_ne = earth.dcm_ecef_to_ned(lat[i], lon[i]).T
        out[i] = earth.geodetic_to_ecef(lat[i], lon[i], alt[i]) + c_ne @ (
            euler_to_dcm(*rpy[i]) @ np.asarray(lever_arm)
        )
    return out


def test_noise_free_imu_integrates_onto_the_truth_over_the_whole_drive(
    full_clean: SynthResult, seoul: SeoulCampusParams
) -> None:
    imu, truth = full_clean.tables["imu"], full_clean.tables["truth"]
    assert truth.num_rows == imu.num_rows == seoul.duration_s * seoul.imu_rate_hz + 1
    lat, lon = np.radians(_np(truth, "lat_deg")), np.radians(_np(truth, "lon_deg"))
    x0 = np.zeros(mech.NAV_DIM)
    x0[:3] = lat[0], lon[0], _np(truth, "alt_m")[0]
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
    north = (out[:, 0] - lat) * (rm + seoul.alt_m)
    east = (out[:, 1] - lon) * (rn + seoul.alt_m) * math.cos(lat[0])
    horizontal = np.hypot(north, east)
    assert horizontal.max() < 1.0  # measured: ~0.24 m (cw) after 15 minutes
    assert np.abs(out[:, 2] - _np(truth, "alt_m")).max() < 0.1


def test_spp_from_noise_free_pseudoranges_lands_on_the_antenna(
    full_clean: SynthResult, seoul: SeoulCampusParams
) -> None:
    obs, truth = full_clean.tables["gnss_obs"], full_clean.tables["truth"]
    t = obs.column("t_ns").to_numpy()
    starts = spp.epoch_starts(t)
    sat = _np(obs, "sat_x_m", "sat_y_m", "sat_z_m")
    pr = _np(obs, "pseudorange_m") + _np(obs, "sat_clock_m")
    epoch, _ = spp.epoch_index(t)
    fix = spp.solve(sat, pr, epoch, starts.size - 1, max_iter=10, tol_m=1e-6, reject_outliers=False)
    assert fix.solved.all()
    x = np.column_stack([fix.ecef_m, fix.clock_m])
    rows = np.searchsorted(truth.column("t_ns").to_numpy(), t[starts[:-1]])
    ant = _antenna_ecef(truth.take(pa.array(rows)), seoul.lever_arm_m)
    err = np.linalg.norm(x[:, :3] - ant, axis=1)
    assert err.max() < 0.1  # measured: ~1.5 mm, the 1 mm rounding of RINEX pseudoranges
    clock = _np(truth, "clock_bias_m")[rows]
    assert np.abs(x[:, 3] - clock).max() < 0.1
    # velocity and drift from the rates, at the antenna (lever arm rotation included)
    vel = np.empty((len(rows), 4))
    sv = _np(obs, "sat_vx_mps", "sat_vy_mps", "sat_vz_mps")
    rate = _np(obs, "pseudorange_rate_mps") + _np(obs, "sat_clock_drift_mps")
    for k, (a, b) in enumerate(itertools.pairwise(starts)):
        vel[k], _ = spp.solve_velocity(sat[a:b], sv[a:b], rate[a:b], np.ones(b - a), x[k, :3])
    gnss = full_clean.tables["gnss"]
    lat, lon = np.radians(_np(gnss, "lat_deg")), np.radians(_np(gnss, "lon_deg"))
    v_ned = _np(gnss, "vel_n_mps", "vel_e_mps", "vel_d_mps")
    v_ecef = np.array(
        [earth.dcm_ecef_to_ned(a, o).T @ v for a, o, v in zip(lat, lon, v_ned, strict=True)]
    )
    assert np.abs(vel[:, :3] - v_ecef).max() < 0.02  # light-time rate terms: ~1 cm/s
    assert np.abs(vel[:, 3] - _np(truth, "clock_drift_mps")[rows]).max() < 0.02


def test_truth_obeys_the_non_holonomic_constraint(short_noisy: SynthResult) -> None:
    truth = short_noisy.tables["truth"]
    rpy = _np(truth, "roll_rad", "pitch_rad", "yaw_rad")
    v = _np(truth, "vel_n_mps", "vel_e_mps", "vel_d_mps")
    v_body = np.array([euler_to_dcm(*a).T @ b for a, b in zip(rpy, v, strict=True)])
    assert np.abs(v_body[:, 1:]).max() < 1e-9
    assert v_body[:, 0].max() > 5.0


def test_the_drive_is_the_campus_route(full_clean: SynthResult, seoul: SeoulCampusParams) -> None:
    truth = full_clean.tables["truth"]
    assert set(truth.column_names) >= BIAS_COLUMNS
    assert seoul.duration_s >= 600.0
    v = _np(truth, "vel_n_mps", "vel_e_mps", "vel_d_mps")
    speed = np.linalg.norm(v[:, :2], axis=1)
    rest = int(seoul.stationary_s * seoul.imu_rate_hz)
    assert speed[: rest + 1].max() == 0.0
    assert speed.max() == pytest.approx(15.0, abs=1e-9)
    alt = _np(truth, "alt_m")
    assert alt.max() - alt.min() > 8.0  # hills and dips
    # loops in both directions: the unwrapped heading sweeps a full turn each way
    yaw = np.unwrap(_np(truth, "yaw_rad"))
    sweep = yaw - np.minimum.accumulate(yaw)
    back = np.maximum.accumulate(yaw) - yaw
    assert sweep.max() > 2 * math.pi
    assert back.max() > 2 * math.pi
    lat = _np(truth, "lat_deg")
    assert abs(lat.mean() - 37.46) < 0.02


def test_ccw_is_the_mirror_image_of_cw(seoul: SeoulCampusParams) -> None:
    p = dataclasses.replace(seoul, noise_free=True, duration_s=200.0)
    cw, ccw = (simulate(p, seed=1, variant=v).tables["truth"] for v in ("cw", "ccw"))
    psi0 = math.radians(seoul.yaw_deg)
    d = np.angle(np.exp(1j * (_np(cw, "yaw_rad") + _np(ccw, "yaw_rad") - 2 * psi0)))
    assert np.abs(d).max() < 1e-9
    first = next(leg for leg in route("cw") if abs(leg.angle_deg) == 360.0)
    assert first.angle_deg > 0  # the cw drive meets a clockwise loop first
    assert next(leg for leg in route("ccw") if abs(leg.angle_deg) == 360.0).angle_deg < 0


def test_imu_errors_match_the_configured_model(
    short_noisy: SynthResult, short_clean: SynthResult, short_params: SeoulCampusParams
) -> None:
    noisy, clean = short_noisy.tables, short_clean.tables
    truth = noisy["truth"]
    rate = short_params.imu_rate_hz
    m = short_params.imu
    for sensor, bias, density, rw in (
        ("acc_{}_mps2", "acc_bias_{}_mps2", m.accel_noise_mps2_rthz, m.accel_bias_rw_mps3_rthz),
        (
            "gyro_{}_radps",
            "gyro_bias_{}_radps",
            m.gyro_noise_radps_rthz,
            m.gyro_bias_rw_radps2_rthz,
        ),
    ):
        for axis in "xyz":
            white = (
                _np(noisy["imu"], sensor.format(axis))
                - _np(clean["imu"], sensor.format(axis))
                - _np(truth, bias.format(axis))
            )
            assert np.std(white) == pytest.approx(density * math.sqrt(rate), rel=0.03)
            assert abs(np.corrcoef(white[1:], white[:-1])[0, 1]) < 0.05
            steps = np.diff(_np(truth, bias.format(axis)))
            assert np.std(steps) == pytest.approx(rw / math.sqrt(rate), rel=0.03)
    assert short_noisy.sensors.imu_noise == m.noise_model()
    assert short_clean.sensors.imu_noise is not None
    assert short_clean.sensors.imu_noise.gyro_noise_radps_rthz == 0.0
    assert short_noisy.sensors.lever_arm_m == short_params.lever_arm_m


def test_observable_errors_match_their_reported_sigmas(
    short_noisy: SynthResult, short_clean: SynthResult
) -> None:
    a, b = short_noisy.tables["gnss_obs"], short_clean.tables["gnss_obs"]
    assert a.column("sv").to_pylist() == b.column("sv").to_pylist()
    rows = np.searchsorted(
        short_noisy.tables["truth"].column("t_ns").to_numpy(), a.column("t_ns").to_numpy()
    )
    d_clock = (
        _np(short_noisy.tables["truth"], "clock_bias_m", "clock_drift_mps")[rows]
        - _np(short_clean.tables["truth"], "clock_bias_m", "clock_drift_mps")[rows]
    )
    z_pr = (_np(a, "pseudorange_m") - _np(b, "pseudorange_m") - d_clock[:, 0]) / _np(
        a, "pseudorange_std_m"
    )
    z_rate = (
        _np(a, "pseudorange_rate_mps") - _np(b, "pseudorange_rate_mps") - d_clock[:, 1]
    ) / _np(a, "pseudorange_rate_std_mps")
    for z in (z_pr, z_rate):
        assert z.size > 500
        assert np.std(z) == pytest.approx(1.0, rel=0.1)
        assert abs(np.mean(z)) < 0.15
    el = _np(a, "elevation_deg")
    assert el.min() >= 10.0
    cn0 = _np(a, "cn0_dbhz")
    assert np.corrcoef(el, cn0)[0, 1] > 0.8


def test_noise_free_fixes_are_the_antenna(
    short_clean: SynthResult, seoul: SeoulCampusParams
) -> None:
    gnss, truth = short_clean.tables["gnss"], short_clean.tables["truth"]
    rows = np.searchsorted(truth.column("t_ns").to_numpy(), gnss.column("t_ns").to_numpy())
    ant = _antenna_ecef(truth.take(pa.array(rows)), seoul.lever_arm_m)
    fix = np.array(
        [
            earth.geodetic_to_ecef(math.radians(la), math.radians(lo), h)
            for la, lo, h in _np(gnss, "lat_deg", "lon_deg", "alt_m")
        ]
    )
    np.testing.assert_allclose(fix, ant, atol=1e-6)
    imu_pos = np.array(
        [
            earth.geodetic_to_ecef(math.radians(la), math.radians(lo), h)
            for la, lo, h in _np(truth.take(pa.array(rows)), "lat_deg", "lon_deg", "alt_m")
        ]
    )
    np.testing.assert_allclose(
        np.linalg.norm(fix - imu_pos, axis=1), np.linalg.norm(seoul.lever_arm_m), atol=1e-6
    )
    assert np.all(gnss.column("fix_type").to_numpy() == 3)
    assert np.all(gnss.column("num_sats").to_numpy() >= 4)
    h_acc = _np(gnss, "h_acc_m")
    assert np.all((h_acc > 0.5) & (h_acc < 5.0))  # reported even when the errors are off


def test_same_seed_same_tables_other_seed_other_noise(
    short_params: SeoulCampusParams, short_noisy: SynthResult
) -> None:
    again = simulate(short_params, seed=7, variant="cw")
    for name, table in short_noisy.tables.items():
        assert again.tables[name].equals(table), name
    other = simulate(short_params, seed=8, variant="cw")
    acc = _np(short_noisy.tables["imu"], "acc_x_mps2")
    assert np.abs(_np(other.tables["imu"], "acc_x_mps2") - acc).min() > 0.0
    np.testing.assert_array_equal(
        _np(other.tables["truth"], "lat_deg"), _np(short_noisy.tables["truth"], "lat_deg")
    )


def test_dataset_descriptors_repeat_the_simulated_sensors(repo_params: Params) -> None:
    p = repo_params.synth.seoul_campus
    for variant in ("cw", "ccw"):
        name = f"seoul_campus_{variant}"
        cfg = load_dataset_config(REPO / "datasets" / name / "dataset.yaml")
        assert cfg.id == name
        assert name in repo_params.datasets
        assert cfg.imu.noise == p.imu.noise_model()
        assert cfg.gnss.lever_arm_m == p.lever_arm_m
        assert cfg.logs == (f"raw/{name}.mcap", f"raw/{name}.obs", f"raw/{name}.nav")
        assert set(cfg.required) == {"imu", "gnss", "gnss_obs", "truth"}


def test_a_drive_shorter_than_the_rest_stays_at_rest(seoul: SeoulCampusParams) -> None:
    p = dataclasses.replace(seoul, duration_s=30.0, noise_free=True)  # stationary_s is 60
    result = simulate(p, seed=3, variant="ccw")
    truth, imu = result.tables["truth"], result.tables["imu"]
    assert truth.num_rows == 3001
    assert np.abs(_np(truth, "vel_n_mps", "vel_e_mps", "vel_d_mps")).max() == 0.0
    f = _np(imu, "acc_x_mps2", "acc_y_mps2", "acc_z_mps2")
    g = earth.gravity(math.radians(seoul.lat_deg), seoul.alt_m)
    np.testing.assert_allclose(np.linalg.norm(f, axis=1), g, rtol=1e-12)
    w = _np(imu, "gyro_x_radps", "gyro_y_radps", "gyro_z_radps")
    np.testing.assert_allclose(np.linalg.norm(w, axis=1), earth.OMEGA_IE, rtol=1e-9)
    assert result.tables["gnss_obs"].num_rows > 4 * 31


def test_the_observables_are_reproducible_from_the_rinex_navigation_file(
    short_clean: SynthResult, seoul: SeoulCampusParams, tmp_path: Path
) -> None:
    assert short_clean.ephemeris is not None
    rinex.write_nav(tmp_path / "x.nav", short_clean.ephemeris)
    back = read_gps_nav(tmp_path / "x.nav")
    for name in Ephemeris._fields:  # exactly the broadcast elements the satellites flew
        np.testing.assert_array_equal(getattr(back, name), getattr(short_clean.ephemeris, name))
    obs, truth = short_clean.tables["gnss_obs"], short_clean.tables["truth"]
    t = obs.column("t_ns").to_numpy()
    rows = np.searchsorted(truth.column("t_ns").to_numpy(), t)
    ant = _antenna_ecef(truth.take(pa.array(rows)), seoul.lever_arm_m)
    prn = np.array([int(s[1:]) for s in obs.column("sv").to_pylist()])
    # The epoch is the receiver's clock reading: the signals arrived b / c earlier, when the
    # antenna was b / c behind along its velocity (the body's; the lever-arm term moves it
    # by < 0.1 mm in that time).
    clock = _np(truth, "clock_bias_m")[rows]
    at = truth.take(pa.array(rows))
    lat, lon = np.radians(_np(at, "lat_deg")), np.radians(_np(at, "lon_deg"))
    v_ned = _np(at, "vel_n_mps", "vel_e_mps", "vel_d_mps")
    v_ecef = np.stack(
        [earth.dcm_ecef_to_ned(a, b).T @ v for a, b, v in zip(lat, lon, v_ned, strict=True)]
    )
    ant = ant - (clock / C_MPS)[:, None] * v_ecef
    state = transmit_state(back, select(back, prn, t), t, ant, rx_offset_s=-clock / C_MPS)
    sat = _np(obs, "sat_x_m", "sat_y_m", "sat_z_m")
    np.testing.assert_allclose(state.sat.pos_m, sat, atol=1e-6)
    sat_clock = C_MPS * (state.sat.clock_s - state.sat.tgd_s)
    np.testing.assert_allclose(sat_clock, _np(obs, "sat_clock_m"), atol=1e-6)
    # the noise-free pseudorange is that range plus the receiver clock, to the 1 mm rounding
    residual = _np(obs, "pseudorange_m") - (state.range_m + clock - sat_clock)
    assert np.abs(residual).max() <= 0.0005 + 1e-4  # + the lever-arm motion in b / c
