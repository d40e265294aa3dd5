"""Paper 000's claims beside our Monte Carlo numbers, with a verdict computed from them.

Each claim is compared through a paired difference (filter A minus filter B, seed by seed)
and its confidence interval: ``no practical difference`` when the whole interval lies within
the equivalence margin (``experiments.tractor_cascaded.equivalence_*``), otherwise
``reproduced`` when it lies on the claimed side of zero, ``contradicted`` when it lies on the
other side, ``not distinguishable`` when it contains zero. A convergence claim for a filter
whose bias converged within the band in fewer than half of the runs (while the other's did
in at least half) is ``contradicted``; ``not measurable`` when too few runs remain to
compare. Nothing here is tuned to the paper: the verdicts follow the numbers.

Every claim is judged once per reading of Table 1 (``reading`` column): the sections' own
(params.yaml: per second, ``Q = Table 1 * dt``) and each ``sensitivity_noise_interval_s``
variant (``@q0.02s``: Table 1 as the variance of one 0.02 s step, the literal reading), each
against the EKF with the same reading.

``mechanisms`` adds measurements that test *why* our results differ where they do, and the
rows they explain carry the result in their note. With paper 000's alpha = 1e-3 the sigma
points sit within ``1e-3 sqrt(6)`` standard deviations of the mean, so the unscented transform
reduces to a second-order expansion: the predicted mean gains ``1/2 tr(f'' P)`` and the
covariance equals the EKF's ``F P F^T`` to that order. In the navigation model the only
curvature is ``E_dot, N_dot = (V - r_b)(sin, cos) psi``, so the UKF's North rate is
``(V - r_b) cos(psi) (1 - P_psipsi / 2)`` where the EKF's is ``(V - r_b) cos(psi)``, with
``P_psipsi`` the posterior heading variance the sigma points are drawn from. With GPS the
filter absorbs the factor in the radar bias, which tracks ``V_radar - V / (1 - P_psipsi /
2)``. Table 1 read per second leaves ``P_psipsi`` near 0.004 rad^2 once settled (offset
-0.006 m/s, inside the band), but ``P_psipsi`` starts from ``P0`` (0.25 rad^2, ours: the paper
states none) and takes about 0.3 s to fall below 0.026 rad^2 (where the offset equals the
0.04 m/s band); the large term of those first steps puts the UKF's radar bias a few
hundredths of a m/s behind the EKF's, and the slowly observed radar bias works that lag off
over seconds, so it enters the band later than the EKF's (the paired error at 5 s,
``radar_bias_err_5s_mps``, measures the lag). Read per 0.02 s step, Table 1's heading-bias
random walk with its position noise leaves ``psi`` and ``psi_b`` separable only weakly
through the track, ``P_psipsi`` stays near 0.15 rad^2 and the offset (-0.25 m/s) never
leaves the band's outside. Without GPS the term integrates into the
position while the heading variance grows, so the UKF drifts more. This is the paper's UKF,
not a defect of ours: with the unscented mean replaced by the propagated central point our UKF
reproduces the EKF's radar-bias estimate and covariance
(``tests/pipeline/estimation/cascaded/test_ukf_radar_bias.py``). The checks compare the sizes
this predicts with the sizes measured.
"""

from __future__ import annotations

import math
from typing import Any

from navreplay.pipeline.estimation.cascaded.config import CascadedFilterParams
from navreplay.pipeline.experiments.tractor_cascaded.config import (
    BASELINE,
    NOMINAL,
    PSI_D_LABEL,
    TractorExperimentParams,
)
from navreplay.pipeline.synth.tractor import TractorStraightParams

UKF, HYBRID = "cascaded_ukf", "cascaded_hybrid"
_RADAR_SETTLED = "bias_err_mean_settled_radar_bias_mps"
_OTHER_BIASES = ("gyro_bias_z_radps", "heading_bias_rad", "steer_bias_rad")


def verdict(ci: dict[str, Any], claimed_sign: int, margin: float, n_min: int = 3) -> str:
    """Verdict on a claim that the paired difference has sign ``claimed_sign`` (-1 or +1),
    with an equivalence ``margin`` in the metric's unit (module docstring)."""
    if ci["n"] < n_min or ci.get("ci_low") is None or ci.get("ci_high") is None:
        return "not measurable"
    if -margin <= ci["ci_low"] and ci["ci_high"] <= margin:
        return "no practical difference"
    lo, hi = sorted((ci["ci_low"] * claimed_sign, ci["ci_high"] * claimed_sign))
    if lo > 0:
        return "reproduced"
    if hi < 0:
        return "contradicted"
    return "not distinguishable"


