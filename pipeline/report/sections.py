"""HTML of the report's table sections (figures come from ``figures``/``figures_outage``)."""

from __future__ import annotations

import re
from collections.abc import Sequence
from typing import Any

import numpy as np

from navreplay.pipeline.outages.stats import mean_interval
from navreplay.pipeline.report import html as h
from navreplay.pipeline.report import markdown
from navreplay.pipeline.report.experiments import CsvTable, Experiment
from navreplay.pipeline.report.inputs import SMOOTHED, DatasetInputs, Run
from navreplay.pipeline.report.tables import PAPER_PAIR, PAPER_REDUCTION_PCT

Row = dict[str, Any]
MAX_TABLE_ROWS = 40  # rows of an experiment's CSV shown on the page


def overview(data: DatasetInputs, rows: Sequence[Row]) -> str:
    """What the dataset holds, which runs exist (filter x scenario), what was skipped, why
    (the verdict, ``verdict_section``, comes before it)."""
    parts: list[str] = []
    meta = data.meta
    if meta is not None:
        tables = ", ".join(f"{k} ({v:,} rows)" for k, v in sorted(meta.tables.items()))
        parts.append(h.para(f"Tables: {tables}. Time base: {meta.time_base}."))
    truth = "the truth table" if data.truth is not None else (
        "the GNSS fixes (no truth: inside an outage window the withheld fixes are the truth; "
        "outside, the error is a residual)")  # fmt: skip
    if rows:
        parts.append(h.para(f"Errors are measured against {truth}."))
        filters, scenarios = data.filters(), data.scenarios()
        grid = []
        status = {(r["filter"], r["scenario"]): r for r in rows}
        for f in filters:
            g: Row = {"filter": f}
            for sc in scenarios:
                r = status.get((f, sc))
                g[sc] = None if r is None else r["status"]
            grid.append(g)
        cls = {sc: _status_cls(sc) for sc in scenarios}
        parts.append(h.table(grid, [("filter", "filter")] + [(s, s) for s in scenarios], cls=cls))
        skipped = [r for r in rows if r["status"] != "ok"]
        if skipped:
            items = "".join(
                f"<li><b>{h.esc(r['filter'])}</b> / {h.esc(r['scenario'])}: "
                f"{h.esc(r['status'])}: {h.esc(r.get('reason') or 'no reason given')}</li>"
                for r in skipped
            )
            parts.append(f"<h3>Not run, not finished or not consistent</h3><ul>{items}</ul>")
    else:
        parts.append(h.para("No filter runs for this dataset yet.", "note"))
    return "".join(parts)


def verdict(rows: Sequence[Row]) -> str:
    """The report's first words on its runs: how many are ``ok``, and what the others are."""
    counts: dict[str, int] = {}
    for r in rows:
        counts[str(r["status"])] = counts.get(str(r["status"]), 0) + 1
    ok = counts.pop("ok", 0)
    if not counts:
        return h.para(f"All {ok} runs ended ok.", "verdict ok")
    others = ", ".join(f"{n} {status.replace('_', ' ')}" for status, n in sorted(counts.items()))
    head = "No run ended ok" if ok == 0 else f"{ok} of {len(rows)} runs ended ok"
    why = " (the reasons are listed below"
    if "inconsistent" in counts:
        why += (
            "; an inconsistent run finished, but its innovations are larger than its "
            "covariance says"
        )
    return h.para(f"{head}: {others}{why}).", "verdict bad" if ok == 0 else "verdict warn")


