"""Paper 000's experiments with every cascaded filter in closed loop, as pure functions.

For each filter label (``cascaded_ekf``, ``cascaded_ukf``, ``cascaded_hybrid`` and, to test
an explanation of the paper's EKF, ``cascaded_ekf_psi_d``: the EKF with ``J1`` linearized
about the desired heading as the paper prints it) and each Monte Carlo seed, the 80 s
scenario of section 9 runs in closed loop (``closed_loop``: the LQR steers the simulated
tractor from that filter's estimates, 3 m step, 3 m/s due North, 50 Hz), nominally and with
one GPS outage of each configured length starting at ``outage_start_s``. A seed fixes the
sensor noise, so the runs of one seed are paired across filters and scenarios.

Each filter also runs, every scenario, with each other reading of Table 1 in
``sensitivity_noise_interval_s`` (label ``<filter>@q<interval>s``; e.g. ``@q0.02s``, Table 1
per 0.02 s step, beside the sections' per-second reading).

``summarize_run`` reduces a run to scalars (``RunSummary``); ``run_experiment`` runs them all
(in ``workers`` processes; the result does not depend on their number) and ``summarize``
aggregates: means with t-based confidence intervals per label, scenario and metric, and
paired differences against ``cascaded_ekf`` with the same reading of Table 1.
``comparison.paper_comparison`` puts the paper's claims beside these numbers; ``figures``
draws them; the stage
``navreplay experiment tractor_cascaded`` writes everything.
"""

from __future__ import annotations

import dataclasses
import math
import time
import zlib
from collections.abc import Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import stats

from navreplay.pipeline.estimation.cascaded.closed_loop import (
    ClosedLoopRun,
    run_closed_loop_scenarios,
)
from navreplay.pipeline.estimation.cascaded.config import (
    CascadedFilterParams,
    LinearizationParams,
)
from navreplay.pipeline.estimation.cascaded.engine import make_setup
from navreplay.pipeline.estimation.cascaded.metrics import BIASES, bias_convergence
from navreplay.pipeline.estimation.cascaded.model import NAV_E, NAV_N, NAV_PSI, NAV_RB, NX
from navreplay.pipeline.experiments.tractor_cascaded.config import (
    BASELINE,
    NOMINAL,
    PSI_D_LABEL,
    TractorExperimentParams,
)
from navreplay.pipeline.nav.earth import F64
from navreplay.pipeline.synth.tractor import TractorStraightParams

RADAR_PROBE_S = 5.0  #: time of the ``radar_bias_err_5s_mps`` sample, s


@dataclass(frozen=True)
class ExperimentInputs:
    """Everything the runs need (picklable for the worker processes)."""

    sim: TractorStraightParams
    sections: Mapping[str, CascadedFilterParams]
    exp: TractorExperimentParams
    seed: int


@dataclass(frozen=True)
class RunSpec:
    label: str
    scenario: str
    seed_index: int


@dataclass
class RunSummary:
    """The scalars of one run; ``series`` holds the example seed's time series."""

    spec: RunSpec
    values: dict[str, float]
    runtime_s: float
    wall_s: float
    series: dict[str, F64] | None = None
    extra: dict[str, Any] = field(default_factory=dict)


def labels(exp: TractorExperimentParams) -> list[str]:
    """Filter labels in report order."""
    out = list(exp.filters)
    if exp.paper_linearization:
        out.insert(out.index(BASELINE) + 1, PSI_D_LABEL)
    for interval in exp.sensitivity_noise_interval_s:
        out += [sensitivity_label(f, interval) for f in exp.filters]
    return out


def sensitivity_label(name: str, interval_s: float) -> str:
    """The label of filter ``name`` with Table 1 accumulating over ``interval_s``."""
    return f"{name}@q{interval_s:g}s"


def is_variant(label: str) -> bool:
    """Labels run in the nominal scenario only (the paper-linearization variant; the noise
    variants run every scenario, to compare outage drifts under both readings of Table 1)."""
    return label == PSI_D_LABEL


def reading_of(label: str) -> str:
    """The Table 1 reading of a label: ``""`` for the sections' own, ``"@q<interval>s"``."""
    return label[label.index("@q") :] if "@q" in label else ""


