"""The Monte Carlo windows reduced to the experiment tables.

- ``sat_reduction``: per (baseline -> candidate) pair and satellite count k, the mean 3-D
  position error over the partial-outage windows of both filters (the window mean of the error
  at every instant, measured without re-alignment) and the reduction
  ``100 (e_A - e_B) / e_A`` with its paired interval (``stats``); paper 001's Table 1 beside.
- ``drift_vs_length``: per filter and complete-outage length, the error at the outage's end
  (mean and interval), its maximum and RMS, drift in % of the distance travelled, and the
  re-convergence time.

Rows are plain dicts; ``SAT_REDUCTION_COLUMNS`` is the CSV contract the report stage reads.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import pyarrow as pa

from navreplay.pipeline.estimation.core.integrity import FINISHED
from navreplay.pipeline.nav.earth import F64
from navreplay.pipeline.outages.config import OutagesParams
from navreplay.pipeline.outages.stats import delta_reduction, mean_interval, paired_reduction

SAT_REDUCTION_COLUMNS = (
    "pair",
    "sats",
    "err_baseline_m",
    "err_candidate_m",
    "reduction_pct",
    "ci_low_pct",
    "ci_high_pct",
)
DRIFT_COLUMNS = (
    "filter",
    "length_s",
    "windows",
    "err_end_m",
    "err_end_ci_low_m",
    "err_end_ci_high_m",
    "err_max_m",
    "err_rms_m",
    "drift_pct_distance",
    "drift_ci_low_pct",
    "drift_ci_high_pct",
    "reconverge_s_median",
    "reconverged_frac",
)

#: Paper 001 (Chan et al.), Table 1: average error reduction in % for 0..4 satellites, 60 s
#: outages, UKF with the non-holonomic constraint over the UKF without it.
PAPER_001_TABLE1 = {0: 54.4, 1: 53.2, 2: 52.6, 3: 52.4, 4: 22.6}
PAPER_001_PAIR = ("tc_ukf", "tc_ukf_nhc")


def _select(rows: pa.Table, length_s: float, sats: int) -> dict[tuple[int, int], dict[str, Any]]:
    """(seed, window) -> row, for the rows of one case."""
    out = {}
    for r in rows.to_pylist():
        if math.isclose(r["length_s"], length_s) and r["sats"] == sats:
            out[(r["seed"], r["window"])] = r
    return out


def _paired(
    base: Mapping[tuple[int, int], dict[str, Any]],
    cand: Mapping[tuple[int, int], dict[str, Any]],
    key: str,
) -> tuple[F64, F64]:
    """The values of ``key`` on the windows both filters ran without diverging."""
    keys = sorted(
        k
        for k in set(base) & set(cand)
        if base[k]["status"] in FINISHED
        and cand[k]["status"] in FINISHED
        and base[k][key] is not None
        and cand[k][key] is not None
    )
    return (
        np.array([base[k][key] for k in keys], dtype=np.float64),
        np.array([cand[k][key] for k in keys], dtype=np.float64),
    )


def sat_reduction(windows: Mapping[str, pa.Table], params: OutagesParams) -> list[dict[str, Any]]:
    """The reduction table (see the module docstring), one row per pair and k."""
    out = []
    for i, (a, b) in enumerate(params.pairs):
        for k in params.sats:
            base = _select(windows[a], params.sats_window_s, k)
            cand = _select(windows[b], params.sats_window_s, k)
            ea, eb = _paired(base, cand, "err_mean_m")
            boot = paired_reduction(ea, eb, params.confidence, params.resamples, seed=1000 * i + k)
            delta = delta_reduction(ea, eb, params.confidence)
            paper = PAPER_001_TABLE1.get(k) if (a, b) == PAPER_001_PAIR else None
            elev = [r["kept_elevation_mean_deg"] for r in base.values() if r["kept_svs"]]
            gdops = [r["kept_gdop"] for r in base.values() if r["kept_gdop"] is not None]
            out.append(
                {
                    "pair": f"{a}->{b}",
                    "baseline": a,
                    "candidate": b,
                    "sats": k,
                    "windows": int(ea.size),
                    "err_baseline_m": float(ea.mean()) if ea.size else None,
                    "err_candidate_m": float(eb.mean()) if eb.size else None,
                    "reduction_pct": _num(boot.estimate),
                    "ci_low_pct": _num(boot.low),
                    "ci_high_pct": _num(boot.high),
                    "ci_delta_pct": delta.json(),
                    "err_end_baseline_m": _mean_of(base, "err_end_m"),
                    "err_end_candidate_m": _mean_of(cand, "err_end_m"),
                    "kept_elevation_mean_deg": float(np.mean(elev)) if elev else None,
                    "kept_gdop_mean": float(np.mean(gdops)) if gdops else None,
                    "paper_reduction_pct": paper,
                    "paper_inside_ci": (
                        None
                        if paper is None or not math.isfinite(boot.low)
                        else bool(boot.low <= paper <= boot.high)
                    ),
                }
            )
    return out


def _num(x: float) -> float | None:
    return x if math.isfinite(x) else None


def _mean_of(rows: Mapping[Any, dict[str, Any]], key: str) -> float | None:
    v = [r[key] for r in rows.values() if r[key] is not None and r["status"] in FINISHED]
    return float(np.mean(v)) if v else None


def drift_vs_length(windows: Mapping[str, pa.Table], params: OutagesParams) -> list[dict[str, Any]]:
    """The drift table (see the module docstring), one row per filter and length."""
    out = []
    for i, name in enumerate(params.filters):
        for j, length in enumerate(params.lengths_s):
            rows = [
                r for r in _select(windows[name], length, 0).values() if r["status"] in FINISHED
            ]

            def col(key: str, rows: list[dict[str, Any]] = rows) -> F64:
                return np.array([r[key] for r in rows if r[key] is not None], dtype=np.float64)

            seed = 100 * i + j
            end = mean_interval(col("err_end_m"), params.confidence, params.resamples, seed)
            drift = mean_interval(
                col("drift_pct_distance"), params.confidence, params.resamples, seed
            )
            rec = col("reconverge_s")
            out.append(
                {
                    "filter": name,
                    "length_s": length,
                    "windows": len(rows),
                    "err_end_m": _num(end.estimate),
                    "err_end_ci_low_m": _num(end.low),
                    "err_end_ci_high_m": _num(end.high),
                    "err_max_m": _num(float(np.mean(col("err_max_m")))) if rows else None,
                    "err_rms_m": _num(float(np.mean(col("err_rms_m")))) if rows else None,
                    "drift_pct_distance": _num(drift.estimate),
                    "drift_ci_low_pct": _num(drift.low),
                    "drift_ci_high_pct": _num(drift.high),
                    "reconverge_s_median": float(np.median(rec)) if rec.size else None,
                    "reconverged_frac": rec.size / len(rows) if rows else None,
                }
            )
    return out


def csv_text(rows: Sequence[Mapping[str, Any]], columns: Sequence[str]) -> str:
    """Rows as CSV text with the given columns (empty cell for None, 6 significant digits)."""

    def cell(v: Any) -> str:
        if v is None:
            return ""
        if isinstance(v, float):
            return f"{v:.6g}"
        return str(v)

    lines = [",".join(columns)]
    lines += [",".join(cell(r[c]) for c in columns) for r in rows]
    return "\n".join(lines) + "\n"


def _fmt(v: float | None, spec: str = ".1f") -> str:
    return "n/a" if v is None else format(v, spec)


def reduction_text(rows: Sequence[Mapping[str, Any]]) -> str:
    """The reduction table beside the paper's values, as fixed-width text."""
    head = (
        f"{'pair':<24} {'k':>2} {'n':>4} {'e_A m':>7} {'e_B m':>7} {'reduction %':>12} "
        f"{'95% CI':>16} {'paper %':>8}"
    )
    lines = [head]
    for r in rows:
        ci = f"[{_fmt(r['ci_low_pct'])}, {_fmt(r['ci_high_pct'])}]"
        paper = _fmt(r["paper_reduction_pct"]) if r["paper_reduction_pct"] is not None else "-"
        e_a, e_b = _fmt(r["err_baseline_m"], ".2f"), _fmt(r["err_candidate_m"], ".2f")
        lines.append(
            f"{r['pair']:<24} {r['sats']:>2} {r['windows']:>4} {e_a:>7} {e_b:>7} "
            f"{_fmt(r['reduction_pct']):>12} {ci:>16} {paper:>8}"
        )
    lines.append(
        "paper 001, Table 1 (54.4, 53.2, 52.6, 52.4, 22.6 % for 0..4 satellites, 60 s outages) "
        "compares the UKF with and without NHC: it stands beside tc_ukf->tc_ukf_nhc only."
    )
    return "\n".join(lines)


def drift_text(rows: Sequence[Mapping[str, Any]]) -> str:
    """The drift-vs-length table as fixed-width text."""
    lines = [
        f"{'filter':<12} {'length s':>8} {'n':>4} {'err end m':>10} {'95% CI':>16} "
        f"{'max m':>7} {'drift %':>8} {'reconv s':>9}"
    ]
    for r in rows:
        ci = f"[{_fmt(r['err_end_ci_low_m'], '.2f')}, {_fmt(r['err_end_ci_high_m'], '.2f')}]"
        lines.append(
            f"{r['filter']:<12} {r['length_s']:>8.0f} {r['windows']:>4} "
            f"{_fmt(r['err_end_m'], '.2f'):>10} {ci:>16} {_fmt(r['err_max_m'], '.2f'):>7} "
            f"{_fmt(r['drift_pct_distance'], '.2f'):>8} {_fmt(r['reconverge_s_median']):>9}"
        )
    return "\n".join(lines)
