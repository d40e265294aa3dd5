"""The fix-error model learned from a log's fixes against its receiver velocity."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pyarrow as pa
import pytest

from navreplay.ingest.schema import from_columns
from navreplay.pipeline.estimation.ins import fixnoise as fn
from navreplay.pipeline.estimation.ins import inputs as inp
from navreplay.pipeline.estimation.ins.config import GnssNoiseParams
from navreplay.pipeline.estimation.ins.models import measurement as me
from tests.pipeline.scenarios.drives import drive as scenario_drive
from tests.pipeline.scenarios.drives import params

LAT0, LON0, R = math.radians(37.5), math.radians(127.0), 6378137.0
GNSS = GnssNoiseParams(pos_error_corr_time_s=30.0)


def _gauss_markov(n: int, tau_s: float, dt_s: float, sigma: float, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    phi = math.exp(-dt_s / tau_s) if tau_s > 0.0 else 0.0
    e = np.empty((n, 3))
    e[0] = rng.normal(0.0, sigma, 3)
    w = rng.normal(0.0, sigma * math.sqrt(1.0 - phi**2), (n, 3))
    for k in range(1, n):
        e[k] = phi * e[k - 1] + w[k]
    return e


def drive(
    tau_s: float, *, dt_s: float = 1.0, duration_s: float = 900.0, sigma: float = 1.5,
    vel_sigma: float = 0.05, seed: int = 0,
) -> tuple[np.ndarray, dict[str, np.ndarray]]:  # fmt: skip
    """A car weaving at 7-13 m/s, its fixes with Gauss-Markov errors of ``tau_s`` (0: white)
    and per-axis ``sigma`` (vertical 1.5x), its receiver velocity with white noise."""
    n = int(duration_s / dt_s)
    fine = np.arange(0.0, duration_s + dt_s, 0.01)
    yaw = 0.3 * np.sin(fine / 40.0) + 0.002 * fine
    speed = 10.0 + 3.0 * np.sin(fine / 25.0)
    north = np.concatenate([[0.0], np.cumsum(speed * np.cos(yaw))[:-1] * 0.01])
    east = np.concatenate([[0.0], np.cumsum(speed * np.sin(yaw))[:-1] * 0.01])
    k = np.round(np.arange(n) * dt_s / 0.01).astype(int)
    err = _gauss_markov(n, tau_s, dt_s, sigma, seed) * [1.0, 1.0, 1.5]
    vel_noise = np.random.default_rng(seed + 100).normal(0.0, vel_sigma, (n, 3))
    cols = {
        "lat_deg": np.degrees(LAT0 + (north[k] + err[:, 0]) / R),
        "lon_deg": np.degrees(LON0 + (east[k] + err[:, 1]) / (R * math.cos(LAT0))),
        "alt_m": 50.0 - err[:, 2],
        "vel_n_mps": speed[k] * np.cos(yaw[k]) + vel_noise[:, 0],
        "vel_e_mps": speed[k] * np.sin(yaw[k]) + vel_noise[:, 1],
        "vel_d_mps": vel_noise[:, 2],
        "fix_type": np.full(n, 3),
    }
    return np.round(np.arange(n) * dt_s * 1e9).astype(np.int64), cols


def table(t_ns: np.ndarray, cols: dict[str, np.ndarray], **extra: object) -> pa.Table:
    return from_columns("gnss", {"t_ns": t_ns, **cols, **extra})


def learned(
    tau_s: float, *, dt_s: float = 1.0, duration_s: float = 900.0, seed: int = 0
) -> fn.FixNoise:
    t, cols = drive(tau_s, dt_s=dt_s, duration_s=duration_s, seed=seed)
    fixes = inp.prepare_fixes(table(t, cols), GNSS)
    assert fixes.noise is not None
    return fixes.noise


def test_the_inflation_is_the_variance_of_the_mean_of_gauss_markov_samples() -> None:
    assert fn.inflation(0.0, 1.0) == 1.0
    phi = math.exp(-0.2 / 10.0)
    assert fn.inflation(10.0, 0.2) == pytest.approx((1 + phi) / (1 - phi))
    assert fn.inflation(60.0, 1.0) == pytest.approx(1.0 + 2.0 * 60.0, rel=0.01)


@pytest.mark.parametrize("dt_s", [1.0, 0.2])
def test_white_fix_errors_are_learned_as_white_with_their_size(dt_s: float) -> None:
    noise = learned(0.0, dt_s=dt_s)
    assert noise.source == "learned"
    assert "white" in noise.reason
    assert noise.tau_s < dt_s  # below one fix interval: no inflation worth the name
    assert noise.inflation < 1.2
    assert noise.sigma_h_m == pytest.approx(1.5, rel=0.1)
    assert noise.sigma_v_m == pytest.approx(2.25, rel=0.15)
    assert noise.sigma_source == "learned"


@pytest.mark.parametrize(("tau_s", "seed"), [(5.0, 0), (10.0, 1), (30.0, 2)])
def test_correlated_fix_errors_are_learned_with_their_correlation_time(
    tau_s: float, seed: int
) -> None:
    noise = learned(tau_s, seed=seed)
    assert noise.source == "learned"
    # never much shorter (the filter would be overconfident); longer only costs accuracy
    assert 0.7 * tau_s <= noise.tau_s <= 2.5 * tau_s
    assert noise.inflation == pytest.approx(fn.inflation(noise.tau_s, 1.0))
    assert noise.sigma_h_m == pytest.approx(1.5, rel=0.35)


def test_single_fix_jumps_do_not_pass_for_correlation() -> None:
    t, cols = drive(0.0)
    rng = np.random.default_rng(7)
    jumps = rng.choice(t.size, 9, replace=False)
    cols["lat_deg"][jumps] += np.degrees(100.0 / R)  # F1: 100 m north, single epochs
    noise = inp.prepare_fixes(table(t, cols), GNSS).noise
    assert noise is not None
    assert noise.tau_s < 1.0
    assert noise.sigma_h_m == pytest.approx(1.5, rel=0.15)


def test_the_receivers_accuracy_wins_and_the_learned_one_fills_in() -> None:
    t, cols = drive(0.0)
    given = inp.prepare_fixes(table(t, cols, h_acc_m=np.full(t.size, 0.9)), GNSS)
    assert given.noise is not None
    assert given.noise.sigma_source == "reported"
    np.testing.assert_allclose(given.fix[:, me.FX_SIG_H], 0.9 * math.sqrt(given.noise.inflation))
    absent = inp.prepare_fixes(table(t, cols), GNSS)
    assert absent.noise is not None
    np.testing.assert_allclose(
        absent.fix[:, me.FX_SIG_H], absent.noise.sigma_h_m * math.sqrt(absent.noise.inflation)
    )
    assert absent.fix[0, me.FX_SIG_H] != pytest.approx(GNSS.pos_sigma_default_m)


def test_without_receiver_velocity_the_configured_model_is_used_and_says_why() -> None:
    t, cols = drive(0.0)
    for c in ("vel_n_mps", "vel_e_mps", "vel_d_mps"):
        cols[c] = np.full(t.size, np.nan)
    fixes = inp.prepare_fixes(table(t, cols), GNSS)
    assert fixes.noise is not None
    assert fixes.noise.source == "configured"
    assert "no receiver velocity" in fixes.noise.reason
    assert fixes.noise.tau_s == 30.0
    assert fixes.fix[0, me.FX_POS_INFL] == pytest.approx(fn.inflation(30.0, 1.0))


def test_a_log_too_short_for_its_correlation_takes_at_least_the_configured_time() -> None:
    noise = learned(120.0, duration_s=240.0, seed=3)
    assert noise.tau_s >= 30.0
    short = learned(0.0, duration_s=40.0)
    assert short.source == "configured"
    assert "too few" in short.reason


def test_a_correlation_beyond_the_longest_lag_still_gives_the_errors_size() -> None:
    """tau 120 s over 6 minutes: the longest lag (120 s) shows 2 sigma^2 (1 - exp(-1)) of the
    1.5 m errors; read with the tau taken it gives their size, not the 3 m default (which,
    inflated x240, would leave a consumer IMU on its own for minutes). Three independent
    samples of the error fit a shorter tau on some seeds: those take the other branch."""
    beyond = [n for n in (learned(120.0, duration_s=360.0, seed=s) for s in range(3, 10))
              if "beyond the longest lag" in n.reason]  # fmt: skip
    assert len(beyond) >= 3
    for noise in beyond:
        assert noise.sigma_source == "learned"
        assert 0.6 * 1.5 <= noise.sigma_h_m <= 1.6 * 1.5


def test_learning_can_be_switched_off() -> None:
    t, cols = drive(0.0)
    off = GnssNoiseParams(pos_error_corr_time_s=30.0, learn_fix_noise=False)
    noise = inp.prepare_fixes(table(t, cols), off).noise
    assert noise is not None
    assert noise.source == "configured"
    assert noise.tau_s == 30.0


def test_pseudorange_noise_is_learned_from_single_point_residuals_where_none_is_given() -> None:
    tables, _ = scenario_drive(120.0)
    gnss = params().filters.get("tc_ekf").gnss
    obs = tables["gnss_obs"]
    given = inp.prepare_obs(obs, gnss)
    assert given.noise is not None
    assert given.noise.source == "reported"
    for c in ("pseudorange_std_m", "pseudorange_rate_std_mps"):
        i = obs.column_names.index(c)
        obs = obs.set_column(i, obs.schema.field(c), pa.nulls(obs.num_rows, pa.float64()))
    learned = inp.prepare_obs(obs, gnss)
    assert learned.noise is not None
    assert learned.noise.source == "learned"
    assert learned.noise.epochs > 100
    # the synthesized receiver's own sigmas (elevation-dependent; their median)
    pr = float(np.median(tables["gnss_obs"].column("pseudorange_std_m").to_numpy()))
    rate = float(np.median(tables["gnss_obs"].column("pseudorange_rate_std_mps").to_numpy()))
    assert learned.noise.pseudorange_sigma_m == pytest.approx(pr, rel=0.25)
    assert learned.noise.rate_sigma_mps == pytest.approx(rate, rel=0.35)
    np.testing.assert_allclose(learned.obs[:, me.OB_SIG_PR], learned.noise.pseudorange_sigma_m)


def _no_velocity(tau_s: float, reported: float | None, sigma: float = 1.5) -> inp.FixData:
    """``drive`` without a receiver velocity, with ``reported`` as the receiver's accuracy."""
    t, cols = drive(tau_s, sigma=sigma)
    for c in ("vel_n_mps", "vel_e_mps", "vel_d_mps"):
        cols[c] = np.full(t.size, np.nan)
    extra = {} if reported is None else {"h_acc_m": np.full(t.size, reported)}
    return inp.prepare_fixes(table(t, cols, **extra), replace(GNSS, fix_error_states=True))