def baseline_of(label: str) -> str:
    """The paired baseline of a label: ``cascaded_ekf`` with the same reading of Table 1."""
    return BASELINE + reading_of(label)


def section_for(label: str, sections: Mapping[str, CascadedFilterParams],
                sim: TractorStraightParams) -> tuple[str, CascadedFilterParams]:  # fmt: skip
    """(filter name, params section) of a label: the psi_d variant linearizes about the
    simulated line's heading; ``<name>@q<interval>s`` changes ``process_noise.interval_s``."""
    if label == PSI_D_LABEL:
        lin = LinearizationParams("desired_heading", sim.line_heading_deg)
        return BASELINE, dataclasses.replace(sections[BASELINE], linearization=lin)
    if "@q" in label:
        name, interval = label.split("@q")
        sec = sections[name]
        pn = dataclasses.replace(sec.process_noise, interval_s=float(interval.removesuffix("s")))
        return name, dataclasses.replace(sec, process_noise=pn)
    return label, sections[label]


def run_seed(seed: int, index: int) -> np.random.SeedSequence:
    """The noise seed of Monte Carlo run ``index`` (independent of every dataset's)."""
    return np.random.SeedSequence([seed, zlib.crc32(b"tractor_cascaded"), index])


def specs(exp: TractorExperimentParams) -> list[RunSpec]:
    """Every run of the experiment, in a fixed order."""
    out: list[RunSpec] = []
    for label in labels(exp):
        for scenario in exp.scenarios():
            if is_variant(label) and scenario != NOMINAL:
                continue
            out += [RunSpec(label, scenario, i) for i in range(exp.seeds)]
    return out


def _rms(a: F64) -> float:
    return float(np.sqrt(np.mean(np.square(a)))) if a.size else math.nan


def _recovery_s(t: F64, lateral: F64, tol: float, t_end: float) -> float:
    """First time after which |lateral| < tol holds until ``t_end``; NaN if it never does."""
    sel = t < t_end
    out = np.abs(lateral[sel]) >= tol
    if not out.size or out[-1]:
        return math.nan
    bad = np.flatnonzero(out)
    return float(t[sel][0] if not bad.size else t[sel][bad[-1] + 1])


def summarize_run(run: ClosedLoopRun, spec: RunSpec, inputs: ExperimentInputs) -> RunSummary:
    """Reduce one closed-loop run to the scalars of ``RunSummary.values``."""
    exp, section = inputs.exp, section_for(spec.label, inputs.sections, inputs.sim)[1]
    res, t = run.result, run.t_s
    x, tx = res.x, run.truth_x[: res.x.shape[0]]
    t = t[: x.shape[0]]
    err = x - tx
    settled = t >= exp.settle_s
    v: dict[str, float] = {"diverged": float(res.status != "ok")}
    conv = bias_convergence(t, x, tx, section.convergence_band)
    for name, i in BIASES:
        c = conv[name]
        v[f"conv_{name}"] = math.nan if c is None else c
        v[f"bias_err_end_{name}"] = float(err[-1, i])
        v[f"bias_err_mean_settled_{name}"] = float(np.mean(err[settled, i]))
    others = [v[f"conv_{n}"] for n, _ in BIASES[1:]]
    v["conv_radar_over_slowest_other"] = v["conv_radar_bias_mps"] / max(others)
    for axis, i in (("e", NAV_E), ("n", NAV_N)):
        v[f"pos_err_{axis}_rms_m"] = _rms(err[:, i])
        v[f"pos_err_{axis}_rms_settled_m"] = _rms(err[settled, i])
        v[f"pos_err_{axis}_mean_settled_m"] = float(np.mean(err[settled, i]))
    v["heading_err_rms_settled_rad"] = _rms(err[settled, NAV_PSI])
    v["heading_var_settled_rad2"] = float(np.mean(res.P[settled, 0, NAV_PSI, NAV_PSI]))
    # the radar-bias error during convergence (the UKF's lag behind the EKF: comparison)
    k5 = min(int(np.searchsorted(t - t[0], RADAR_PROBE_S)), t.size - 1)
    v["radar_bias_err_5s_mps"] = float(err[k5, NAV_RB])
    lat = run.lateral_err_m[: x.shape[0]]
    outages = inputs.exp.scenarios()[spec.scenario]
    t_free = outages[0][0] if outages else float(t[-1]) + 1.0
    v["step_recovery_s"] = _recovery_s(t, lat, exp.step_tolerance_m, t_free)
    v["lateral_rms_settled_m"] = _rms(lat[settled & (t < t_free)])
    v["lateral_abs_max_settled_m"] = float(np.max(np.abs(lat[settled & (t < t_free)])))
    v["lateral_abs_end_m"] = float(abs(lat[-1]))
    if outages:
        a, b = outages[0]
        inside = np.flatnonzero((t >= a) & (t < b))
        e_h = np.hypot(err[:, NAV_E], err[:, NAV_N])
        v["drift_end_m"] = float(e_h[inside[-1]])
        v["drift_max_m"] = float(e_h[inside].max())
        v["drift_e_end_m"] = float(err[inside[-1], NAV_E])
        v["drift_n_end_m"] = float(err[inside[-1], NAV_N])
        v["lateral_abs_outage_end_m"] = float(abs(lat[inside[-1]]))
        v["lateral_abs_outage_max_m"] = float(np.max(np.abs(lat[inside])))
        v["heading_err_outage_end_rad"] = float(err[inside[-1], NAV_PSI])
        v["drift_n_rel_end_m"] = float(err[inside[-1], NAV_N] - err[inside[0], NAV_N])
        v["ut_term_n_outage_m"] = float(np.sum(ut_north_term(x, res.P, tx, inputs.sim.dt_s)[
            inside[:-1]]))  # fmt: skip
    return RunSummary(spec, v, res.runtime_s, 0.0)


