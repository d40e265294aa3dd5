"""The outage experiment tables of one dataset from its Monte Carlo windows.

Reads MONTECARLO_DIR/<filter>/windows.parquet for the filters of params.yaml `outages` and
writes into DIR (each file atomically):
  sat_reduction.csv / .json   per (baseline -> candidate) pair and satellite count: mean 3-D
                              error over the 60 s partial-outage windows of both filters and
                              the reduction in % with its 95 % paired bootstrap (BCa) interval;
                              CSV columns pair, sats, err_baseline_m, err_candidate_m,
                              reduction_pct, ci_low_pct, ci_high_pct
  drift_vs_length.csv / .json per filter and complete-outage length: error at the end (with
                              its interval), max, RMS, drift in % of distance, re-convergence
  sat_reduction_vs_paper.md   our tc_ukf -> tc_ukf_nhc row beside paper 001's Table 1, with
                              the measurements that explain the difference (JSON: in
                              sat_reduction.json under "paper_comparison")
Both tables are printed, the reduction beside the paper's values. A filter whose Monte Carlo
folder holds skipped.json (`navreplay montecarlo --skip-unfit`: the tables cannot drive it)
is left out, with the pairs that need it; the JSON says which and why.

examples:
  navreplay outages datasets/seoul_campus_cw/montecarlo --tables datasets/seoul_campus_cw/tables \\
      --out datasets/seoul_campus_cw/experiments
"""

from __future__ import annotations

import argparse
import json
import logging
from collections.abc import Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

from navreplay.pipeline.errors import PipelineError
from navreplay.pipeline.stages.options import add_dir, add_out, add_params

log = logging.getLogger(__name__)


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "montecarlo", type=Path, metavar="MONTECARLO_DIR", help="one folder per filter"
    )
    add_dir(parser, "--tables", "the dataset's tables (truth, meta.json)")
    add_params(parser, "parameters")
    add_out(parser, "output dir")


def run(args: argparse.Namespace) -> int:
    import pyarrow.parquet as pq

    from navreplay.ingest.atomic import atomic_write_json, atomic_write_text
    from navreplay.ingest.meta import read_meta
    from navreplay.ingest.typed import to_plain
    from navreplay.pipeline.outages import paper
    from navreplay.pipeline.outages.tables import (
        DRIFT_COLUMNS,
        SAT_REDUCTION_COLUMNS,
        csv_text,
        drift_text,
        drift_vs_length,
        reduction_text,
        sat_reduction,
    )
    from navreplay.pipeline.params import load_params

    params = load_params(args.params)
    o = params.outages
    windows, skipped = _read_windows(args.montecarlo, o.filters)
    # filters the tables could not drive, and the pairs that need them, are left out
    o = replace(
        o,
        filters=tuple(f for f in o.filters if f in windows),
        pairs=tuple(p for p in o.pairs if p[0] in windows and p[1] in windows),
    )
    reduction = sat_reduction(windows, o)
    drift = drift_vs_length(windows, o)
    truth, imu_noise, dataset = None, None, args.montecarlo.parent.name
    if args.tables is not None:
        meta = read_meta(args.tables)
        dataset = meta.dataset
        if meta.sensors is not None and meta.sensors.imu_noise is not None:
            imu_noise = to_plain(meta.sensors.imu_noise)
        if (args.tables / "truth.parquet").is_file():
            truth = pq.read_table(args.tables / "truth.parquet")
    nhc = params.filters.tc_ukf_nhc.nhc
    cmp = paper.compare(
        reduction,
        windows,
        o.sats_window_s,
        imu_noise=imu_noise,
        nhc_sigma_mps=(nhc.sigma_lateral_mps, nhc.sigma_vertical_mps) if nhc else None,
        truth=truth,
        nhc_rate_hz=nhc.rate_hz if nhc else None,
    )
    method = (
        "mean over windows of each window's mean 3-D position error (no re-alignment); "
        "reduction 100 (e_A - e_B) / e_A; interval: paired BCa bootstrap over windows "
        f"({o.resamples} resamples, {o.confidence:.0%}); ci_delta_pct: delta method"
    )
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out / "sat_reduction.csv", csv_text(reduction, SAT_REDUCTION_COLUMNS))
    atomic_write_json(
        out / "sat_reduction.json",
        {
            "dataset": dataset,
            "method": method,
            "outages": to_plain(o),
            "rows": reduction,
            "paper_comparison": cmp,
            "skipped": skipped,
        },
    )
    atomic_write_text(out / "drift_vs_length.csv", csv_text(drift, DRIFT_COLUMNS))
    atomic_write_json(out / "drift_vs_length.json", {"dataset": dataset, "rows": drift})
    note = paper.markdown(cmp, dataset) if reduction else _no_pairs_note(dataset, skipped)
    atomic_write_text(out / "sat_reduction_vs_paper.md", note)
    for name, reason in skipped.items():
        print(f"{dataset}: {name} skipped ({reason}); its pairs are left out")
    print(f"{dataset}: error reduction per satellite count ({method})")
    print(reduction_text(reduction))
    print(f"\n{dataset}: drift against complete-outage length")
    print(drift_text(drift))
    print(f"-> {out}")
    return 0


def _read_windows(
    montecarlo: Path, filters: Sequence[str]
) -> tuple[dict[str, Any], dict[str, str]]:
    """Each filter's ``windows.parquet`` by name, and the reasons of the skipped ones."""
    import pyarrow.parquet as pq

    from navreplay.pipeline.outages.montecarlo import SKIPPED

    windows: dict[str, Any] = {}
    skipped: dict[str, str] = {}
    for name in filters:
        path = montecarlo / name / "windows.parquet"
        skip = montecarlo / name / SKIPPED
        if skip.is_file():
            skipped[name] = str(json.loads(skip.read_text())["reason"])
        elif path.is_file():
            windows[name] = pq.read_table(path)
        else:
            raise PipelineError(f"{path}: missing; run `navreplay montecarlo ... --filter {name}`")
    return windows, skipped


def _no_pairs_note(dataset: str, skipped: Mapping[str, str]) -> str:
    lines = [
        f"# {dataset}: error reduction per satellite count against paper 001",
        "",
        "No pair of `outages.pairs` could run on this dataset:",
        "",
        *(f"- {name}: {reason}" for name, reason in skipped.items()),
        "",
        "The drift of the other filters against outage length is in drift_vs_length.csv.",
    ]
    return "\n".join(lines) + "\n"
