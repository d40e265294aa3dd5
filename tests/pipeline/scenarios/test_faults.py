"""The faults of the catalogue as table transformations (what the filters are given)."""

from __future__ import annotations

import numpy as np
import pytest

from navreplay.ingest.schema import validate
from navreplay.pipeline.estimation.core.windows import NS
from navreplay.pipeline.nav import earth
from navreplay.pipeline.scenarios.apply import apply_scenario
from navreplay.pipeline.scenarios.config import FaultSpec, ScenarioSpec, WindowsSpec
from navreplay.pipeline.scenarios.faults import ScenarioError, column
from tests.pipeline.scenarios.drives import Tables, drive


def fault(kind: str, at_s: float = 30.0, **kw: float) -> ScenarioSpec:
    return ScenarioSpec(faults=(FaultSpec(kind, at_s, **kw),))  # type: ignore[arg-type]


@pytest.fixture(scope="module")
def tables() -> Tables:
    return drive()[0]


def t0(tables: Tables) -> int:
    return int(tables["imu"].column("t_ns")[0].as_py())


def ecef(tables: Tables, name: str = "gnss") -> np.ndarray:
    g = tables[name]
    lat, lon = np.radians(column(g, "lat_deg")), np.radians(column(g, "lon_deg"))
    alt = column(g, "alt_m")
    return np.array(
        [earth.geodetic_to_ecef(a, b, c) for a, b, c in zip(lat, lon, alt, strict=True)]
    )


def test_nominal_changes_nothing(tables: Tables) -> None:
    applied = apply_scenario(tables, "nominal", ScenarioSpec())
    assert all(applied.tables[n] is tables[n] for n in tables)
    assert applied.windows == ()


def test_f1_moves_one_fix_100_m_north_and_one_pseudorange_of_that_epoch(tables: Tables) -> None:
    applied = apply_scenario(tables, "f1", fault("F1"))
    out = applied.tables
    moved = np.linalg.norm(ecef(out) - ecef(tables), axis=1)
    k = int(np.argmax(moved))
    assert moved[k] == pytest.approx(100.0, abs=0.01)
    assert np.sum(moved > 1e-6) == 1
    t_jump = int(tables["gnss"].column("t_ns")[k].as_py())
    assert t_jump == t0(tables) + 30 * NS
    # the observation fault behind a one-epoch jump: the highest satellite's range +100 m
    obs, new = tables["gnss_obs"], out["gnss_obs"]
    rows = np.flatnonzero(obs.column("t_ns").to_numpy() == t_jump)
    diff = column(new, "pseudorange_m") - column(obs, "pseudorange_m")
    (hit,) = np.flatnonzero(diff != 0.0)
    assert hit in rows
    assert diff[hit] == pytest.approx(100.0)
    el = column(obs, "elevation_deg")
    assert el[hit] == np.max(el[rows])
    assert [w.kind for w in applied.windows] == ["F1"]


def test_f2_moves_every_fix_from_its_start(tables: Tables) -> None:
    out = apply_scenario(tables, "f2", fault("F2", 25.0)).tables
    moved = np.linalg.norm(ecef(out) - ecef(tables), axis=1)
    after = tables["gnss"].column("t_ns").to_numpy() >= t0(tables) + 25 * NS
    np.testing.assert_allclose(moved[after], 100.0, atol=0.01)
    assert np.all(moved[~after] == 0.0)