def best_rows(windows: Sequence[Row], status: dict[tuple[str, str], str]) -> list[Row]:
    """Which filter held best in each outage condition (satellites kept, window length): the
    lowest mean error at the windows' ends, with its 95 % interval (BCa bootstrap over the
    windows), and the runner-up. Only runs that finished (ok or inconsistent) compete, and
    only the filters: a smoothed run (``inputs.SMOOTHED``) knew the fixes after each window."""
    groups: dict[tuple[int, float], dict[str, list[float]]] = {}
    refs: dict[tuple[int, float], set[str]] = {}
    for w in windows:
        if w.get("err_end_m") is None or status.get((w["filter"], w["scenario"])) not in (
            "ok", "inconsistent"):  # fmt: skip
            continue
        if w.get("sats") is None and not str(w["scenario"]).startswith("outage"):
            continue
        if str(w["filter"]).endswith(SMOOTHED):
            continue
        key = (int(w.get("sats") or 0), round(float(w["duration_s"]), 1))
        groups.setdefault(key, {}).setdefault(str(w["filter"]), []).append(float(w["err_end_m"]))
        refs.setdefault(key, set()).add(str(w.get("reference") or ""))
    rows = []
    for (sats, length), per_filter in sorted(groups.items()):
        ranked = sorted(
            ((mean_interval(np.asarray(e, dtype=np.float64)), f, len(e))
             for f, e in per_filter.items()),
            key=lambda item: (item[0].estimate, item[1]),
        )  # fmt: skip
        (best, name, n), rest = ranked[0], ranked[1:]
        rows.append({
            "condition": "complete outage" if sats == 0 else f"{sats} satellites",
            "length_s": length,
            "windows": n,
            "best": name,
            "mean_m": best.estimate,
            "ci_low_m": best.low,
            "ci_high_m": best.high,
            "next": rest[0][1] if rest else None,
            "next_mean_m": rest[0][0].estimate if rest else None,
            "filters": len(ranked),
            "against": ", ".join(sorted(r for r in refs[(sats, length)] if r)),
        })  # fmt: skip
    return rows


def verdict_section(
    data: DatasetInputs, rows: Sequence[Row], windows: Sequence[Row], warnings: Sequence[str]
) -> str:
    """The page's first screen: the runs' statuses, the data-quality verdict, which filter
    held best for each outage length and satellite count, and the warnings."""
    parts = [verdict(rows)] if rows else [h.para("No filter runs for this dataset yet.", "note")]
    if warnings:
        items = "".join(f"<li>{h.esc(w)}</li>" for w in warnings[:8])
        more = f"<li>... and {len(warnings) - 8} more</li>" if len(warnings) > 8 else ""
        parts.append(
            h.para(f"Data quality: {len(warnings)} warning(s) from the ingest audit.", "warn")
            + f'<ul class="warnings">{items}{more}</ul>'
        )
    elif data.ingest_report is not None:
        parts.append(h.para("Data quality: the ingest audit raised no warning.", "ok"))
    status = {(str(r["filter"]), str(r["scenario"])): str(r["status"]) for r in rows}
    best = best_rows(windows, status)
    if best:
        cols = (("condition", "condition"), ("length_s", "length s"), ("best", "held best"),
                ("mean_m", "mean error at end m"), ("ci_low_m", "95 % low"),
                ("ci_high_m", "95 % high"), ("windows", "windows"), ("next", "next best"),
                ("next_mean_m", "its mean m"), ("filters", "filters compared"),
                ("against", "measured against"))  # fmt: skip
        parts.append("<h3>Which filter held best</h3>" + h.table(best, cols))
    trouble = [r for r in rows if r["status"] not in ("ok", "skipped")]
    if trouble:
        items = "".join(
            f"<li><b>{h.esc(r['filter'])}</b> / {h.esc(r['scenario'])}: "
            f"{h.esc(str(r['status']).replace('_', ' '))}: "
            f"{h.esc(r.get('reason') or 'no reason given')}</li>"
            for r in trouble[:12]
        )
        more = f"<li>... and {len(trouble) - 12} more (Overview)</li>" if len(trouble) > 12 else ""
        parts.append(f'<ul class="warnings">{items}{more}</ul>')
    return "".join(parts)