def _stat(summary: dict[str, Any], label: str, scenario: str, metric: str) -> dict[str, Any]:
    return dict(summary["stats"].get(label, {}).get(scenario, {}).get(metric, {"n": 0}))


def _paired(summary: dict[str, Any], label: str, scenario: str, metric: str) -> dict[str, Any]:
    return dict(summary["paired"].get(label, {}).get(scenario, {}).get(metric, {"n": 0}))


def _row(claim: str, paper: str, metric: str, ours: dict[str, Any], claimed_sign: int,
         margin: float, note: str = "", override: str | None = None) -> dict[str, Any]:  # fmt: skip
    return {
        "claim": claim,
        "paper": paper,
        "metric": metric,
        "ours": ours,
        "margin": margin,
        "verdict": override or verdict(ours, claimed_sign, margin),
        "note": note,
    }


def _convergence_row(summary: dict[str, Any], a: str, b: str, bias: str, seeds: int,
                     claim: str, paper: str, margin: float) -> dict[str, Any]:  # fmt: skip
    """A claim that ``a`` converges ``bias`` faster than ``b``."""
    m = f"conv_{bias}"
    ca, cb = _stat(summary, a, NOMINAL, m), _stat(summary, b, NOMINAL, m)
    note = (
        f"converged within the band in {ca['n']}/{seeds} {_short(a)} and {cb['n']}/{seeds} "
        f"{_short(b)} runs; mean {_fmt(ca.get('mean'))} s vs {_fmt(cb.get('mean'))} s"
    )
    if ca["n"] >= 3 and cb["n"] >= 3 and ca.get("mean"):
        note += f"; time ratio {_short(b)}/{_short(a)} {cb['mean'] / ca['mean']:.2f}"
    override = None
    if 2 * ca["n"] < seeds <= 2 * cb["n"]:
        override = "contradicted"
    return _row(claim, paper, f"{m}: {_short(a)} - {_short(b)} (s)",
                _paired(summary, a, NOMINAL, m), -1, margin, note, override)  # fmt: skip


def _short(label: str) -> str:
    return label.partition("@")[0].removeprefix("cascaded_").upper()


def reading_name(suffix: str, default_interval_s: float) -> str:
    """Human name of a reading of Table 1: ``""`` (the sections' own) or ``@q<interval>s``."""
    interval = float(suffix.removeprefix("@q").removesuffix("s")) if suffix else default_interval_s
    what = "per second" if interval == 1.0 else f"per {interval:g} s"
    if interval == 0.02:
        what = "per 0.02 s step (literal)"
    return f"Table 1 {what}" + (" (default)" if not suffix else "")


def readings(exp: TractorExperimentParams) -> list[str]:
    """Label suffixes of the readings of Table 1 the experiment ran, the default first."""
    return ["", *dict.fromkeys(f"@q{v:g}s" for v in exp.sensitivity_noise_interval_s)]


def paper_comparison(
    summary: dict[str, Any],
    exp: TractorExperimentParams,
    mech: dict[str, Any] | None = None,
    default_interval_s: float = 1.0,
) -> list[dict[str, Any]]:
    """One row per claim and reading of Table 1 (``readings``; the rows of one claim are
    adjacent): the paper's statement, our paired difference with its interval, the verdict
    (see the module docstring); the UKF rows' notes quote ``mech`` (``mechanisms``), the
    measured explanation, when given."""
    per_reading = [
        [dict(row, reading=reading_name(r, default_interval_s))
         for row in _claims(summary, exp, mech or {}, r)]
        for r in readings(exp)
    ]  # fmt: skip
    return [row for rows in zip(*per_reading, strict=True) for row in rows]


