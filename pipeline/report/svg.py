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
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from typing import Any

import numpy as np

from navreplay.pipeline.nav.earth import F64

MAX_POINTS = 1200  # per line, after decimation: two extremes per pixel column of a wide plot

RC: dict[str, Any] = {
    "svg.hashsalt": "navreplay",
    "svg.fonttype": "none",
    "font.family": "sans-serif",
    "font.size": 9.0,
    "axes.titlesize": 10.0,
    # titles at the top of their axes: matplotlib's automatic place (None) measures every
    # axes' tick labels at each draw to lift a title over top ones, which no figure has (a
    # fifth of a report's rendering time)
    "axes.titley": 1.0,
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


def fixed_layout(
    fig: Any,
    *,
    left: float = 0.75,
    right: float = 0.15,
    top: float = 0.35,
    bottom: float = 0.5,
    hgap: float = 0.3,
    wgap: float = 0.75,
) -> None:
    """Place the figure's grid of axes with fixed margins and gaps, in inches.

    The report's figures have known furniture (a y label and tick labels on the left, a time
    axis at the bottom, a title over each panel and perhaps the figure's), so fixed margins
    fit them. matplotlib's constrained layout measures every tick label of every axes twice
    per figure to find the same margins: half of a report's rendering time.
    """
    width, height = (float(v) for v in fig.get_size_inches())
    rows, cols = fig.axes[0].get_subplotspec().get_gridspec().get_geometry()
    axes_h = (height - top - bottom - (rows - 1) * hgap) / rows
    axes_w = (width - left - right - (cols - 1) * wgap) / cols
    fig.subplots_adjust(
        left=left / width,
        right=1.0 - right / width,
        top=1.0 - top / height,
        bottom=bottom / height,
        hspace=hgap / axes_h,
        wspace=wgap / axes_w,
    )


def label_width_in(fig: Any, labels: Sequence[str]) -> float:
    """The width of the widest of ``labels`` as tick labels of ``fig``, inches (0 for none):
    what a fixed left margin must hold beside category tick labels."""
    import matplotlib as mpl
    from matplotlib.font_manager import FontProperties

    renderer = fig.canvas.get_renderer()
    font = FontProperties(size=mpl.rcParams["ytick.labelsize"])
    widths = [renderer.get_text_width_height_descent(s, font, ismath=False)[0] for s in labels]
    return float(max(widths, default=0.0)) / float(fig.dpi)


def figure_svg(fig: Any, key: str) -> str:
    """The figure as an inline ``<svg>`` element (no XML prolog), ids prefixed by ``key``.

    Closes the figure. ``key`` must be unique within the page (letters, digits, ``-``, ``_``).
    """
    import matplotlib.pyplot as plt

    _tag_series(fig)
    buf = io.StringIO()
    # the whole figure (its fixed margins leave little waste), so that the axes' places in
    # the SVG are their figure positions: data-axes maps the reader's pointer to data values
    fig.savefig(buf, format="svg", metadata={"Date": None, "Creator": None})
    axes = _axes_map(fig)
    plt.close(fig)
    text = buf.getvalue()
    text = text[text.index("<svg") :].replace("<svg", f"<svg data-axes='{axes}'", 1)
    return prefix_ids(compact(text), key)


def _tag_series(fig: Any) -> None:
    """Give every legend entry and the artist it names one id (``ser<n>``, and ``ser<n>h``,
    ``ser<n>t`` for the entry's handle and text), so the page can hide a series on a click
    on its entry (``html.ZOOM_JS``)."""
    from matplotlib.container import Container

    n = 0
    for ax in fig.axes:
        leg = ax.get_legend()
        if leg is None:
            continue
        artists, _ = ax.get_legend_handles_labels()
        for artist, handle, label in zip(
            artists, leg.legend_handles, leg.get_texts(), strict=False
        ):
            # a container (error bars) is its parts: ser<n>, ser<n>_1, ser<n>_2 ...
            parts = artist.get_children() if isinstance(artist, Container) else [artist]
            for j, part in enumerate(parts):
                part.set_gid(f"ser{n}" if j == 0 else f"ser{n}_{j}")
            if handle is not None:
                handle.set_gid(f"ser{n}h")
            label.set_gid(f"ser{n}t")
            n += 1


def _axes_map(fig: Any) -> str:
    """Each axes' box in SVG points (x0, y0, x1, y1 from the top left) with its data limits and
    scales, as JSON: what the page needs to show the data values under the pointer."""
    import json

    width, height = (float(v) * 72.0 for v in fig.get_size_inches())
    out = []
    for ax in fig.axes:
        if not ax.get_visible():
            continue
        b = ax.get_position()
        out.append([round(b.x0 * width, 2), round((1.0 - b.y1) * height, 2),
                    round(b.x1 * width, 2), round((1.0 - b.y0) * height, 2),
                    *(float(v) for v in ax.get_xlim()), *(float(v) for v in ax.get_ylim()),
                    ax.get_xscale(), ax.get_yscale()])  # fmt: skip
    return json.dumps(out, separators=(",", ":"))


def compact(svg: str) -> str:
    """Matplotlib's SVG text made smaller without a visible change: polylines as relative
    steps of 0.1 pt, other geometry to 0.01 pt, no indentation between elements, and no ids
    that nothing refers to (matplotlib names every group; only clip paths and markers are
    referred to). Text is untouched."""
    svg = _PATH_RE.sub(_compact_path, svg)
    svg = _GEOM_RE.sub(lambda m: _FLOAT_RE.sub(_round2, m.group(0)), svg)
    svg = _BETWEEN_RE.sub("><", svg)
    used = set(_REF_RE.findall(svg))

    def keep(m: re.Match[str]) -> str:
        return m.group(0) if m.group(1) in used or _SERIES_RE.match(m.group(1)) else ""

    return _ID_ATTR_RE.sub(keep, svg)


_BETWEEN_RE = re.compile(r">\s+<")
_REF_RE = re.compile(r'(?:url\(#|href="#)([^)"]+)')
_ID_ATTR_RE = re.compile(r' id="([^"]+)"')
_SERIES_RE = re.compile(r"ser\d+(?:_\d+|[ht])?$")


# A polyline's path data (M and L commands, maybe a closing z, as matplotlib writes every
# line and filled band) becomes "M x y l dx dy dx dy ... m dx dy l ...": relative steps
# between points rounded to 0.1 pt (1/7 px at the page's scale, differenced after rounding so
# that no error accumulates) print in a third of the characters of matplotlib's
# "L x.xxxxxx y.yyyyyy" lines. Paths with curves are left alone.
_PATH_RE = re.compile(r'\bd="(M[-\d.\sML]+)(z?)\s*"')
_CMD_RE = re.compile(r"([ML])([^ML]*)")


def _compact_path(m: re.Match[str]) -> str:
    cmds, coords = [], []
    for cmd, nums in _CMD_RE.findall(m.group(1)):
        xy = nums.split()
        for k in range(0, len(xy), 2):
            cmds.append(cmd if k == 0 else "L")
            coords.append(xy[k : k + 2])
    pts = np.round(np.asarray(coords, dtype=np.float64) * 10.0).astype(np.int64)
    out = [f"M{_tenths(int(pts[0, 0]))} {_tenths(int(pts[0, 1]))}"]
    mode = "M"
    for k in range(1, len(cmds)):
        dx, dy = (int(v) for v in pts[k] - pts[k - 1])
        letter = "m" if cmds[k] == "M" else "l"
        sep = letter if letter != mode else " "
        out.append(f"{sep}{_tenths(dx)} {_tenths(dy)}")
        mode = letter
    return f'd="{"".join(out)}{m.group(2)}"'


def _tenths(v: int) -> str:
    """An integer count of tenths as the shortest decimal text (``-12`` -> ``-1.2``)."""
    sign, v = ("-", -v) if v < 0 else ("", v)
    whole, frac = divmod(v, 10)
    if frac == 0:
        return f"{sign}{whole}"
    return f"{sign}{whole}.{frac}" if whole else f"{sign}.{frac}"


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
