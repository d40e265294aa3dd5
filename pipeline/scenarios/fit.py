"""Outage scenarios that fit the log at hand (``navreplay analyze``).

The named scenarios of ``params.yaml`` are made for the built-in drives: five windows of 60 s
after 120 s of settling need some 10 minutes. A user's log is often shorter. ``fit_scenarios``
keeps every scenario whose windows fit as configured and adapts the others, in this order:

1. the margins change to ``FitParams``: windows may start ``settle_s`` after the first GNSS
   fix (instead of ``earliest_s`` after the first IMU sample, which is also too early when
   the fixes begin later) and end ``tail_s`` before the last one, and as many windows as fit
   are placed (same length, seed and gap);
2. if not even one fits, the longest length of ``FitParams.lengths_s`` below the
   scenario's that fits is used.

Windows lie only where the log has GNSS fixes (or raw observations): an outage where there
was no GNSS anyway measures nothing. Each adaptation is reported in one line that says what
was changed and how to choose otherwise; a scenario that cannot fit at all is returned with
the reason. Explicit windows are the user's choice and are kept as they are.

``parse_outage`` reads the ``--outage`` option and ``scenarios.fit.outages``: ``30s`` (as
many 30 s windows as fit, placed at random) or ``30s@45s`` (one window from 45 s after the
first IMU sample).
"""

from __future__ import annotations

import re
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np
import pyarrow as pa

from navreplay.ingest.schema import FixType
from navreplay.pipeline.estimation.core.windows import NS
from navreplay.pipeline.scenarios.config import (
    FitParams,
    ScenariosParams,
    ScenarioSpec,
    WindowsSpec,
)
from navreplay.pipeline.scenarios.faults import times
from navreplay.pipeline.scenarios.windows import random_fit

_OUTAGE_RE = re.compile(
    r"^\s*(?P<len>\d+(?:\.\d*)?)\s*(?P<lu>s|min)?\s*(?:@\s*(?P<at>\d+(?:\.\d*)?)\s*(?P<au>s|min)?)?\s*$"
)


@dataclass(frozen=True)
class Fitted:
    """What ``fit_scenarios`` made of the scenarios.

    Attributes:
        scenarios: the scenarios section with the adapted specs in place.
        notes: one line per adapted scenario: what changed and what to do instead.
        unfit: scenario -> why no window of it fits this log.
    """

    scenarios: ScenariosParams
    notes: tuple[str, ...]
    unfit: Mapping[str, str]


def _seconds(value: str, unit: str | None) -> float:
    return float(value) * (60.0 if unit == "min" else 1.0)


def parse_outage(text: str, fit: FitParams) -> tuple[str, ScenarioSpec]:
    """The scenario ``--outage TEXT`` asks for, and its name (``outage_30s``,
    ``outage_30s_at_45s``); ``ValueError`` says what is accepted."""
    m = _OUTAGE_RE.match(text)
    if m is None or float(m["len"]) <= 0:
        raise ValueError(
            f"--outage {text!r}: give a length, optionally with its start, in seconds from the "
            "first IMU sample: 30s (as many 30 s windows as fit), 30s@45s, 2min@1.5min"
        )
    length = _seconds(m["len"], m["lu"])
    if m["at"] is None:
        windows = WindowsSpec(
            placement="random", length_s=length, count=fit.max_windows, seed=1,
            earliest_s=fit.settle_s, tail_s=fit.tail_s, min_gap_s=fit.settle_s,
        )  # fmt: skip
        return f"outage_{length:g}s", ScenarioSpec(
            f"complete GNSS outages of {length:g} s, as many as fit (--outage)", windows
        )
    start = _seconds(m["at"], m["au"])
    windows = WindowsSpec(placement="explicit", length_s=length, starts_s=(start,))
    return f"outage_{length:g}s_at_{start:g}s", ScenarioSpec(
        f"a complete GNSS outage of {length:g} s from {start:g} s (--outage)", windows
    )


def aided_span(tables: Mapping[str, pa.Table], t0_ns: int) -> tuple[float, float] | None:
    """(first, last) time with GNSS, s from ``t0_ns``: 3-D fixes, else raw observations."""
    gnss = tables.get("gnss")
    t: np.ndarray | None = None
    if gnss is not None and gnss.num_rows:
        good = np.asarray(gnss.column("fix_type").fill_null(0).to_numpy()) >= FixType.FIX_3D
        t = times(gnss)[good]
    if (t is None or t.size == 0) and "gnss_obs" in tables and tables["gnss_obs"].num_rows:
        t = times(tables["gnss_obs"])
    if t is None or t.size == 0:
        return None
    return (int(t.min()) - t0_ns) / NS, (int(t.max()) - t0_ns) / NS


