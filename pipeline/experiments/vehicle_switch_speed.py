"""Calibration of ``vehicle_switched``'s switching speed on held-out noise realizations.

Paper 003 switches from the kinematic to the dynamic model "at higher speed" but gives no
value. The speed is chosen here by measurement, on seeds disjoint from the acceptance
Monte Carlo (``vehicle_paired``: seeds ``synth.seed + i``, ``i < seeds``), so that the
acceptance is not judged on the data the speed was tuned on:

1. ``car_speed_ramp`` is synthesized on seeds ``synth.seed + calibration_seed_offset + i``,
   ``i < calibration_seeds`` (``experiments.vehicle_bands``), and ``vehicle_kinematic`` and
   ``vehicle_dynamic`` run on each, nominally and with the periodic outages of
   ``vehicle_bands.band_table``, tabulated in the acceptance's speed bands
   (``vehicle_bands.SPEED_EDGES_MPS``).
2. Per scenario and band, the paired difference ``dynamic - kinematic`` of the horizontal
   RMS gets a t interval (``confidence``); the dynamic model is *not worse* there when the
   upper bound is <= the acceptance's equivalence margin (``equivalence_rel`` x the better
   model's mean band RMS): the test the switched filter must pass afterwards, in the same
   bands. (0.5 m/s bands were tried first: below 8 m/s their intervals are up to +-63 mm
   wide against 8-15 mm margins, so bands were failed for want of samples, not because
   the dynamic model was worse, and the rule put the switch at 8.5 m/s, above bands
   where the dynamic model is 2 m better with outages.)
3. ``speed_up_mps`` is the lowest band edge above which the dynamic model is not worse in
   every band of both scenarios; ``speed_down_mps`` is ``HYSTERESIS_MPS`` below it (at
   least half of it).

``navreplay experiment vehicle_switch_speed --out DIR`` runs it and writes
``calibration.{json,csv}`` (one row per scenario and band) and ``switch_note.md``;
``filters.vehicle_switched.switching`` in params.yaml holds the result.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from navreplay.pipeline.estimation.config import FiltersParams
from navreplay.pipeline.estimation.core.contract import Backend
from navreplay.pipeline.experiments.vehicle_bands import SPEED_EDGES_MPS, band_table
from navreplay.pipeline.experiments.vehicle_bands_config import VehicleBandsParams
from navreplay.pipeline.experiments.vehicle_paired import SINGLE, mean_ci
from navreplay.pipeline.synth import car

#: calibration bands, m/s: the acceptance's
CALIBRATION_EDGES_MPS = SPEED_EDGES_MPS
#: back to the kinematic model this far below the switch-up speed: ten times the
#: wheel-speed noise (0.05 m/s), so noise alone does not toggle the model, and a fifth of
#: the 2.5 m/s low-speed bands
HYSTERESIS_MPS = 0.5


def calibration_seeds(base_seed: int, exp: VehicleBandsParams) -> list[int]:
    """The held-out seeds: ``base_seed + calibration_seed_offset + i``."""
    first = base_seed + exp.calibration_seed_offset
    return [first + i for i in range(exp.calibration_seeds)]


def calibration_rows(
    drive: car.CarSpeedRampParams,
    filters: FiltersParams,
    seeds: Sequence[int],
    *,
    edges: tuple[float, ...] = CALIBRATION_EDGES_MPS,
    backend: Backend = "numba",
) -> list[dict[str, Any]]:
    """Per-seed band rows (subset ``all``) of the two single models on ``seeds``."""
    out = []
    for s in seeds:
        tables = car.synthesize(drive, s).tables
        for r in band_table(tables, filters, edges=edges, backend=backend, names=SINGLE):
            if r["subset"] == "all":
                out.append({"seed": s, **r})
    return out


def dynamic_vs_kinematic(
    rows: Sequence[Mapping[str, Any]], confidence: float, equivalence_rel: float
) -> list[dict[str, Any]]:
    """Per scenario and band: ``dynamic - kinematic`` with its interval and ``dynamic_ok``.

    Bands where either model has no sample in some seed are left out.
    """
    cell: dict[tuple[str, float, float, str], dict[int, float]] = {}
    for r in rows:
        if r["pos_h_rms_m"] is not None:
            key = (r["scenario"], r["band_lo_mps"], r["band_hi_mps"], r["filter"])
            cell.setdefault(key, {})[r["seed"]] = r["pos_h_rms_m"]
    seeds = sorted({r["seed"] for r in rows})
    out = []
    for scen, lo, hi in sorted({k[:3] for k in cell}):
        got = [cell.get((scen, lo, hi, f), {}) for f in SINGLE]
        if any(len(g) != len(seeds) for g in got):
            continue
        k_rms, d_rms = (np.array([g[s] for s in seeds]) for g in got)
        mean, low, high = mean_ci(d_rms - k_rms, confidence)
        margin = equivalence_rel * min(float(k_rms.mean()), float(d_rms.mean()))
        out.append(
            {"scenario": scen, "band_lo_mps": lo, "band_hi_mps": hi, "seeds": len(seeds),
             "kinematic_rms_mean_m": float(k_rms.mean()),
             "dynamic_rms_mean_m": float(d_rms.mean()),
             "dyn_minus_kin_mean_m": mean, "dyn_minus_kin_ci_low_m": low,
             "dyn_minus_kin_ci_high_m": high, "margin_m": margin,
             "dynamic_ok": high <= margin}
        )  # fmt: skip
    return out


def switch_speeds(
    table: Sequence[Mapping[str, Any]], hysteresis_mps: float = HYSTERESIS_MPS
) -> tuple[float, float]:
    """(speed_up_mps, speed_down_mps) of the rule in the module docstring.

    Raises:
        ValueError: when the dynamic model is worse in the highest band (no edge
            qualifies), or not worse in any band (no switching is needed: use
            ``vehicle_dynamic``), or the table is empty.
    """
    los = sorted({float(r["band_lo_mps"]) for r in table})
    if not los:
        raise ValueError("empty calibration table")
    bad = [float(r["band_lo_mps"]) for r in table if not r["dynamic_ok"]]
    if not bad:
        raise ValueError("the dynamic model is not worse in any band: no switching needed")
    above = [lo for lo in los if lo > max(bad)]
    if not above:
        raise ValueError(f"the dynamic model is worse in the highest band ({los[-1]:g} m/s)")
    up = above[0]
    return up, max(up - hysteresis_mps, 0.5 * up)


def note(table: Sequence[Mapping[str, Any]], up: float, down: float) -> str:
    """Markdown: the rule, the chosen speeds and the bands that decided them."""
    seeds = table[0]["seeds"] if table else 0
    lines = [
        f"**Switching speed of vehicle_switched, calibrated on {seeds} held-out noise "
        f"realizations** (`calibration.csv`; disjoint from the acceptance seeds). Per "
        f"scenario and band, the paired difference dynamic - kinematic of the horizontal "
        f"RMS; the dynamic model is not worse when its upper bound is within the acceptance "
        f"margin. Lowest edge above which it is not worse in every band of both scenarios: "
        f"**{up:g} m/s** (speed_up_mps); back to the kinematic model below **{down:g} m/s** "
        f"(speed_down_mps, the hysteresis).",
        "",
        "| scenario | band, m/s | dynamic - kinematic, mm [CI] | margin, mm | dynamic ok |",
        "|---|---|---|---|---|",
    ]
    for r in table:
        lines.append(
            f"| {r['scenario']} | {r['band_lo_mps']:g}-{r['band_hi_mps']:g} | "
            f"{1000 * r['dyn_minus_kin_mean_m']:+.1f} [{1000 * r['dyn_minus_kin_ci_low_m']:+.1f}, "
            f"{1000 * r['dyn_minus_kin_ci_high_m']:+.1f}] | {1000 * r['margin_m']:.1f} | "
            f"{'yes' if r['dynamic_ok'] else 'no'} |"
        )
    return "\n".join(lines) + "\n"