def _status_cls(key: str) -> Any:
    return lambda r: {"ok": "ok", "inconsistent": "warn", None: ""}.get(r.get(key), "bad")


_METRIC_COLS = (
    ("filter", "filter"),
    ("scenario", "scenario"),
    ("status", "status"),
    ("reference", "against"),
    ("pos_err_h_rms_m", "horiz. RMS m"),
    ("pos_err_3d_rms_m", "3-D RMS m"),
    ("pos_err_3d_max_m", "3-D max m"),
    ("vel_err_3d_rms_mps", "vel RMS m/s"),
    ("nees_mean", "NEES mean"),
    ("nees_dof", "NEES dof"),
    ("gate_rejections", "gate rejections"),
    ("gate_resets", "gate resets"),
)


def metrics(rows: Sequence[Row]) -> str:
    if not rows:
        return ""
    return h.table(rows, _METRIC_COLS, cls={"status": _status_cls("status")}) + h.para(
        "RMS and max over the whole run; NEES over position, velocity and attitude "
        "(its expected value is the dof). The full list is in tables/runs.csv.",
        "note",
    )


def noise_rows(runs: Sequence[Run]) -> list[Row]:
    """Per filter, the noise models its runs used (``metrics.json`` ``imu_noise`` and
    ``fix_noise``; the first run of each filter, they are the same under every scenario that
    keeps the log's fixes)."""
    rows: list[Row] = []
    seen: set[str] = set()
    for r in runs:
        imu, fix = r.metrics.get("imu_noise") or {}, r.metrics.get("fix_noise") or {}
        obs = r.metrics.get("obs_noise") or {}
        if r.filter in seen or not (imu or fix):
            continue
        seen.add(r.filter)
        rows.append({
            "filter": r.filter,
            "imu_source": imu.get("source"),
            "gyro": imu.get("gyro_noise_radps_rthz"),
            "accel": imu.get("accel_noise_mps2_rthz"),
            "tau": fix.get("tau_s"),
            "inflation": fix.get("inflation"),
            "states": fix.get("states_sigma_m") if fix.get("states") else None,
            "fix_source": fix.get("source"),
            "sigma_source": fix.get("sigma_source"),
            "sigma_h": fix.get("sigma_h_m"),
            "reported_h": fix.get("reported_h_m"),
            "why": fix.get("reason"),
            "latency": fix.get("latency_s"),
            "pr": obs.get("pseudorange_sigma_m"),
            "pr_source": obs.get("source"),
        })  # fmt: skip
    return rows


def noise(runs: Sequence[Run]) -> str:
    """What noise each filter assumed, and where it came from (issue: say what was used and
    why)."""
    rows = noise_rows(runs)
    if not rows:
        return ""
    cols = (("filter", "filter"), ("imu_source", "IMU noise from"), ("gyro", "gyro rad/s/√Hz"),
            ("accel", "accel m/s²/√Hz"), ("fix_source", "fix errors"), ("tau", "corr. time s"),
            ("inflation", "variance x"), ("states", "error states σ m"),
            ("sigma_source", "fix σ from"),
            ("sigma_h", "learned σ_h m"), ("reported_h", "reported σ_h m"),
            ("why", "why"), ("latency", "fix latency s"), ("pr_source", "pseudorange σ from"),
            ("pr", "learned pseudorange σ m"))  # fmt: skip
    return h.table(rows, cols) + h.para(
        "IMU noise: the dataset's declared model, else params.yaml's fallback floored by the "
        "noise the log's own samples show. Fix errors: their correlation time learned from the "
        "fixes against the receiver velocity (a Gauss-Markov error's structure function), "
        "else filters.<name>.gnss.pos_error_corr_time_s. A loosely coupled filter with "
        "gnss.fix_error_states carries the horizontal ones as two Gauss-Markov states (error "
        "states σ: their 1-sigma) where the correlation spans three fix intervals or more; "
        "otherwise a fix's variance is multiplied by the inflation for it. The fix σ is the "
        "receiver's reported accuracy where it gives "
        "one, else the learned one, else the default. Tight coupling fuses pseudoranges and "
        "has no fix-error model; their σ is the table's where given, else learned from the "
        "log's single-point residuals.",
        "note",
    )