def _claims(summary: dict[str, Any], exp: TractorExperimentParams, mech: dict[str, Any],
            r: str) -> list[dict[str, Any]]:  # fmt: skip
    """The claims with the labels of reading ``r`` (label suffix)."""
    seeds, dt, dm = exp.seeds, exp.equivalence_s, exp.equivalence_m
    ekf, ukf, hybrid = BASELINE + r, UKF + r, HYBRID + r
    rows: list[dict[str, Any]] = []
    slow = _stat(summary, ekf, NOMINAL, "conv_radar_over_slowest_other")
    radar = _stat(summary, ekf, NOMINAL, "conv_radar_bias_mps").get("mean")
    rows.append(_row(
        "EKF: the radar bias converges slowest, about twice as long as the others",
        "about 2x; the EKF's biases converge in about 20 s (section 9.1)",
        "conv_radar_over_slowest_other: EKF ratio of convergence times, minus 1",
        _shift(slow, -1.0), +1, 0.0, f"EKF radar-bias convergence {_fmt(radar)} s",
    ))  # fmt: skip
    if UKF in exp.filters:
        rows.append(_convergence_row(
            summary, ukf, ekf, "radar_bias_mps", seeds,
            "UKF radar-bias estimate converges faster than the EKF's",
            "about 2x faster (section 9.2)", dt,
        ))  # fmt: skip
        rows[-1]["note"] += _radar_bias_note(mech.get("ukf_radar_bias_offset" + r))
        for bias in _OTHER_BIASES:
            rows.append(_convergence_row(
                summary, ukf, ekf, bias, seeds,
                f"UKF {bias.split('_bias')[0]} bias converges faster than the EKF's",
                "UKF within a few seconds (section 9.2, Fig. 12-13)", dt,
            ))  # fmt: skip
        for axis, name in (("e", "East"), ("n", "North")):
            m = f"pos_err_{axis}_rms_m"
            rows.append(_row(
                f"EKF {name} position error smaller than the UKF's",
                "EKF smaller, especially North (section 9.3, Fig. 14)",
                f"{m}: UKF - EKF (m)", _paired(summary, ukf, NOMINAL, m), +1, dm,
                "GPS at every 0.02 s step (0.03 m sigma) pins both filters' positions; the "
                "UKF's North-rate deficit goes into its radar bias instead (radar-bias row)",
            ))  # fmt: skip
        for scen in exp.scenarios():
            if scen == NOMINAL:
                continue
            rows.append(_row(
                f"UKF drifts less than the EKF in a GPS outage ({scen})",
                "expected from the UKF's better bias estimates (section 9.3)",
                "drift_end_m: UKF - EKF (m)", _paired(summary, ukf, scen, "drift_end_m"), -1,
                dm, _drift_note(mech.get(f"ukf_outage_north_drift_{scen}{r}")),
            ))  # fmt: skip
    if HYBRID in exp.filters:
        rows.append(_row(
            "Hybrid keeps the EKF's position accuracy (not worse)",
            "proposed as future work (section 9.3)", "pos_err_n_rms_m: hybrid - EKF (m)",
            _paired(summary, hybrid, NOMINAL, "pos_err_n_rms_m"), -1, dm,
        ))  # fmt: skip
        rows.append(_convergence_row(
            summary, hybrid, ekf, "radar_bias_mps", seeds,
            "Hybrid converges the radar bias faster than the EKF",
            "proposed as future work (section 9.3)", dt,
        ))  # fmt: skip
        for scen in exp.scenarios():
            if scen != NOMINAL:
                rows.append(_row(
                    f"Hybrid drifts no more than the EKF in a GPS outage ({scen})",
                    "not claimed (our hybrid's design goal)", "drift_end_m: hybrid - EKF (m)",
                    _paired(summary, hybrid, scen, "drift_end_m"), -1, dm,
                ))  # fmt: skip
    return rows


def _radar_bias_note(m: dict[str, Any] | None) -> str:
    """The measured explanation of the UKF's radar-bias offset (``mechanisms``)."""
    if not m or m["measured_mps"].get("mean") is None:
        return ""
    note = (
        f"; why: not a UKF defect but the paper's unscented mean (alpha 1e-3: the second-order "
        f"term -dt/2 (V - r_b) cos(psi) P_psipsi on each North step; with the central-point "
        f"mean our UKF equals the EKF). GPS pins North, so r_b tracks V_radar - V / (1 - "
        f"P_psipsi / 2): with the UKF's own settled heading variance "
        f"{m['heading_var_rad2']:.4f} rad^2 that predicts a settled error of "
        f"{m['predicted_mps']:+.3f} m/s; measured {_fmt(m['measured_mps']['mean'], 3)} m/s "
        f"(EKF {_fmt(m['ekf_measured_mps'].get('mean'), 3)} m/s)"
    )
    lag = m.get("lag_5s_mps", {})
    if lag.get("mean") is not None and abs(m["predicted_mps"]) < m["band_mps"]:
        note += (
            f". The settled offset is inside the band; the slower convergence comes from the "
            f"transient: while P_psipsi is still above its settled value (it starts from P0) "
            f"the larger term leaves the UKF's radar bias {_fmt(lag['mean'], 3)} m/s (CI "
            f"{_fmt(lag.get('ci_low'), 3)} to {_fmt(lag.get('ci_high'), 3)}) behind the "
            f"EKF's at 5 s, a lag it works off only "
            f"as fast as the radar bias is observed"
        )
    return note


