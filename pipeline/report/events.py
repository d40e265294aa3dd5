"""The log's own account of the flight or drive (``events`` and ``vibration`` tables of
``ingest.context``) as report rows: what the vehicle said (messages with their severity), the
modes it flew or drove in, when it was armed, its events and errors, and how its IMUs shook.

Every text comes from the log and is untrusted: the page escapes it (``report.html.table``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from navreplay.ingest.context import severity_name
from navreplay.pipeline.report import html as h
from navreplay.pipeline.report.inputs import DatasetInputs, column, times_ns

Row = dict[str, Any]
#: rows the page shows; ``tables/events.csv`` holds them all
MAX_SHOWN = 200
COLUMNS = ("time_s", "kind", "severity", "text", "source")
VIBE_COLUMNS = ("imu", "samples", "vibe_max_mps2", "vibe_mean_mps2", "above_30_frac", "clips")


def event_rows(data: DatasetInputs) -> list[Row]:
    """One row per event, in time order, its time in s from the report's time origin."""
    ev = data.events
    if ev is None or not ev.num_rows:
        return []
    t = (times_ns(ev) - data.t0_ns()) / 1e9
    sev = ev.column("severity").to_pylist()
    kinds, texts, sources = (ev.column(c).to_pylist() for c in ("kind", "text", "source"))
    return [
        {
            "time_s": float(t[i]),
            "kind": kinds[i],
            "severity": severity_name(sev[i]) if sev[i] is not None else None,
            "text": texts[i],
            "source": sources[i],
        }
        for i in range(ev.num_rows)
    ]


def vibration_rows(data: DatasetInputs) -> list[Row]:
    """Per IMU with levels per axis (ArduPilot, MAVLink): the largest and mean level over the
    axes, the fraction of samples with an axis above 30 m/s^2 (ArduPilot's guide), and the
    clipping events counted over the log (the rise of the cumulative count)."""
    vib = data.vibration
    if vib is None or not vib.num_rows:
        return []
    imu = column(vib, "imu")
    levels = np.column_stack([column(vib, f"vibe_{a}_mps2") for a in "xyz"])
    clips = column(vib, "clip_count")
    rows = []
    for k in np.unique(imu):
        pick = imu == k
        lv = levels[pick]
        have = np.isfinite(lv).any(axis=1)
        c = clips[pick]
        c = c[np.isfinite(c)]
        if not have.any() and not c.size:
            continue
        worst = np.nanmax(lv[have], axis=1) if have.any() else np.empty(0)
        rows.append({
            "imu": int(k),
            "samples": int(have.sum()),
            "vibe_max_mps2": float(worst.max()) if worst.size else None,
            "vibe_mean_mps2": float(np.nanmean(lv[have])) if have.any() else None,
            "above_30_frac": float(np.mean(worst > 30.0)) if worst.size else None,
            "clips": float(c.max() - c.min()) if c.size else None,
        })  # fmt: skip
    return rows


def section(rows: list[Row], vibration: list[Row]) -> str:
    """The messages-and-events table (the first ``MAX_SHOWN`` rows, warnings and worse
    marked) and the vibration summary; empty when the log has neither."""
    if not rows and not vibration:
        return ""
    parts = []
    if rows:
        kinds: dict[str, int] = {}
        for r in rows:
            kinds[r["kind"]] = kinds.get(r["kind"], 0) + 1
        counts = ", ".join(f"{n} {k}" for k, n in sorted(kinds.items()))
        modes = [r["text"] for r in rows if r["kind"] == "mode"]
        lead = f"The log's own account: {counts}."
        if modes:
            lead += f" Modes: {' → '.join(modes[:12])}{' …' if len(modes) > 12 else ''}."
        shown = rows[:MAX_SHOWN]
        more = (
            f" The first {MAX_SHOWN} of {len(rows)} are shown; tables/events.csv holds all."
            if len(rows) > MAX_SHOWN
            else " tables/events.csv holds the same rows."
        )
        parts.append(h.para(lead + more + " Times are from the report's time origin.", "note"))
        cols = (("time_s", "time s"), ("kind", "kind"), ("severity", "severity"),
                ("text", "text"), ("source", "record"))  # fmt: skip
        parts.append(h.table(shown, cols, cls={"severity": _severity_class}))
    if vibration:
        parts.append("<h3>Vibration</h3>")
        vib_cols = (("imu", "IMU"), ("samples", "samples"), ("vibe_max_mps2", "max m/s²"),
                ("vibe_mean_mps2", "mean m/s²"), ("above_30_frac", "share > 30 m/s²"),
                ("clips", "clipping events"))  # fmt: skip
        parts.append(h.table(vibration, vib_cols))
        parts.append(
            h.para(
                "ArduPilot's guide: levels below 30 m/s² are normally acceptable; above 60 "
                "m/s² position and altitude hold nearly always suffer. Clipping (the "
                "accelerometer at its range) corrupts the IMU data every filter here "
                "integrates.",
                "note",
            )
        )
    return "".join(parts)


def summary(rows: list[Row], vibration: list[Row]) -> str | None:
    """The log's own account in one line, for a terminal: its modes, its errors and warnings
    (the first few named), and its worst vibration and clipping; None when it has none."""
    parts = []
    modes = [r["text"] for r in rows if r["kind"] == "mode"]
    if modes:
        parts.append("modes " + " > ".join(modes[:8]) + (" ..." if len(modes) > 8 else ""))
    bad = [r for r in rows if r["kind"] == "error" or r["severity"] in _BAD]
    warn = [r for r in rows if r["severity"] == "warning"]
    for what, found in (("error", bad), ("warning", warn)):
        if found:
            named = "; ".join(str(r["text"])[:60] for r in found[:3])
            more = ", ..." if len(found) > 3 else ""
            parts.append(f"{len(found)} {what}{'s' if len(found) > 1 else ''} ({named}{more})")
    levels = [r for r in vibration if r["vibe_max_mps2"] is not None]
    if levels:
        worst = max(levels, key=lambda r: r["vibe_max_mps2"])
        parts.append(f"vibration up to {worst['vibe_max_mps2']:.3g} m/s^2 (IMU {worst['imu']})")
    clips = sum(r["clips"] or 0 for r in vibration)
    if clips:
        parts.append(f"{clips:.0f} clipping events")
    return "; ".join(parts) if parts else None


_BAD = ("emergency", "alert", "critical", "error")


def _severity_class(row: Row) -> str:
    return (
        "bad"
        if row.get("severity") in ("emergency", "alert", "critical", "error")
        else ("warn" if row.get("severity") == "warning" else "")
    )