def windows(rows: Sequence[Row]) -> str:
    if not rows:
        return ""
    cols = (("filter", "filter"), ("scenario", "scenario"), ("window", "#"),
            ("start_s", "start s"), ("duration_s", "length s"), ("sats", "sats"),
            ("err_end_m", "err at end m"), ("err_max_m", "max m"), ("err_mean_m", "mean m"),
            ("err_rms_m", "RMS m"), ("drift_pct_distance", "drift % dist."),
            ("reconverge_s", "reconverge s"), ("inside_3sigma_frac", "inside 3σ"))  # fmt: skip
    return h.table(rows, cols) + h.para(
        "3-D error inside each window against the reference, with no re-alignment at the "
        "window's start; drift is the error at the end over the distance travelled in it.",
        "note",
    )


def onboard(
    rows: Sequence[Row], ratios: Sequence[Row] = (), innovations: Sequence[Row] = ()
) -> str:
    """The replayed runs against the vehicle's own estimate (``report.onboard``), and the
    onboard EKF's own innovation test ratios and innovations."""
    if not rows and not ratios and not innovations:
        return ""
    run_cols = (("filter", "filter"), ("scenario", "scenario"), ("samples", "samples"),
                ("pos_h_rms_m", "horiz. RMS m"), ("pos_h_max_m", "horiz. max m"),
                ("pos_v_rms_m", "vert. RMS m"), ("vel_3d_rms_mps", "vel RMS m/s"),
                ("roll_rms_deg", "roll RMS °"), ("pitch_rms_deg", "pitch RMS °"),
                ("yaw_rms_deg", "yaw RMS °"))  # fmt: skip
    win_cols = (("filter", "filter"), ("scenario", "scenario"), ("window", "#"),
                ("start_s", "start s"), ("duration_s", "length s"),
                ("pos_3d_end_m", "3-D at end m"), ("pos_h_end_m", "horiz. at end m"),
                ("pos_3d_max_m", "3-D max m"), ("pos_3d_mean_m", "3-D mean m"),
                ("distance_m", "distance m"),
                ("drift_pct_distance", "drift % dist."))  # fmt: skip
    whole = [r for r in rows if r["scope"] == "run"]
    wins = [r for r in rows if r["scope"] == "window"]
    parts = [
        h.para(
            "The vehicle's own estimate (the log's onboard EKF) is the reference here, not "
            "truth: it fused the same fixes with its own model, so outside outages these are "
            "differences between two estimates. It kept GNSS through the injected outages, so "
            "inside a window the difference is the replayed filter's drift against an "
            "estimate that kept GNSS.",
            "note",
        ),
        h.table(whole, run_cols),
    ]
    if wins:
        parts.append("<h3>Drift against the onboard estimate in the outage windows</h3>")
        parts.append(h.table(wins, win_cols))
        parts.append(
            h.para(
                "Onboard minus replayed at the onboard samples inside each window; drift in % "
                "of the distance the onboard track travelled, where that is over 50 m. "
                "tables/onboard_comparison.csv holds every row.",
                "note",
            )
        )
    ratio_cols = (("measurement", "measurement"), ("samples", "samples"), ("mean", "mean"),
                  ("max", "max"), ("above_1_frac", "fraction above 1"))  # fmt: skip
    parts.append(_titled_table(
        "The onboard EKF's innovation test ratios", ratios, ratio_cols,
        "As the log recorded them (ArduPilot XKF4/NKF4/EKF4: the square root of the ratio; PX4 "
        "estimator_status: the ratio). Above 1 the onboard EKF rejected that measurement.",
    ))  # fmt: skip
    inn_cols = (("component", "innovation"), ("samples", "samples"), ("mean", "mean"),
                ("std", "std"), ("rms", "RMS"), ("max_abs", "max |x|"))  # fmt: skip
    parts.append(_titled_table(
        "The onboard EKF's innovations", innovations, inn_cols,
        "Prediction minus measurement as the log recorded them (ArduPilot XKF3/NKF3/EKF3, PX4 "
        "estimator_innovations), m/s and m; the vertical position is the EKF's height source, "
        "usually the barometer. A mean far from zero against the spread is a bias between the "
        "EKF and that sensor.",
    ))  # fmt: skip
    return "".join(parts)