def _fits(spec: WindowsSpec, end_s: float) -> int:
    """How many windows of ``spec`` its own placement puts before ``end_s``."""
    latest = end_s if spec.latest_s is None else min(spec.latest_s, end_s)
    return random_fit(spec.length_s, spec.min_gap_s, spec.earliest_s, latest)


def fit_windows(
    spec: WindowsSpec, span_s: float, aided: tuple[float, float] | None, fit: FitParams
) -> tuple[WindowsSpec | None, str | None]:
    """``spec`` fitted to a log of ``span_s`` seconds with GNSS over ``aided``: (the windows
    to use or None, a note of what changed or why none fits; None when nothing changed)."""
    if spec.placement == "explicit":
        return spec, None
    if aided is None:
        return None, "the log has no GNSS fix to take away"
    first, last = aided[0], min(aided[1], span_s)
    end = last - spec.tail_s
    settled = first + fit.settle_s <= spec.earliest_s  # GNSS long enough before earliest_s
    if settled and spec.placement == "random" and _fits(spec, end) >= spec.count:
        return spec, None
    if settled and spec.placement == "periodic" and end - spec.earliest_s >= spec.length_s:
        return spec, None
    earliest = first + fit.settle_s
    latest = last - min(spec.tail_s, fit.tail_s)
    for length in (
        spec.length_s,
        *sorted((x for x in fit.lengths_s if x < spec.length_s), reverse=True),
    ):
        n = min(spec.count, random_fit(length, spec.min_gap_s, earliest, latest))
        if n == 0:
            continue
        fitted = WindowsSpec(
            placement="random", length_s=length, count=n, seed=spec.seed,
            earliest_s=earliest, latest_s=latest, tail_s=0.0, min_gap_s=spec.min_gap_s,
        )  # fmt: skip
        shorter = f", shortened to {length:g} s" if length != spec.length_s else ""
        note = (
            f"{spec.count} window(s) of {spec.length_s:g} s need {spec.earliest_s:g} s of "
            f"settling and {spec.tail_s:g} s after; the log has GNSS from {first:.1f} to "
            f"{last:.1f} s: placed {n} window(s){shorter} between {earliest:.1f} and "
            f"{latest:.1f} s"
        )
        return fitted, note
    shortest = min((spec.length_s, *fit.lengths_s))
    return None, (
        f"no outage window fits: the log has GNSS from {first:.1f} to {last:.1f} s, and even "
        f"{shortest:g} s needs {fit.settle_s:g} s of settling before it and {fit.tail_s:g} s "
        "after it"
    )


def fit_scenarios(
    tables: Mapping[str, pa.Table],
    scenarios: ScenariosParams,
    names: Sequence[str],
    *,
    as_many_as_fit: Collection[str] = (),
) -> Fitted:
    """Fit the windows of the scenarios ``names`` to the tables (see the module docstring);
    those of ``as_many_as_fit`` (``--outage LEN``) asked for no more than fit, so their
    fitting is not noted."""
    from navreplay.pipeline.scenarios.apply import log_span

    t0, t_end = log_span(tables)
    span = (t_end - t0) / NS
    aided = aided_span(tables, t0)
    named = dict(scenarios.named)
    notes: dict[str, list[str]] = {}  # what changed -> the scenarios it changed
    unfit: dict[str, str] = {}
    for name in names:
        spec = named[name]
        if spec.windows is None:
            continue
        windows, note = fit_windows(spec.windows, span, aided, scenarios.fit)
        if windows is None:
            unfit[name] = note or "no outage window fits"
            continue
        if note is not None:
            if name not in as_many_as_fit:
                notes.setdefault(note, []).append(name)
            named[name] = replace(spec, windows=windows)
    lines = tuple(
        f"{', '.join(names)}: {note}. To choose instead: --outage LEN[@START], or the "
        "scenarios' windows (scenarios.named.<name>.windows) in a --params file"
        for note, names in notes.items()
    )
    return Fitted(replace(scenarios, named=named), lines, unfit)


def with_outages(
    scenarios: ScenariosParams, texts: Sequence[str]
) -> tuple[ScenariosParams, list[str]]:
    """The scenarios with those of ``texts`` (``parse_outage``) added; and their names."""
    named = dict(scenarios.named)
    names = []
    for text in texts:
        name, spec = parse_outage(text, scenarios.fit)
        named[name] = spec
        names.append(name)
    return replace(scenarios, named=named), names
