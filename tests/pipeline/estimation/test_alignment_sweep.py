"""Issue 21's alignment acceptance on its hardest corners (``benchmarks/alignment_sweep.py``
runs the whole grid): every INS filter aligns within 5 s of the first sustained motion, its
yaw error 60 s into the motion is under 3 deg (5 deg with 5 m fixes and no receiver
velocity), and no run takes a heading from the noise of differenced fixes at standstill.

Cases that fail today are marked ``xfail(strict=True)`` with the figure measured (seed 1) and
what goes wrong, so that a fix in the estimation code shows up as an unexpected pass."""

from __future__ import annotations

import functools
from pathlib import Path

import pytest

from benchmarks import alignment_sweep as sw
from navreplay.ingest.meta import SensorMeta
from navreplay.pipeline.estimation.ins.replay import run_filter
from navreplay.pipeline.params import Params, load_params

REPO = Path(__file__).resolve().parents[3]
SEED = 1


@functools.cache
def _params() -> Params:
    return load_params(REPO / "params.yaml")


@functools.cache
def _drive(kind: str, noise_m: float, *, white: bool = False) -> tuple[sw.Tables, SensorMeta]:
    return sw.simulate(_params(), kind, noise_m, SEED, white=white)


def _outcome(cell: sw.Cell, name: str, *, white: bool = False) -> sw.Outcome:
    base, sensors = _drive(cell.kind, cell.noise_m, white=white)
    tables, sens = sw.with_bias(base, sensors, cell.bias_dps, SEED)
    if not cell.velocity:
        tables = sw.without_velocity(tables)
    t0 = int(tables["imu"].column("t_ns")[0].as_py())
    t_motion = sw.first_motion_ns(tables["truth"], t0, cell.kind)
    r = run_filter(tables, sens, name, sw.filter_params(_params(), name))
    return sw.measure(cell, SEED, r, tables["truth"], t_motion)


# the hardest corners: the largest gyro bias and noisiest fixes of each start kind, with and
# without receiver velocity, and the cleanest fixes for contrast
CORNERS = [
    sw.Cell("static", 1.0, 5.0, False),
    sw.Cell("static", 1.0, 5.0, True),
    sw.Cell("static", 0.3, 5.0, False),
    sw.Cell("rolling", 1.0, 5.0, False),
    sw.Cell("rolling", 1.0, 0.5, True),
    sw.Cell("reversing", 1.0, 5.0, True),
    sw.Cell("reversing", 0.3, 5.0, False),
    sw.Cell("reversing", 0.01, 0.5, True),
    sw.Cell("static", 1.0, 1.5, False),
    sw.Cell("rolling", 1.0, 1.5, False),
    sw.Cell("rolling", 0.1, 5.0, False),
]

# what goes wrong, measured on seed 1 (the sweep's CSV has seeds 1-3)
LATE_MOTION = (
    "aligned {:.1f} s after the first motion: a course start needs 8.8 m/s (5 sigma of 5 m "
    "fixes differenced 4 s apart) and the heading from motion, its gyros corrected by the "
    "rest's bias estimate (static_gyro_tol_radps 0.05 finds the rest under a 1 deg/s bias), takes "
    "that "
    "long to get under its 8.6 deg bound from 5 m fixes"
)
LOOSE_YAW = "the heading barely observed by fixes alone (variance x61 for their 30 s correlation)"
NHC_WRONG = "overconfident: the NHC holds the wrong heading the start gave it"


def _yaw(err: float, sigma: float, start: float, why: str) -> str:
    return (
        f"yaw {err:+.1f} deg after 60 s of motion, {abs(err) / sigma:.1f} x its sigma of "
        f"{sigma:.2f} deg ({why}); started {start:+.1f} deg off"
    )


#: (cell, filter) -> what was measured on seed 1 and why it fails
KNOWN: dict[tuple[sw.Cell, str], str] = {
    **{(sw.Cell("static", 1.0, 5.0, False), f): LATE_MOTION.format(50.3) for f in sw.FILTERS},
    (sw.Cell("rolling", 1.0, 5.0, False), "lc_ekf"): _yaw(
        34.8, 27.6, 0.8, "1 deg/s gyro bias and no rest on a rolling start; " + LOOSE_YAW
    ),
    (sw.Cell("static", 0.3, 5.0, False), "lc_ekf_nhc"): _yaw(7.9, 0.82, 8.9, NHC_WRONG),
    (sw.Cell("rolling", 0.1, 5.0, False), "lc_ekf"): _yaw(9.7, 9.38, 0.8, LOOSE_YAW),
    (sw.Cell("rolling", 1.0, 1.5, False), "lc_ekf"): _yaw(
        9.1, 16.9, 0.8, "1 deg/s gyro bias and no rest on a rolling start; " + LOOSE_YAW
    ),
}


def _cases() -> list[object]:
    out: list[object] = []
    for cell in CORNERS:
        for name in sw.FILTERS:
            case_id = f"{cell.label().replace(' ', '-')}-{name}"
            why = KNOWN.get((cell, name))
            marks = [pytest.mark.xfail(strict=True, reason=why)] if why else []
            out.append(pytest.param(cell, name, marks=marks, id=case_id))
    return out


@pytest.mark.slow
@pytest.mark.parametrize(("cell", "name"), _cases())
def test_the_filter_aligns_soon_after_motion_and_holds_its_heading(
    cell: sw.Cell, name: str
) -> None:
    o = _outcome(cell, name)
    assert o.status == "ok", o.failure
    assert o.aligned_after_s <= sw.ALIGN_WITHIN_S, o.failure
    assert abs(o.yaw_err_60_deg) < cell.yaw_limit_deg, o.failure
    assert o.passed, o.failure


@pytest.mark.parametrize("bias_dps", [0.01, 1.0])
def test_no_filter_takes_a_heading_from_noise_at_standstill(bias_dps: float) -> None:
    """White 5 m fixes without receiver velocity (differenced, the noisiest speed there is)
    during 15 s at rest: no filter starts before the motion with a heading from the course."""
    cell = sw.Cell("static", bias_dps, 5.0, False)
    for name in sw.FILTERS:
        o = _outcome(cell, name, white=True)
        assert not (o.aligned_after_s < 0.0 and o.method.startswith("gnss_velocity")), o