def _titled_table(
    title: str, rows: Sequence[Row], cols: Sequence[tuple[str, str]], note: str
) -> str:
    """``<h3>title</h3>``, the table and its note; nothing without rows."""
    if not rows:
        return ""
    return f"<h3>{title}</h3>" + h.table(rows, cols) + h.para(note, "note")


def _pair(text: str) -> tuple[str, ...]:
    """``"tc_ukf -> tc_ukf_nhc"`` (any separator) as its filter names."""
    return tuple(re.findall(r"[A-Za-z0-9_]+", text))


def paper_pct(pair: str, sats: str) -> str:
    """Paper 001's Table 1 value for a row of a reduction table (its pair only), else ""."""
    if _pair(pair) != PAPER_PAIR or not sats.strip().isdigit():
        return ""
    return str(PAPER_REDUCTION_PCT.get(int(sats), ""))


def sat_reduction(table: CsvTable | None, note_md: str | None) -> str:
    """Paper 001 Table 1 as the outages stage computed it, beside the paper's values.

    A ``paper %`` column joins the paper's numbers (its pair, ``PAPER_PAIR``, by ``sats``);
    ``note_md`` is the stage's explanation of the differences (Markdown).
    """
    if table is None:
        return ""
    i_pair, i_sats = table.header.index("pair"), table.header.index("sats")
    rows = [(*r, paper_pct(r[i_pair], r[i_sats])) for r in table.rows]
    src = f"{table.path.parent.name}/{table.path.name}"
    parts = [
        h.text_table((*table.header, "paper %"), rows),
        h.para(
            "Reduction = 100 (e_A - e_B) / e_A, e the mean 3-D error over the outage windows "
            f"with k satellites, with its 95 % interval (from the outages stage's {src}). "
            f"Paper 001, Table 1 gives {' -> '.join(PAPER_PAIR)} only.",
            "note",
        ),
    ]
    if note_md:
        parts.append(f'<div class="md">{markdown.to_html(note_md)}</div>')
    return "".join(parts)


def drift(rows: Sequence[Row], table: CsvTable | None) -> str:
    """Drift against outage length: the outages stage's table when there is one, else the
    complete outages of the runs grouped by length (``tables.drift_by_length``)."""
    if table is not None:
        src = f"{table.path.parent.name}/{table.path.name}"
        return h.text_table(table.header, table.rows[:MAX_TABLE_ROWS]) + h.para(
            f"From the outages stage's {src}.", "note"
        )
    if not rows:
        return ""
    cols = (("filter", "filter"), ("outage_s", "outage s"), ("windows", "windows"),
            ("err_end_mean_m", "mean err at end m"), ("ci_low_m", "95 % low"),
            ("ci_high_m", "95 % high"))  # fmt: skip
    return h.table(rows, cols)


def nis(rows: Sequence[Row]) -> str:
    if not rows:
        return ""
    cols = (("filter", "filter"), ("scenario", "scenario"), ("stream", "stream"),
            ("count", "updates"), ("nis_mean", "mean NIS"), ("dof_mean", "mean dof"),
            ("bound_low", "95 % low"), ("bound_high", "95 % high"),
            ("consistent", "within"), ("rejected", "gated out"))  # fmt: skip
    cls = {"consistent": lambda r: {True: "ok", False: "warn"}.get(r.get("consistent"), "")}
    return h.table(rows, cols, cls=cls) + h.para(
        "Bounds: two-sided 95 % chi-square interval of the time-averaged NIS over the run's "
        "updates (its expected value is the mean dof).",
        "note",
    )


