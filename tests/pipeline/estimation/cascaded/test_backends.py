"""One model, two backends: the compiled cascade and filterpy's filters agree."""

from __future__ import annotations

import dataclasses

import numpy as np
import pyarrow as pa
import pytest

from navreplay.pipeline.estimation.cascaded.backends import replay
from navreplay.pipeline.estimation.cascaded.closed_loop import run_closed_loop
from navreplay.pipeline.estimation.cascaded.config import CascadedFilterParams
from navreplay.pipeline.estimation.cascaded.engine import CascadedResult, make_setup
from navreplay.pipeline.estimation.cascaded.inputs import prepare_inputs
from navreplay.pipeline.estimation.cascaded.outputs import sigmas
from navreplay.pipeline.synth.tractor import TractorStraightParams
from tests.pipeline.estimation.cascaded.conftest import CASCADED


def assert_agree(fast: CascadedResult, ref: CascadedResult) -> None:
    """States within 1e-6 sigma, sigmas within 1e-6, the same innovation times and gating,
    normalized innovations (sqrt NIS) within 1e-6 sigma."""
    assert fast.status == ref.status == "ok"
    np.testing.assert_array_equal(fast.t_ns, ref.t_ns)
    sig = sigmas(fast)
    assert np.max(np.abs(fast.x - ref.x) / sig) < 1e-6
    np.testing.assert_allclose(sigmas(ref), sig, rtol=1e-6)
    np.testing.assert_array_equal(fast.inn_i, ref.inn_i)  # times, streams, gating decisions
    np.testing.assert_allclose(np.sqrt(fast.inn_f[:, 0]), np.sqrt(ref.inn_f[:, 0]), rtol=0,
                               atol=1e-6)  # fmt: skip
    assert [e.kind for e in fast.events] == [e.kind for e in ref.events]


@pytest.mark.parametrize("name", CASCADED)
def test_numba_and_filterpy_agree_on_a_recorded_run_within_1e_6_sigma(
    name: str, sections: dict[str, CascadedFilterParams], recording20: dict[str, pa.Table]
) -> None:
    inp = prepare_inputs(recording20, name)
    setup = make_setup(name, sections[name])
    fast = replay(setup, inp.veh_t, inp.veh, inp.gps_t, inp.gps, "numba")
    ref = replay(setup, inp.veh_t, inp.veh, inp.gps_t, inp.gps, "filterpy")
    assert fast.t_ns.size == 1001
    assert_agree(fast, ref)


def test_backends_agree_with_gps_between_samples_and_irregular_steps(
    sections: dict[str, CascadedFilterParams], recording20: dict[str, pa.Table]
) -> None:
    """GPS at 5 Hz shifted 7 ms off the vehicle samples (navigation-only epochs), one
    vehicle sample in three dropped (0.04 s steps: another control discretization), a gap."""
    inp = prepare_inputs(recording20, "cascaded_ukf")
    keep = np.ones(inp.veh_t.size, bool)
    keep[::3] = False
    keep[300:340] = False  # a 0.8 s gap: input_gap event, split Euler steps
    veh_t, veh = inp.veh_t[keep], inp.veh[keep]
    gps_t, gps = inp.gps_t[::10] + 7_000_000, inp.gps[::10]
    setup = make_setup("cascaded_ukf", sections["cascaded_ukf"])
    fast = replay(setup, veh_t, veh, gps_t, gps, "numba")
    ref = replay(setup, veh_t, veh, gps_t, gps, "filterpy")
    assert "input_gap" in [e.kind for e in fast.events]
    off_grid = np.unique(fast.inn_i[fast.inn_i[:, 0] % 20_000_000 == 7_000_000, 0])
    inside = (gps_t > veh_t[0]) & (gps_t < veh_t[-1])
    np.testing.assert_array_equal(off_grid, gps_t[inside])  # every fix as a nav-only epoch
    assert_agree(fast, ref)


@pytest.mark.parametrize("name", CASCADED)
def test_backends_agree_in_closed_loop_through_an_outage(
    name: str, sections: dict[str, CascadedFilterParams], sim_params: TractorStraightParams
) -> None:
    """The LQR closes the loop on each backend's estimates: same trajectory, same estimates."""
    short = dataclasses.replace(sim_params, duration_s=8.0)
    setup = make_setup(name, sections[name])
    runs = [
        run_closed_loop(setup, short, 5, gps_outages_s=[(4.0, 6.0)], backend=b)
        for b in ("numba", "filterpy")
    ]
    assert_agree(runs[0].result, runs[1].result)
    np.testing.assert_allclose(runs[0].truth, runs[1].truth, rtol=0, atol=1e-6)