@pytest.mark.parametrize("kind", ["F4", "F5"])
def test_f4_and_f5_leave_no_usable_gnss_in_the_window(kind: str, tables: Tables) -> None:
    applied = apply_scenario(tables, kind, fault(kind, 20.0, duration_s=20.0))
    out = applied.tables
    a, b = t0(tables) + 20 * NS, t0(tables) + 40 * NS
    t_obs = out["gnss_obs"].column("t_ns").to_numpy()
    assert not np.any((t_obs >= a) & (t_obs < b))
    g = out["gnss"]
    t = g.column("t_ns").to_numpy()
    inside = (t >= a) & (t < b)
    if kind == "F4":
        assert not inside.any()
    else:  # stuck: the last fix before repeated with fix_type 0 and no satellites
        assert inside.sum() == 20
        assert (g.column("fix_type").to_numpy()[inside] == 0).all()
        assert (g.column("num_sats").to_numpy()[inside] == 0).all()
        last = np.flatnonzero(t < a)[-1]
        assert (column(g, "lat_deg")[inside] == column(g, "lat_deg")[last]).all()
        validate("gnss", g)
    (w,) = applied.outage_windows
    assert (w.kind, w.sats, w.duration_s) == (kind, 0, 20.0)


def test_f7_puts_outliers_on_the_catalogue_fraction_of_samples(tables: Tables) -> None:
    applied = apply_scenario(tables, "f7", fault("F7", 20.0, seed=3))
    (rec,) = applied.injected
    assert rec["gnss_rows"] == 30
    assert len(rec["gnss_hit_t_ns"]) == 3
    t_obs = tables["gnss_obs"].column("t_ns").to_numpy()
    burst = (t_obs >= t0(tables) + 20 * NS) & (t_obs < t0(tables) + 50 * NS)
    assert rec["gnss_obs_rows"] == int(burst.sum())
    assert rec["gnss_obs_epochs"] == 30
    assert len(rec["gnss_obs_hit_epochs"]) == 3  # every pseudorange of 10 % of the epochs
    assert (
        rec["gnss_obs_hit"] == np.flatnonzero(np.isin(t_obs, rec["gnss_obs_hit_epochs"])).tolist()
    )
    d = column(applied.tables["gnss_obs"], "pseudorange_m") - column(
        tables["gnss_obs"], "pseudorange_m"
    )
    assert np.flatnonzero(d).tolist() == rec["gnss_obs_hit"]
    assert 5.0 < np.std(d[rec["gnss_obs_hit"]]) < 40.0  # N(0, 20 m)


def test_f9_f11_f12(tables: Tables) -> None:
    out = apply_scenario(tables, "f9", fault("F9")).tables["gnss"]
    dv = column(out, "vel_n_mps") - column(tables["gnss"], "vel_n_mps")
    assert np.flatnonzero(dv).size == 1
    assert dv.max() == pytest.approx(5.0)
    nan = apply_scenario(tables, "f11", fault("F11")).tables
    assert np.isnan(column(nan["gnss"], "lat_deg")).sum() == 1
    assert np.isnan(column(nan["gnss_obs"], "pseudorange_m")).sum() == 1
    imu = apply_scenario(tables, "f12", fault("F12")).tables["imu"]
    assert tables["imu"].num_rows - imu.num_rows == 200  # 2 s at 100 Hz


def test_one_epoch_fault_after_the_log_is_an_error(tables: Tables) -> None:
    with pytest.raises(ScenarioError, match="F1 at 500"):
        apply_scenario(tables, "f1", fault("F1", 500.0))


def test_outage_windows_remove_both_gnss_streams(tables: Tables) -> None:
    spec = ScenarioSpec(windows=WindowsSpec("explicit", 10.0, starts_s=(20.0, 40.0)))
    applied = apply_scenario(tables, "o", spec)
    for name in ("gnss", "gnss_obs"):
        t = tables[name].column("t_ns").to_numpy() - t0(tables)
        inside = ((t >= 20 * NS) & (t < 30 * NS)) | ((t >= 40 * NS) & (t < 50 * NS))
        assert tables[name].num_rows - applied.tables[name].num_rows == inside.sum() > 0
        kept = applied.tables[name].column("t_ns").to_numpy() - t0(tables)
        assert not np.isin(kept, t[inside]).any()
    meta = applied.metadata()
    assert [w["start_s"] for w in meta["windows"]] == [20.0, 40.0]
    assert meta["windows"][0]["kind"] == "outage"