def ut_north_term(x: F64, P: F64, truth_x: F64, dt_s: float) -> F64:
    """The second-order term the unscented mean adds to each North step (K,), m.

    For ``N+ = N + dt (V - r_b) cos(psi)`` it is ``1/2 tr(f'' P) = -dt/2 (V - r_b) cos(psi)
    P_psipsi + dt sin(psi) P_psi,rb`` at the estimate and covariance of the step's start
    (alpha -> 0 limit of the scaled unscented transform); ``V`` is the radar speed without
    its noise (true speed plus true radar bias).
    """
    v = truth_x[:, NX + 2] + truth_x[:, NAV_RB] - x[:, NAV_RB]
    psi = x[:, NAV_PSI]
    p_pp = P[:, 0, NAV_PSI, NAV_PSI]
    p_pr = P[:, 0, NAV_PSI, NAV_RB]
    out: F64 = -0.5 * dt_s * v * np.cos(psi) * p_pp + dt_s * np.sin(psi) * p_pr
    return out


def _series(run: ClosedLoopRun, rate_hz: float, dt_s: float) -> dict[str, F64]:
    """The example run's time series, decimated to ``rate_hz``."""
    res = run.result
    k = res.x.shape[0]
    step = max(1, round(1.0 / (rate_hz * dt_s)))
    idx = np.arange(0, k, step)
    sig = np.sqrt(np.concatenate(
        [np.diagonal(res.P[:, f], axis1=1, axis2=2) for f in range(2)], axis=1))  # fmt: skip
    out: dict[str, F64] = {"t_s": run.t_s[idx], "lateral_err_m": run.lateral_err_m[idx],
                           "gps_valid": run.gps_valid[idx].astype(float)}  # fmt: skip
    for j in range(2 * NX):
        out[f"x{j}"] = res.x[idx, j]
        out[f"truth{j}"] = run.truth_x[idx, j]
        out[f"sigma{j}"] = sig[idx, j]
    return out