def _drift_note(m: dict[str, Any] | None) -> str:
    """The measured explanation of the UKF's extra outage drift (``mechanisms``)."""
    if not m or m["measured_m"].get("mean") is None or m["predicted_m"].get("mean") is None:
        return ""
    return (
        f"why: the paper's unscented mean, not a UKF defect. Its second-order term -dt/2 "
        f"(V - r_b) cos(psi) P_psipsi summed over the outage's steps (the UKF's own estimate "
        f"and heading variance, which grows without GPS by Table 1's heading noise and the "
        f"gyro-bias uncertainty) predicts a North drift of {_fmt(m['predicted_m']['mean'], 3)} "
        f"m; measured {_fmt(m['measured_m']['mean'], 3)} m (EKF "
        f"{_fmt(m['ekf_measured_m'].get('mean'), 3)} m)"
    )


def _shift(stat: dict[str, Any], by: float) -> dict[str, Any]:
    """A statistic with its mean and interval shifted by ``by``."""
    out = dict(stat)
    for k in ("mean", "ci_low", "ci_high"):
        if out.get(k) is not None:
            out[k] += by
    return out


def _fmt(v: Any, digits: int = 2) -> str:
    return "n/a" if v is None else f"{v:.{digits}f}"


def mechanisms(
    summary: dict[str, Any],
    exp: TractorExperimentParams,
    sim: TractorStraightParams,
    ukf_section: CascadedFilterParams | None,
) -> dict[str, Any]:
    """Measurements testing the explanations (module docstring): predicted vs measured, per
    reading of Table 1 (keys end with the reading's label suffix, ``""`` for the default)."""
    out: dict[str, Any] = {}
    for r in readings(exp):
        out.update({k + r: v for k, v in _mechanisms(summary, exp, sim, ukf_section, r).items()})
    if exp.paper_linearization:
        out["ekf_linearization_point"] = {
            "what": "radar-bias convergence time of the EKF linearized about psi_d (paper eq. "
            "17 as printed) minus the EKF linearized at the estimate",
            "paired_s": _paired(summary, PSI_D_LABEL, NOMINAL, "conv_radar_bias_mps"),
        }
    return out


def _mechanisms(summary: dict[str, Any], exp: TractorExperimentParams,
                sim: TractorStraightParams, ukf_section: CascadedFilterParams | None,
                r: str) -> dict[str, Any]:  # fmt: skip
    out: dict[str, Any] = {}
    ukf, ekf = UKF + r, BASELINE + r
    if ukf_section is not None and UKF in exp.filters:
        var = _stat(summary, ukf, NOMINAL, "heading_var_settled_rad2")
        if var.get("mean") is not None:
            p_psi = var["mean"]
            predicted = -sim.speed_mps * (1.0 / (1.0 - p_psi / 2.0) - 1.0)
            band = ukf_section.convergence_band.radar_bias_mps
            out["ukf_radar_bias_offset"] = {
                "what": "UKF radar-bias error after settling: predicted from the unscented "
                "second-order term with the filter's own mean posterior heading variance (the "
                "one its sigma points are drawn from), -V (1 / (1 - P_psipsi / 2) - 1), and "
                "measured; and the UKF's radar-bias lag behind the EKF's during convergence "
                "(paired error at 5 s, UKF - EKF)",
                "heading_var_rad2": p_psi,
                "predicted_mps": predicted,
                "measured_mps": _stat(summary, ukf, NOMINAL, _RADAR_SETTLED),
                "ekf_measured_mps": _stat(summary, ekf, NOMINAL, _RADAR_SETTLED),
                "band_mps": band,
                "lag_5s_mps": _paired(summary, ukf, NOMINAL, "radar_bias_err_5s_mps"),
            }
        for scen, windows in exp.scenarios().items():
            if not windows:
                continue
            out[f"ukf_outage_north_drift_{scen}"] = {
                "what": "UKF North drift over the outage (error at its end minus at its "
                "start): predicted as the sum over the outage's steps of the unscented "
                "second-order term 1/2 tr(f'' P) computed from the UKF's own estimate and "
                "covariance (runs.ut_north_term), and measured; the EKF's drift for scale",
                "predicted_m": _stat(summary, ukf, scen, "ut_term_n_outage_m"),
                "measured_m": _stat(summary, ukf, scen, "drift_n_rel_end_m"),
                "ekf_measured_m": _stat(summary, ekf, scen, "drift_n_rel_end_m"),
            }
    hv = _stat(summary, ekf, NOMINAL, "heading_var_settled_rad2")
    he = _stat(summary, ekf, NOMINAL, "heading_err_rms_settled_rad")
    if hv.get("mean") is not None and he.get("mean") is not None:
        out["heading_consistency"] = {
            "what": "EKF heading after settling: the filter's own 1-sigma against the actual "
            "RMS error (the simulated tractor has no process noise, so any Q makes the filter "
            "conservative; how much is the reading's doing)",
            "filter_sigma_rad": math.sqrt(hv["mean"]),
            "actual_rms_rad": he["mean"],
        }
    return out
