"""Cross-stream time alignment from speed signals (catalogue case 36, filter fault F20): a known
offset between two streams is recovered within 20 ms, and an 18 s leap-second mix-up in an
ingest is reported as a warning."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pymap3d
import pytest

from navreplay.ingest.alignment import (
    WARN_LAG_S,
    Alignment,
    estimate_lag,
    fix_latency,
    speed_signal,
)
from navreplay.ingest.api import ingest
from navreplay.ingest.config import parse_dataset_config
from navreplay.ingest.meta import read_meta


def _speed(t_s: np.ndarray) -> np.ndarray:
    """An urban speed profile: stops, accelerations and a slow trend."""
    return (
        8.0
        + 4.0 * np.sin(2 * np.pi * t_s / 37.0)
        + 2.5 * np.sin(2 * np.pi * t_s / 11.0 + 1.0)
        + 0.02 * t_s
    )


@pytest.mark.parametrize("lag_s", [0.0, 0.137, -0.45, 18.0])
def test_a_known_offset_is_recovered_within_20_ms(lag_s: float) -> None:
    rng = np.random.default_rng(7)
    t_a = np.arange(0.0, 300.0, 0.1)  # a 10 Hz receiver
    t_b = np.arange(0.013, 300.0, 0.012)  # an 83 Hz CAN bus, stamped lag_s late
    v_a = _speed(t_a) + rng.normal(0.0, 0.05, t_a.size)
    v_b = _speed(t_b - lag_s) * 1.01 + rng.normal(0.0, 0.02, t_b.size)
    ns = 1e9
    est = estimate_lag((t_a * ns).astype(np.int64), v_a, (t_b * ns).astype(np.int64), v_b)
    assert est is not None
    lag, corr, overlap = est
    assert lag == pytest.approx(lag_s, abs=0.02)
    assert corr > 0.99
    assert overlap == pytest.approx(299.9, abs=0.1)


def test_a_flat_signal_gives_no_estimate() -> None:
    t = (np.arange(0.0, 60.0, 0.1) * 1e9).astype(np.int64)
    assert estimate_lag(t, np.full(t.size, 10.0), t, np.full(t.size, 10.0)) is None


def test_speed_from_positions_on_a_long_straight_road() -> None:
    # 10 m/s east at 52 deg N: the speed must not depend on the longitude's magnitude.
    t = np.arange(0.0, 100.0, 1.0)
    lat, lon, _ = pymap3d.ned2geodetic(0.0 * t, 10.0 * t, 0.0 * t, 52.5, 113.4, 0.0)
    sig = speed_signal(
        {"t_ns": (t * 1e9).astype(np.int64), "lat_deg": lat, "lon_deg": lon}, "truth"
    )
    assert sig is not None
    assert sig[2] == "position differences"
    np.testing.assert_allclose(sig[1], 10.0, rtol=2e-3)


def test_an_18_s_offset_between_files_is_a_warning(tmp_path: Path) -> None:
    t = np.arange(0.0, 120.0, 0.1)
    course = math.radians(30.0)
    v = _speed(t)
    wheel = tmp_path / "wheel.csv"
    wheel.write_text(
        "t,v\n" + "".join(f"{a + 18.0:.3f},{b:.4f}\n" for a, b in zip(t, v, strict=True))
    )
    fix = tmp_path / "fix.csv"
    lines = [
        f"{a:.3f},{37.0 + 1e-5 * a:.8f},-122.0,10.0,{b * math.cos(course):.4f},"
        f"{b * math.sin(course):.4f}\n"
        for a, b in zip(t, v, strict=True)
    ]
    fix.write_text("t,lat,lon,alt,vn,ve\n" + "".join(lines))
    common = {"time_column": "t", "time_unit": "s", "time_base": "gps"}
    cfg = parse_dataset_config(
        {
            "id": "leap",
            "csv": [
                {"path": "wheel.csv", "table": "vehicle", "columns": {"speed_mps": "v"}, **common},
                {
                    "path": "fix.csv",
                    "table": "gnss",
                    "columns": {
                        "lat_deg": "lat",
                        "lon_deg": "lon",
                        "alt_m": "alt",
                        "vel_n_mps": "vn",
                        "vel_e_mps": "ve",
                    },
                    "constants": {"fix_type": 3},
                    **common,
                },
            ],
        }
    )
    result = ingest([wheel, fix], tmp_path / "out", config=cfg, config_dir=tmp_path)
    (align,) = result.report["time_base"]["alignment"]
    assert align["streams"] == ["gnss", "vehicle"]
    assert align["lag_s"] == pytest.approx(18.0, abs=0.02)
    assert abs(align["lag_s"]) > WARN_LAG_S
    assert any("time bases disagree" in w and "+18.0" in w for w in result.report["warnings"])


def _latency_logs(tmp_path: Path, latency: float | None) -> dict[str, object]:
    """CSV logs of a drive: fixes whose speed lags the onboard estimator's by 0.2 s, an IMU,
    and (``latency``) a declared ``gnss.latency_s``."""
    t = np.arange(0.0, 120.0, 0.1)
    course = math.radians(30.0)
    files = {
        "est.csv": (t, _speed(t)),  # the estimator on the IMU's clock ...
        "fix.csv": (t, _speed(t - 0.2)),  # ... the fixes describe 0.2 s before their stamps
    }
    for name, (ts, v) in files.items():
        (tmp_path / name).write_text(
            "t,lat,lon,alt,vn,ve\n"
            + "".join(
                f"{a:.3f},{37.0 + 1e-5 * a:.8f},-122.0,10.0,{b * math.cos(course):.4f},"
                f"{b * math.sin(course):.4f}\n"
                for a, b in zip(ts, v, strict=True)
            )
        )
    (tmp_path / "imu.csv").write_text(
        "t,ax,ay,az,gx,gy,gz\n" + "".join(f"{a:.3f},0,0,-9.8,0,0,0\n" for a in t)
    )
    common = {"time_column": "t", "time_unit": "s", "time_base": "gps"}
    fix3 = {"constants": {"fix_type": 3}}
    nav = {"lat_deg": "lat", "lon_deg": "lon", "alt_m": "alt", "vel_n_mps": "vn"}
    nav["vel_e_mps"] = "ve"
    imu = {f"acc_{a}_mps2": f"a{a}" for a in "xyz"} | {f"gyro_{a}_radps": f"g{a}" for a in "xyz"}
    return {
        "id": "late",
        "gnss": {} if latency is None else {"latency_s": latency},
        "csv": [
            {"path": "fix.csv", "table": "gnss", "columns": nav, **common, **fix3},
            {"path": "est.csv", "table": "estimator", "columns": nav, **common},
            {"path": "imu.csv", "table": "imu", "columns": imu, **common},
        ],
    }


@pytest.mark.parametrize("declared", [None, 0.05])
def test_the_fixes_latency_is_measured_against_the_onboard_estimator(
    tmp_path: Path, declared: float | None
) -> None:
    cfg = parse_dataset_config(_latency_logs(tmp_path, declared))
    logs = [tmp_path / n for n in ("fix.csv", "est.csv", "imu.csv")]
    result = ingest(logs, tmp_path / "out", config=cfg, config_dir=tmp_path)
    sensors = read_meta(tmp_path / "out").sensors
    assert sensors is not None
    checks = result.report["time_base"]["checks"]
    if declared is None:
        assert sensors.gnss_latency_s == pytest.approx(0.2, abs=0.02)
        assert "onboard estimator" in sensors.gnss_latency_source
    else:  # the dataset's word wins over the measurement
        assert sensors.gnss_latency_s == declared
        assert sensors.gnss_latency_source == "dataset.yaml gnss.latency_s"
    assert any(c.startswith("gnss latency") for c in checks)


def test_no_latency_without_a_clear_plausible_lag() -> None:
    def pair(lag: float, corr: float) -> Alignment:
        return Alignment("gnss", "estimator", lag, corr, 100.0, 1.0, ("velocity", "velocity"))

    got = fix_latency([pair(-0.2, 0.99)])
    assert got is not None
    assert got[0] == pytest.approx(0.2)
    assert fix_latency([pair(-0.2, 0.8)]) is None  # no clear peak
    assert fix_latency([pair(+0.2, 0.99)]) is None  # fixes ahead of the vehicle: a clock fault
    assert fix_latency([pair(-18.0, 0.99)]) is None  # leap seconds, not a receiver's delay
    assert fix_latency([pair(-0.005, 0.99)]) is None  # nothing to correct
