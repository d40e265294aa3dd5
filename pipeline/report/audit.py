"""The data-quality audit section, from ``ingest_report.json`` and ``meta.json``.

Rows per table: rows, span, rate, median interval, jitter, longest interval, gaps (count,
total, longest), segment breaks, re-sorted, late-dropped and duplicate samples, backward
clock steps, NaN/inf counts; per file: format, completeness and defects (what was lost or
recovered, where); the time-base decisions, frame conversions, cross-stream alignment checks
and the ingest warnings. ``audit_rows`` also goes to ``tables/audit.csv``.
"""

from __future__ import annotations

from typing import Any

from navreplay.pipeline.report import html as h
from navreplay.pipeline.report.inputs import DatasetInputs

Row = dict[str, Any]


def _get(d: Any, *keys: str) -> Any:
    for k in keys:
        if not isinstance(d, dict):
            return None
        d = d.get(k)
    return d


def audit_rows(report: dict[str, Any] | None) -> list[Row]:
    """One row per canonical table of the ingest report."""
    if not report or not isinstance(report.get("tables"), dict):
        return []
    rows = []
    for name in sorted(report["tables"]):
        t = report["tables"][name]
        st, hy = _get(t, "stats") or {}, _get(t, "hygiene") or {}
        nonfinite = st.get("nonfinite") or {}
        nan = sum(int(v.get("nan", 0)) for v in nonfinite.values() if isinstance(v, dict))
        inf = sum(int(v.get("inf", 0)) for v in nonfinite.values() if isinstance(v, dict))
        rows.append(
            {
                "table": name,
                "stream": t.get("stream"),
                "rows": st.get("rows"),
                "duration_s": st.get("duration_s"),
                "rate_hz": st.get("rate_hz"),
                "median_dt_ms": st.get("median_dt_ms"),
                "jitter_ms": st.get("jitter_ms"),
                "max_dt_ms": st.get("max_dt_ms"),
                "gaps": _get(st, "gaps", "count"),
                "gaps_total_s": _get(st, "gaps", "total_s"),
                "gap_longest_s": _get(st, "gaps", "longest_s"),
                "segments": len(st.get("segments") or []),
                "reordered": hy.get("reordered"),
                "dropped_late": hy.get("dropped_late"),
                "duplicates": (hy.get("duplicates_exact_dropped") or 0)
                + (hy.get("duplicates_conflicting_dropped") or 0),
                "clock_steps": len(hy.get("clock_steps_backward") or []),
                "nan": nan,
                "inf": inf,
            }
        )
    return rows


COLUMNS = (
    ("table", "table"),
    ("stream", "stream"),
    ("rows", "rows"),
    ("duration_s", "span s"),
    ("rate_hz", "rate Hz"),
    ("median_dt_ms", "median dt ms"),
    ("jitter_ms", "jitter ms"),
    ("max_dt_ms", "max dt ms"),
    ("gaps", "gaps"),
    ("gaps_total_s", "gap total s"),
    ("gap_longest_s", "longest gap s"),
    ("segments", "segments"),
    ("reordered", "re-sorted"),
    ("dropped_late", "late dropped"),
    ("duplicates", "duplicates"),
    ("clock_steps", "clock steps"),
    ("nan", "NaN"),
    ("inf", "inf"),
)


def _flag(key: str) -> Any:
    return lambda r: "warn" if isinstance(r.get(key), int | float) and r[key] > 0 else ""


def _list(items: list[Any]) -> str:
    return "<ul>" + "".join(f"<li>{h.esc(i)}</li>" for i in items) + "</ul>" if items else ""


def audit_section(data: DatasetInputs) -> str:
    """The audit section's HTML; empty when the dataset has neither report nor meta."""
    report, meta = data.ingest_report, data.meta
    if report is None and meta is None:
        return ""
    parts = []
    rows = audit_rows(report)
    if rows:
        flags = {k: _flag(k) for k in ("gaps", "segments", "dropped_late", "duplicates", "nan")}
        flags["clock_steps"] = _flag("clock_steps")
        parts.append(h.table(rows, COLUMNS, cls=flags, table_id="audit-tables"))
    files = (report or {}).get("files") or []
    if files:
        frows = []
        for f in files:
            comp = ", ".join(f.get("completeness") or []) or "complete"
            defects = "; ".join(
                f"{d.get('kind', '?')}: {d.get('reason', '')}".strip()
                + (f" ({d['messages_lost']} lost)" if d.get("messages_lost") else "")
                for d in f.get("defects") or []
            )
            frows.append(
                {
                    "name": f.get("name"),
                    "format": f"{f.get('format')} {f.get('variant') or ''}".strip(),
                    "completeness": comp,
                    "defects": defects or "none",
                }
            )
        cols = (("name", "file"), ("format", "format"), ("completeness", "completeness"),
                ("defects", "defects"))  # fmt: skip
        ok = {"completeness": lambda r: "ok" if r["completeness"] == "complete" else "bad"}
        parts.append("<h3>Files</h3>" + h.table(frows, cols, cls=ok))
    tb = (report or {}).get("time_base") or {}
    base = tb.get("base") or (meta.time_base if meta else None)
    decisions = [str(d) for d in tb.get("decisions") or []]
    if base:
        parts.append(f"<h3>Time base</h3><p>t_ns counts on the <b>{h.esc(base)}</b> clock.</p>")
        parts.append(_list(decisions))
    checks = [*tb.get("checks", []), *tb.get("alignment", [])]
    if checks:
        parts.append("<h3>Cross-stream checks</h3>" + _list([_short(c) for c in checks]))
    conversions = list(meta.frame_conversions) if meta else []
    for name, t in sorted(((report or {}).get("tables") or {}).items()):
        conversions += [f"{name}: {c}" for c in t.get("frame_conversions") or []]
    if conversions:
        parts.append("<h3>Frame conversions</h3>" + _list(sorted(set(conversions))))
    warnings = [str(w) for w in (report or {}).get("warnings") or []]
    if warnings:
        parts.append('<h3>Warnings</h3><ul class="warnings">')
        parts.append("".join(f"<li>{h.esc(w)}</li>" for w in warnings) + "</ul>")
    return "".join(parts)


def _short(check: Any) -> str:
    if isinstance(check, dict):
        return ", ".join(f"{k}={v}" for k, v in sorted(check.items()))
    return str(check)


def warnings(data: DatasetInputs) -> list[str]:
    """The ingest warnings and damaged files, for the page's top and ``analyze``'s summary."""
    report = data.ingest_report or {}
    out = [str(w) for w in report.get("warnings") or []]
    for f in report.get("files") or []:
        comp = [c for c in f.get("completeness") or [] if c != "complete"]
        if comp:
            out.append(f"{f.get('name')}: {', '.join(comp)}")
    return out