def cost(rows: Sequence[Row]) -> str:
    rows = [r for r in rows if r.get("runtime_s") is not None]
    if not rows:
        return ""
    cols: tuple[tuple[str, str], ...] = (("filter", "filter"), ("scenario", "scenario"),
            ("epochs", "output epochs"), ("duration_s", "data s"), ("runtime_s", "wall s"),
            ("realtime_factor", "x real time"))  # fmt: skip
    if any(r.get("compile_s") is not None for r in rows):
        cols = (*cols, ("compile_s", "of which JIT s"))
    return h.table(rows, cols) + h.para(
        "Wall time of the replay (inputs, alignment, filter) on one core; a run that found no "
        "compiled kernel in the numba cache includes the compilation.",
        "note",
    )


def provenance(p: dict[str, Any]) -> str:
    rows = [
        {"item": "package version", "value": p["package_version"]},
        {"item": "git commit", "value": p["git_commit"] or "not a git checkout"},
        {"item": "params hash (params.yaml)", "value": p["params_hash"] or "n/a"},
        {"item": "time base", "value": p["time_base"] or "n/a"},
    ]
    rows += [
        {"item": f"input {s['name']} ({s['format']})", "value": f"sha256 {s['sha256']}"}
        for s in p["sources"]
    ]
    rows += [
        {"item": f"run {r['filter']} / {r['scenario']}",
         "value": f"params {r['params_hash'] or 'n/a'}, backend {r['backend'] or 'n/a'}"}
        for r in p["runs"]
    ]  # fmt: skip
    return h.table(rows, (("item", "item"), ("value", "value")))


_VERDICT_CLS = {"agrees": "ok", "differs": "bad", "partly": "warn"}


def experiments(exps: Sequence[Experiment], figs: list[str]) -> str:
    """Each experiment directory as a sub-section (``pipeline.report.experiments``)."""
    parts = []
    for e in exps:
        parts.append(f'<h3 id="exp-{h.esc(e.name)}">{h.esc(e.title)}</h3>')
        parts += [h.para(p) for p in e.summary]
        parts += [f'<div class="md">{markdown.to_html(n)}</div>' for n in e.notes]
        if e.claims:
            parts.append(
                h.table(
                    e.claims,
                    (
                        ("claim", "claim"),
                        ("paper", "paper"),
                        ("ours", "ours"),
                        ("verdict", "verdict"),
                    ),
                    cls={"verdict": lambda r: _VERDICT_CLS.get(r["verdict"], "")},
                )
            )
        for t in e.tables:
            parts.append(f"<h4>{h.esc(t.title)}</h4>")
            parts.append(h.text_table(t.header, t.rows[:MAX_TABLE_ROWS]))
            if len(t.rows) > MAX_TABLE_ROWS:
                where = f"tables/experiments/{e.name}/{t.path.name}"
                note = f"First {MAX_TABLE_ROWS} of {len(t.rows)} rows; all in {where}."
                parts.append(h.para(note, "note"))
            if t.caption:
                parts.append(h.para(t.caption, "note"))
        for i, f in enumerate(e.figures):
            svg = f.svg
            if svg is not None:
                from navreplay.pipeline.report.svg import compact, prefix_ids

                svg = prefix_ids(compact(svg), f"exp-{e.name}-{i}")
                figs.append(svg)
            parts.append(h.figure(svg, f.caption or f.title, png_uri=f.png_data_uri))
            if svg is None:
                figs.append(f.png_data_uri or "")
    return "".join(parts)