@pytest.mark.parametrize("sigma", [0.5, 1.5, 5.0])
def test_without_velocity_white_fixes_at_their_reported_accuracy_are_taken_white(
    sigma: float,
) -> None:
    fixes = _no_velocity(0.0, sigma, sigma)
    assert fixes.noise is not None
    assert fixes.noise.tau_s == 0.0
    assert fixes.noise.source == "learned"
    assert "white" in fixes.noise.reason
    assert not fixes.noise.states
    assert fixes.fix[0, me.FX_POS_INFL] == 1.0  # no inflation: every fix is new information


@pytest.mark.parametrize("tau_s", [10.0, 30.0, 120.0])
def test_without_velocity_correlated_fixes_keep_the_configured_inflation(tau_s: float) -> None:
    fixes = _no_velocity(tau_s, 1.5)
    assert fixes.noise is not None
    assert fixes.noise.correlated
    assert "correlated" in fixes.noise.reason
    # an assumed tau does not become error states (see the module docstring)
    assert not fixes.noise.states
    assert fixes.noise.tau_s == GNSS.pos_error_corr_time_s
    assert fixes.fix[0, me.FX_POS_INFL] == pytest.approx(fn.inflation(30.0, 1.0))


def test_without_velocity_and_accuracy_or_with_an_unclear_share_the_configured_model_stays() -> (
    None
):
    silent = _no_velocity(0.0, None)  # no reported size to compare the white part with
    assert silent.noise is not None
    assert silent.noise.source == "configured"
    assert not silent.noise.states
    # white errors of 1.5 m reported as 2.5 m: 36 % of the variance white, neither clear case
    unclear = _no_velocity(0.0, 2.5)
    assert unclear.noise is not None
    assert unclear.noise.source == "configured"
    assert "undecided" in unclear.noise.reason
    assert not unclear.noise.states
