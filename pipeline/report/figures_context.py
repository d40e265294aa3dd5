"""The log's context on one time axis: what the receiver said, how high the vehicle was, and
where the filters rejected measurements, with the outage windows shaded on every panel.

Panels, each only when the log has its data:

- satellites used in the fix (``gnss.num_sats``) and the fix type (``gnss.fix_type``);
- the receiver's reported accuracies (``gnss.h_acc_m``, ``v_acc_m``);
- its dilutions of precision (``gnss.hdop``, ``vdop``; 99.99, a receiver's "unknown", is left
  out);
- height: the fixes', the onboard estimate's and each filter's nominal run, from the first fix;
- the onboard EKF's innovation test ratios (``estimator`` ``test_ratio_*``), 1 marked;
- gate rejections of each filter's nominal run, per stream, as ticks (``innovations.parquet``
  rows not accepted);
- the log's events (``events``: ``ingest.context``): the mode (named spans), armed spans,
  autopilot events and errors, and messages as ticks coloured by severity;
- vibration (``vibration``): levels of the first IMU (ArduPilot's 30 m/s^2 guide line, PX4's
  own metrics) with the clipping events of every IMU marked.

The outage windows are those of the first scenario that has any.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from navreplay.ingest.schema import ESTIMATOR_TEST_RATIOS
from navreplay.pipeline.report.inputs import DatasetInputs, Run, column, times_ns
from navreplay.pipeline.report.svg import (
    TRUTH_COLOUR,
    colour,
    decimate_minmax,
    figure_svg,
    fixed_layout,
    label_width_in,
    shade_windows,
    style,
)

POINTS = 600  # per line
DOP_UNKNOWN = 99.0  # receivers say 99.99 for "no solution"


def _has(values: np.ndarray) -> bool:
    return bool(np.isfinite(values).any())


def _windows_s(data: DatasetInputs, t0: int) -> list[tuple[float, float]]:
    for r in data.runs:
        if r.windows:
            return [((w.start_ns - t0) / 1e9, (w.end_ns - t0) / 1e9) for w in r.windows]
    return []


def _rejections(run: Run) -> dict[str, np.ndarray]:
    inn = run.innovations
    if inn is None or inn.num_rows == 0 or "accepted" not in inn.column_names:
        return {}
    accepted = np.asarray(inn.column("accepted").to_numpy(zero_copy_only=False), dtype=bool)
    streams = np.asarray(inn.column("stream").to_pylist(), dtype=object)
    t = times_ns(inn)
    return {str(s): t[(streams == s) & ~accepted] for s in sorted(set(streams[~accepted]))}


def context(data: DatasetInputs, key: str) -> str | None:
    """The context figure (see the module docstring); None when there is nothing to draw."""
    gnss = data.gnss if data.gnss is not None and data.gnss.num_rows else None
    nominal = [r for r in data.runs if r.scenario == "nominal" and r.ran]
    rejections = {r.filter: _rejections(r) for r in nominal}
    panels: list[str] = []
    if gnss is not None and (_has(column(gnss, "num_sats")) or _has(column(gnss, "fix_type"))):
        panels.append("sats")
    if gnss is not None and (_has(column(gnss, "h_acc_m")) or _has(column(gnss, "v_acc_m"))):
        panels.append("acc")
    if gnss is not None and (_has(column(gnss, "hdop")) or _has(column(gnss, "vdop"))):
        panels.append("dop")
    if gnss is not None or data.onboard is not None or nominal:
        panels.append("height")
    if data.onboard is not None and any(
        _has(column(data.onboard, c)) for c in ESTIMATOR_TEST_RATIOS
    ):
        panels.append("tests")
    if any(rejections.values()):
        panels.append("rejections")
    if data.events is not None and data.events.num_rows:
        panels.append("events")
    if data.vibration is not None and data.vibration.num_rows:
        panels.append("vibration")
    if len(panels) < 2:
        return None
    t0 = data.t0_ns()
    filters = data.filters()
    windows = _windows_s(data, t0)
    with style() as plt:
        fig, axes = plt.subplots(
            len(panels), 1, figsize=(9.0, 0.8 + 1.6 * len(panels)), sharex=True, squeeze=False
        )
        names = [*(_LANES if "events" in panels else ()),
                 *(filters if "rejections" in panels else ())]  # fmt: skip
        # category tick labels (lanes, filter names) are wider than numbers
        fixed_layout(fig, top=0.6, hgap=0.35, left=max(0.75, label_width_in(fig, names) + 0.45))
        for ax, panel in zip(axes[:, 0], panels, strict=True):
            shade_windows(ax, windows, "outage window" if panel == panels[0] else None)
            _draw(panel, ax, data, gnss, nominal, rejections, filters, t0)
            if ax.get_legend_handles_labels()[0]:  # a panel may have nothing labelled
                ax.legend(loc="upper right", ncols=4, fontsize=7.0)
        axes[-1, 0].set_xlabel("time since start, s")
        fig.suptitle(f"{data.dataset}: the log's context")
        return figure_svg(fig, key)


_SATS = (("num_sats", "satellites used", "#0072B2"),
         ("fix_type", "fix type (3: 3-D, 6: RTK fixed)", "#D55E00"))  # fmt: skip
_ACC = (("h_acc_m", "reported horizontal σ", "#0072B2"),
        ("v_acc_m", "reported vertical σ", "#009E73"))  # fmt: skip


def _draw(
    panel: str,
    ax: Any,
    data: DatasetInputs,
    gnss: Any,
    nominal: list[Run],
    rejections: dict[str, dict[str, np.ndarray]],
    filters: list[str],
    t0: int,
) -> None:
    if panel in ("sats", "acc", "dop"):
        _gnss_panel(panel, ax, gnss, t0)
    elif panel == "height":
        _height(ax, data, gnss, nominal, filters, t0)
    elif panel == "events":
        _events_panel(ax, data.events, t0)
    elif panel == "vibration":
        _vibration_panel(ax, data.vibration, t0)
    elif panel == "tests":
        _tests_panel(ax, data.onboard, t0)
    else:
        _rejections_panel(ax, rejections, filters, t0)


def _gnss_panel(panel: str, ax: Any, gnss: Any, t0: int) -> None:
    t = (times_ns(gnss) - t0) / 1e9
    if panel == "dop":
        for name, c in (("hdop", "#0072B2"), ("vdop", "#009E73")):
            v = column(gnss, name)
            ok = np.isfinite(v) & (v < DOP_UNKNOWN)
            if ok.any():
                ax.plot(*decimate_minmax(t[ok], v[ok], POINTS), color=c, label=name.upper())
        ax.set_ylabel("DOP")
        return
    step = panel == "sats"
    for name, label, c in _SATS if step else _ACC:
        v = column(gnss, name)
        if not _has(v):
            continue
        if step:
            ax.step(*decimate_minmax(t, v, POINTS), where="post", color=c, label=label)
        else:
            ax.plot(*decimate_minmax(t, v, POINTS), color=c, label=label)
    ax.set_ylabel("count / type" if step else "m")


def _tests_panel(ax: Any, ob: Any, t0: int) -> None:
    t = (times_ns(ob) - t0) / 1e9
    for i, name in enumerate(ESTIMATOR_TEST_RATIOS):
        v = column(ob, name)
        if _has(v):
            ok = np.isfinite(v)
            ax.plot(*decimate_minmax(t[ok], v[ok], POINTS), color=colour(i), lw=0.8,
                    label=name.removeprefix("test_ratio_"))  # fmt: skip
    ax.axhline(1.0, color="#b3261e", lw=0.8, ls="--", label="rejected above")
    ax.set_ylabel("onboard test ratio")


def _height(
    ax: Any, data: DatasetInputs, gnss: Any, nominal: list[Run], filters: list[str], t0: int
) -> None:
    base = None
    sources = [("GNSS fixes", gnss, TRUTH_COLOUR), ("onboard estimate", data.onboard, "#000000")]
    sources += [(r.filter, r.estimate, colour(filters.index(r.filter))) for r in nominal]
    for label, table, c in sources:
        if table is None or table.num_rows == 0:
            continue
        h = column(table, "alt_m")
        if not _has(h):
            continue
        base = float(h[np.isfinite(h)][0]) if base is None else base
        t = (times_ns(table) - t0) / 1e9
        ax.plot(*decimate_minmax(t, h - base, POINTS), color=c, label=label, lw=0.9)
    ax.set_ylabel("height from first, m")


def _rejections_panel(
    ax: Any, rejections: dict[str, dict[str, np.ndarray]], filters: list[str], t0: int
) -> None:
    names = sorted({s for by in rejections.values() for s in by})
    for i, f in enumerate(filters):
        for s, ts in rejections.get(f, {}).items():
            y = i + names.index(s) / max(len(names), 1) * 0.8
            shown = ts[:: max(1, ts.size // POINTS)]  # the label keeps the full count
            ax.plot((shown - t0) / 1e9, np.full(shown.size, y), "|", ms=6,
                    color=colour(filters.index(f)), label=f"{f}: {s} ({ts.size})")  # fmt: skip
    ax.set_yticks(range(len(filters)), filters)
    ax.set_ylabel("gate rejections")


_LANES = ("messages", "events, errors", "armed", "mode")
_SEVERITY_COLOURS = (("#b3261e", 3), ("#E69F00", 4), ("#7f7f7f", 7))  # up to error, warning, rest
#: ArduPilot: "vibration levels below 30 m/s/s are normally acceptable"
VIBE_GUIDE_MPS2 = 30.0


def _kind_times(events: Any, kind: str, t0: int) -> tuple[np.ndarray, list[str]]:
    kinds = np.asarray(events.column("kind").to_pylist(), dtype=object)
    pick = np.flatnonzero(kinds == kind)
    t = (times_ns(events)[pick] - t0) / 1e9
    texts = events.column("text").to_pylist()
    return t, [str(texts[i]) for i in pick]


def _events_panel(ax: Any, events: Any, t0: int) -> None:
    t_all = (times_ns(events) - t0) / 1e9
    t_end = float(max(t_all.max(), ax.get_xlim()[1]))
    t, modes = _kind_times(events, "mode", t0)
    span = max(t_end - float(t_all.min()), 1e-9)
    for i, (start, name) in enumerate(zip(t, modes, strict=True)):
        stop = t[i + 1] if i + 1 < len(t) else t_end
        ax.broken_barh([(start, stop - start)], (2.7, 0.6), color=colour(i % 8), alpha=0.35)
        if (stop - start) / span > 0.04:
            ax.text(start, 3.0, f" {name}", va="center", fontsize=6.5, clip_on=True)
    t, states = _kind_times(events, "arming", t0)
    for i, (start, state) in enumerate(zip(t, states, strict=True)):
        if state == "armed":
            stop = t[i + 1] if i + 1 < len(t) else t_end
            ax.broken_barh([(start, stop - start)], (1.7, 0.6), color="#009E73", alpha=0.6)
    for state, c in (("armed", "#009E73"), ("disarmed", "#000000")):
        at = t[[s == state for s in states]] if len(states) else t
        if at.size:  # the changes themselves (a log started armed shows only its disarm)
            ax.plot(at, np.full(at.size, 2.0), "|", ms=10, mew=1.5, color=c, label=state)
    for kind, c in (("event", "#0072B2"), ("error", "#b3261e")):
        t, _ = _kind_times(events, kind, t0)
        if t.size:
            ax.plot(t, np.full(t.size, 1.0), "|", ms=8, color=c, label=f"{kind}s ({t.size})")
    kinds = np.asarray(events.column("kind").to_pylist(), dtype=object)
    severity = column(events, "severity")
    t = (times_ns(events) - t0) / 1e9
    done = np.zeros(len(t), bool)
    for c, worst in _SEVERITY_COLOURS:
        pick = (kinds == "message") & ~done & ((severity <= worst) | (worst == 7))
        done |= pick
        if pick.any():
            label = {3: "messages: error or worse", 4: "warnings"}.get(worst, "messages")
            ax.plot(t[pick], np.zeros(int(pick.sum())), "|", ms=8, color=c,
                    label=f"{label} ({int(pick.sum())})")  # fmt: skip
    ax.set_yticks(range(len(_LANES)), _LANES)
    ax.set_ylim(-0.6, 3.6)


def _vibration_panel(ax: Any, vib: Any, t0: int) -> None:
    imu = column(vib, "imu")
    first = imu == np.nanmin(imu)
    t = (times_ns(vib) - t0) / 1e9
    drew_levels = False
    for i, name in enumerate(("vibe_x_mps2", "vibe_y_mps2", "vibe_z_mps2", "accel_vibe_mps2")):
        v = column(vib, name)
        ok = first & np.isfinite(v)
        if ok.any():
            label = name.removesuffix("_mps2").replace("_", " ") + " (IMU 0), m/s²"
            ax.plot(*decimate_minmax(t[ok], v[ok], POINTS), color=colour(i), lw=0.8, label=label)
            drew_levels |= name != "accel_vibe_mps2"
    if drew_levels:
        ax.axhline(VIBE_GUIDE_MPS2, color="#b3261e", lw=0.8, ls="--", label="30 m/s² (ArduPilot)")
    for i, name in enumerate(("dvel_vibe_mps", "dang_vibe_rad")):
        v = column(vib, name)
        ok = first & np.isfinite(v)
        if ok.any():
            unit = "m/s" if name.endswith("mps") else "rad"
            label = f"{'Δvelocity' if i == 0 else 'Δangle'} vibration (PX4), {unit}"
            ax.plot(*decimate_minmax(t[ok], v[ok], POINTS), color=colour(4 + i), lw=0.8,
                    label=label)  # fmt: skip
    clips = _clip_times(vib, imu, t)
    if clips.size:
        ax.plot(clips, np.zeros(clips.size), "x", ms=5, color="#b3261e",
                label=f"clipping ({clips.size} samples with new clips)")  # fmt: skip
    ax.set_ylabel("vibration")


def _clip_times(vib: Any, imu: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Times where some IMU's cumulative clipping count rose."""
    count = column(vib, "clip_count")
    out = []
    for k in np.unique(imu[np.isfinite(imu)]):
        pick = (imu == k) & np.isfinite(count)
        c, tt = count[pick], t[pick]
        rose = np.flatnonzero(np.diff(c) > 0) + 1
        out.append(tt[rose])
    return np.sort(np.concatenate(out)) if out else np.empty(0)