def run_seed_label(label: str, seed_index: int, inputs: ExperimentInputs) -> list[RunSummary]:
    """Every scenario of one label and seed in closed loop (sharing the samples before the
    outages: ``closed_loop.run_closed_loop_scenarios``), summarized; with the time series
    for the example seed."""
    name, section = section_for(label, inputs.sections, inputs.sim)
    flag = dataclasses.replace(section.divergence, on_divergence="flag")
    setup = make_setup(name, dataclasses.replace(section, divergence=flag))
    scenarios = {s: w for s, w in inputs.exp.scenarios().items()
                 if not is_variant(label) or s == NOMINAL}  # fmt: skip
    t0 = time.perf_counter()
    runs = run_closed_loop_scenarios(setup, inputs.sim, run_seed(inputs.seed, seed_index),
                                     scenarios)  # fmt: skip
    wall = (time.perf_counter() - t0) / len(runs)
    out = []
    for scen, run in runs.items():
        summary = summarize_run(run, RunSpec(label, scen, seed_index), inputs)
        summary.wall_s = wall
        if seed_index == inputs.exp.example_seed:
            summary.series = _series(run, inputs.exp.timeseries_rate_hz, inputs.sim.dt_s)
        out.append(summary)
    return out


def _run_chunk(chunk: Sequence[tuple[str, int]], inputs: ExperimentInputs) -> list[RunSummary]:
    return [s for label, seed in chunk for s in run_seed_label(label, seed, inputs)]


def run_experiment(inputs: ExperimentInputs) -> list[RunSummary]:
    """Every run of the experiment, in ``specs`` order (independent of ``workers``)."""
    todo = specs(inputs.exp)
    units = list(dict.fromkeys((s.label, s.seed_index) for s in todo))
    workers = min(inputs.exp.workers, len(units))
    if workers <= 1:
        parts = [_run_chunk(units, inputs)]
    else:
        chunks = [units[i::workers] for i in range(workers)]
        with ProcessPoolExecutor(max_workers=workers) as pool:
            parts = list(pool.map(_run_chunk, chunks, [inputs] * workers))
    by_spec = {s.spec: s for part in parts for s in part}
    return [by_spec[s] for s in todo]


def mean_ci(values: F64, confidence: float) -> dict[str, float | int | None]:
    """n (finite values), mean, sample std and the t-based interval of the mean."""
    a = values[np.isfinite(values)]
    n = int(a.size)
    if n == 0:
        return {"n": 0, "mean": None, "std": None, "ci_low": None, "ci_high": None}
    mean = float(a.mean())
    if n == 1:
        return {"n": 1, "mean": mean, "std": None, "ci_low": None, "ci_high": None}
    std = float(a.std(ddof=1))
    half = float(stats.t.ppf(0.5 + confidence / 2.0, n - 1)) * std / math.sqrt(n)
    return {"n": n, "mean": mean, "std": std, "ci_low": mean - half, "ci_high": mean + half}


def summarize(runs: Sequence[RunSummary], exp: TractorExperimentParams) -> dict[str, Any]:
    """Aggregate the runs: ``stats[label][scenario][metric]`` (``mean_ci`` of the seeds,
    NaN = not converged / not applicable, counted out of ``n``), ``paired[label][scenario]
    [metric]`` (label minus ``baseline_of(label)``, the EKF with the same reading of Table 1,
    seed by seed) and ``seeds``."""
    table: dict[tuple[str, str], dict[str, F64]] = {}
    for key in {(r.spec.label, r.spec.scenario) for r in runs}:
        sel = sorted((r for r in runs if (r.spec.label, r.spec.scenario) == key),
                     key=lambda r: r.spec.seed_index)  # fmt: skip
        names = sel[0].values.keys()
        table[key] = {m: np.array([r.values[m] for r in sel]) for m in names}
    out: dict[str, Any] = {"seeds": exp.seeds, "confidence": exp.confidence, "stats": {},
                           "paired": {}}  # fmt: skip
    for (label, scen), cols in sorted(table.items()):
        out["stats"].setdefault(label, {})[scen] = {
            m: mean_ci(v, exp.confidence) for m, v in sorted(cols.items())
        }
        base = table.get((baseline_of(label), scen))
        if label == baseline_of(label) or base is None:
            continue
        out["paired"].setdefault(label, {})[scen] = {
            m: mean_ci(v - base[m], exp.confidence) for m, v in sorted(cols.items()) if m in base
        }
    return out
