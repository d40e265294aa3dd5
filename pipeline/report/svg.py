"""Byte-stable, self-contained SVG figures for the HTML reports.

Every figure is a matplotlib figure saved as SVG with:

- a fixed ``svg.hashsalt`` and no ``Date`` metadata, so the same data give the same bytes;
- text kept as text (``svg.fonttype: none``): small, searchable, selectable in a browser;
- its element ids prefixed with the figure's key, so several figures can sit inline in one
  HTML page without id clashes (clip paths, markers);
- lines decimated by ``decimate_minmax`` before plotting: per bucket the first, minimum,
  maximum and last sample are kept, so peaks survive and an hour-long drive stays a few
  hundred kilobytes. The page's zoom (``html.ZOOM_JS``) magnifies the vector drawing.
"""

from __future__ import annotations

import io
import itertools
import re
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np

from navreplay.pipeline.nav.earth import F64

MAX_POINTS = 2000  # per line, after decimation: two extremes per pixel column of a wide plot

RC: dict[str, Any] = {
    "svg.hashsalt": "navreplay",
    "svg.fonttype": "none",
    "font.family": "sans-serif",
    "font.size": 9.0,
    "axes.titlesize": 10.0,
    "axes.grid": True,
    "grid.alpha": 0.35,
    "grid.linewidth": 0.5,
    "lines.linewidth": 1.0,
    "legend.fontsize": 8.0,
    "legend.framealpha": 0.85,
    "figure.dpi": 100,
    "path.simplify": False,
    "axes.prop_cycle": None,  # filled below
}

# Colour-blind-safe palette (Okabe-Ito), assigned to filters in a fixed order.
PALETTE = (
    "#0072B2",
    "#D55E00",
    "#009E73",
    "#CC79A7",
    "#E69F00",
    "#56B4E9",
    "#F0E442",
    "#000000",
)
TRUTH_COLOUR = "#444444"
OUTAGE_COLOUR = "#f2b134"


@contextmanager
def style() -> Iterator[Any]:
    """matplotlib (Agg backend) under the report's deterministic style; yields ``pyplot``."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt
    from cycler import cycler

    rc = dict(RC, **{"axes.prop_cycle": cycler(color=list(PALETTE))})
    with matplotlib.rc_context(rc):  # type: ignore[arg-type]
        yield plt


def colour(index: int) -> str:
    """The palette colour of the ``index``-th filter (cycled)."""
    return PALETTE[index % len(PALETTE)]


_ID_RE = re.compile(r'id="([^"]+)"')


def figure_svg(fig: Any, key: str) -> str:
    """The figure as an inline ``<svg>`` element (no XML prolog), ids prefixed by ``key``.

    Closes the figure. ``key`` must be unique within the page (letters, digits, ``-``, ``_``).
    """
    import matplotlib.pyplot as plt

    buf = io.StringIO()
    fig.savefig(buf, format="svg", metadata={"Date": None, "Creator": None}, bbox_inches="tight")
    plt.close(fig)
    text = buf.getvalue()
    text = _GEOM_RE.sub(lambda m: _FLOAT_RE.sub(_round2, m.group(0)), text[text.index("<svg") :])
    return prefix_ids(text, key)


# Geometry is written with 6 decimals of a point; 2 are plenty (1/100 px) and halve the size.
# Only path data and x/y attributes are touched, never text (tick labels keep their digits).
_GEOM_RE = re.compile(r'(?:\bd|\bx|\by|\bpoints)="[^"]*"')
_FLOAT_RE = re.compile(r"-?\d+\.\d{3,}")


def _round2(m: re.Match[str]) -> str:
    v = f"{float(m.group(0)):.2f}".rstrip("0").rstrip(".")
    return "0" if v == "-0" else v


def prefix_ids(svg: str, key: str) -> str:
    """``svg`` with every element id (and reference to it) prefixed by ``key-``."""
    for old in sorted(set(_ID_RE.findall(svg)), key=len, reverse=True):
        new = f"{key}-{old}"
        svg = svg.replace(f'id="{old}"', f'id="{new}"')
        svg = svg.replace(f"url(#{old})", f"url(#{new})")
        svg = svg.replace(f'href="#{old}"', f'href="#{new}"')
    return svg


def decimate_minmax(x: F64, y: F64, max_points: int = MAX_POINTS) -> tuple[F64, F64]:
    """Reduce a line to at most about ``max_points`` points, keeping every extreme.

    The samples are cut into ``max_points // 4`` buckets of equal count; each bucket keeps
    its first, minimum, maximum and last sample in time order. NaN samples are kept as
    line breaks (one per bucket that has any). Shorter inputs are returned unchanged.
    """
    n = x.size
    if n <= max_points:
        return x, y
    buckets = max(1, max_points // 4)
    edges = np.linspace(0, n, buckets + 1).astype(np.int64)
    keep: list[np.ndarray] = []
    for a, b in itertools.pairwise(edges):
        if b <= a:
            continue
        seg = y[a:b]
        finite = np.isfinite(seg)
        idx = [a, b - 1]
        if finite.any():
            rel = np.flatnonzero(finite)
            idx += [a + rel[np.argmin(seg[rel])], a + rel[np.argmax(seg[rel])]]
        if not finite.all():
            idx.append(a + int(np.flatnonzero(~finite)[0]))
        keep.append(np.unique(np.asarray(idx, dtype=np.int64)))
    sel = np.unique(np.concatenate(keep))
    return x[sel], y[sel]


def shade_windows(ax: Any, windows_s: list[tuple[float, float]], label: str | None) -> None:
    """Shade outage windows (seconds on the x axis) on ``ax``; labels only the first."""
    for i, (a, b) in enumerate(windows_s):
        ax.axvspan(a, b, color=OUTAGE_COLOUR, alpha=0.25, lw=0, label=label if i == 0 else None)
