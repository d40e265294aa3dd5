"""HTML building blocks of the reports: escaping, tables, figures, the page shell.

The page is one file: CSS and the small script inline, figures inline SVG (or PNG data
URIs), no network access of any kind. ``ZOOM_JS`` makes the figures interactive: wheel to
zoom around the pointer, drag to pan, double-click to reset (it changes the SVG's
``viewBox``, so the vector drawing stays sharp at any magnification); the data values under
the pointer (from the figure's ``data-axes``, ``svg.figure_svg``); a click on a legend entry
hides or shows its series; a link to a folded section opens it.
"""

from __future__ import annotations

import html
from collections.abc import Sequence
from typing import Any

from navreplay.pipeline.report.tables import fmt

CSS = """
:root { --fg: #1b1f24; --muted: #5b6570; --line: #d8dde3; --bg2: #f5f7f9; --accent: #0b5cad; }
* { box-sizing: border-box; }
body { font: 14px/1.45 system-ui, -apple-system, "Segoe UI", Roboto, sans-serif; color: var(--fg);
       margin: 0; }
header { background: #12263a; color: #fff; padding: 14px 28px; }
header h1 { margin: 0; font-size: 22px; }
header p { margin: 4px 0 0; color: #c9d6e3; }
nav { position: sticky; top: 0; background: #fff; border-bottom: 1px solid var(--line);
      padding: 6px 28px; z-index: 5; font-size: 13px; display: flex; flex-wrap: wrap;
      row-gap: 2px; }
nav a { margin-right: 14px; color: var(--accent); text-decoration: none; white-space: nowrap; }
main { padding: 8px 28px 40px; max-width: 1280px; }
section { margin-top: 26px; }
h2 { font-size: 18px; border-bottom: 2px solid var(--line); padding-bottom: 4px; }
h3 { font-size: 15px; margin: 18px 0 6px; }
p.note, .caption { color: var(--muted); font-size: 13px; }
table { border-collapse: collapse; margin: 8px 0 14px; font-size: 12.5px; }
th, td { border: 1px solid var(--line); padding: 3px 8px; text-align: right; }
th { background: var(--bg2); }
td.t, th.t { text-align: left; }
tr:nth-child(even) td { background: #fbfcfd; }
.ok { color: #17703a; font-weight: 600; }
.warn { color: #9a6200; font-weight: 600; }
.bad { color: #b3261e; font-weight: 600; }
figure { margin: 10px 0 18px; border: 1px solid var(--line); border-radius: 4px; padding: 6px;
         overflow: hidden; background: #fff; position: relative; }
.readout { position: absolute; display: none; pointer-events: none; background: #fffffff0;
           border: 1px solid var(--line); border-radius: 3px; padding: 1px 5px; font-size: 11.5px;
           font-variant-numeric: tabular-nums; }
figure svg, figure img { display: block; width: 100%; height: auto; cursor: zoom-in; }
figure.zoomed svg { cursor: grab; }
figcaption { color: var(--muted); font-size: 12.5px; margin-top: 4px; }
details { margin: 8px 0; }
summary { cursor: pointer; font-weight: 600; }
section > details > summary h2 { display: inline-block; width: calc(100% - 24px); margin: 0; }
section#verdict { border: 2px solid var(--line); border-radius: 6px; padding: 4px 14px 8px; }
ul.warnings li { color: #9a6200; }
code { background: var(--bg2); padding: 0 3px; border-radius: 3px; }
.scroll { overflow-x: auto; }
"""

ZOOM_JS = r"""
(function () {
  "use strict";
  function zoomable(svg) {
    var vb0 = svg.viewBox.baseVal;
    if (!vb0 || !vb0.width) { return; }
    var home = [vb0.x, vb0.y, vb0.width, vb0.height];
    var drag = null;
    function set(v) { svg.setAttribute("viewBox", v.join(" ")); }
    function cur() { var b = svg.viewBox.baseVal; return [b.x, b.y, b.width, b.height]; }
    function toSvg(ev) {
      var r = svg.getBoundingClientRect(), v = cur();
      return [v[0] + (ev.clientX - r.left) / r.width * v[2],
              v[1] + (ev.clientY - r.top) / r.height * v[3]];
    }
    svg.addEventListener("wheel", function (ev) {
      ev.preventDefault();
      var p = toSvg(ev), v = cur(), k = ev.deltaY < 0 ? 0.8 : 1.25;
      var w = Math.min(home[2], v[2] * k), h = Math.min(home[3], v[3] * k);
      set([p[0] - (p[0] - v[0]) * w / v[2], p[1] - (p[1] - v[1]) * h / v[3], w, h]);
      svg.parentNode.classList.toggle("zoomed", w < home[2]);
    }, { passive: false });
    svg.addEventListener("mousedown", function (ev) { drag = [ev.clientX, ev.clientY, cur()]; });
    window.addEventListener("mouseup", function () { drag = null; });
    svg.addEventListener("mousemove", function (ev) {
      if (!drag) { return; }
      var r = svg.getBoundingClientRect(), v = drag[2];
      set([v[0] - (ev.clientX - drag[0]) / r.width * v[2],
           v[1] - (ev.clientY - drag[1]) / r.height * v[3], v[2], v[3]]);
    });
    svg.addEventListener("dblclick", function () {
      set(home); svg.parentNode.classList.remove("zoomed");
    });
  }
  function toSvgOf(svg, ev) {
    var r = svg.getBoundingClientRect(), b = svg.viewBox.baseVal;
    return [b.x + (ev.clientX - r.left) / r.width * b.width,
            b.y + (ev.clientY - r.top) / r.height * b.height];
  }
  // a click on a legend entry hides or shows its series
  function toggles(svg) {
    svg.querySelectorAll("[id]").forEach(function (entry) {
      var m = /-ser(\d+)[ht]$/.exec(entry.id);
      if (!m) { return; }
      var parts = svg.querySelectorAll('[id$="-ser' + m[1] + '"], [id*="-ser' + m[1] + '_"]');
      if (!parts.length) { return; }
      entry.style.cursor = "pointer";
      entry.addEventListener("click", function (ev) {
        ev.stopPropagation();
        var off = parts[0].style.opacity === "0";
        parts.forEach(function (e) { e.style.opacity = off ? "" : "0"; });
        svg.querySelectorAll('[id$="-ser' + m[1] + 'h"], [id$="-ser' + m[1] + 't"]')
          .forEach(function (e) { e.style.opacity = off ? "" : "0.35"; });
      });
    });
  }
  // the data values under the pointer, from each axes' box and limits (data-axes)
  function readout(svg) {
    var axes = JSON.parse(svg.getAttribute("data-axes") || "[]");
    if (!axes.length) { return; }
    var tip = document.createElement("div");
    tip.className = "readout";
    svg.parentNode.appendChild(tip);
    function at(lo, hi, f, scale) {
      if (scale === "log") {
        return Math.pow(10, Math.log10(lo) + f * (Math.log10(hi) - Math.log10(lo)));
      }
      return lo + f * (hi - lo);
    }
    svg.addEventListener("mousemove", function (ev) {
      var p = toSvgOf(svg, ev), shown = false;
      axes.forEach(function (a) {
        if (shown || p[0] < a[0] || p[0] > a[2] || p[1] < a[1] || p[1] > a[3]) { return; }
        var x = at(a[4], a[5], (p[0] - a[0]) / (a[2] - a[0]), a[8]);
        var y = at(a[6], a[7], (a[3] - p[1]) / (a[3] - a[1]), a[9]);
        tip.textContent = "x " + x.toPrecision(5) + ", y " + y.toPrecision(4);
        var fr = svg.parentNode.getBoundingClientRect();
        tip.style.left = (ev.clientX - fr.left + 12) + "px";
        tip.style.top = (ev.clientY - fr.top + 12) + "px";
        shown = true;
      });
      tip.style.display = shown ? "block" : "none";
    });
    svg.addEventListener("mouseleave", function () { tip.style.display = "none"; });
  }
  document.querySelectorAll("figure.zoom svg").forEach(function (svg) {
    zoomable(svg); toggles(svg); readout(svg);
  });
  function reveal() {
    var target = location.hash && document.getElementById(location.hash.slice(1));
    var folded = target && target.querySelector(":scope > details");
    if (folded) { folded.open = true; }
  }
  window.addEventListener("hashchange", reveal);
  reveal();
})();
"""


def esc(text: Any) -> str:
    return html.escape(str(text), quote=True)


def table(
    rows: Sequence[dict[str, Any]],
    columns: Sequence[tuple[str, str]],
    *,
    cls: dict[str, Any] | None = None,
    table_id: str = "",
) -> str:
    """An HTML table; ``columns`` are (key, heading); text columns are left-aligned.

    ``cls`` maps a key to a function of the row returning a CSS class for that cell.
    """
    cls = cls or {}
    head = "".join(f'<th class="t">{esc(h)}</th>' if i == 0 else f"<th>{esc(h)}</th>"
                   for i, (_, h) in enumerate(columns))  # fmt: skip
    body = []
    for r in rows:
        cells = []
        for key, _ in columns:
            v = r.get(key)
            classes = []
            if isinstance(v, str) or v is None:
                classes.append("t")
            if key in cls:
                extra = cls[key](r)
                if extra:
                    classes.append(extra)
            attr = f' class="{" ".join(classes)}"' if classes else ""
            cells.append(f"<td{attr}>{esc(fmt(v))}</td>")
        body.append("<tr>" + "".join(cells) + "</tr>")
    ident = f' id="{esc(table_id)}"' if table_id else ""
    return (
        f'<div class="scroll"><table{ident} class="data"><thead><tr>{head}</tr></thead>'
        f"<tbody>{''.join(body)}</tbody></table></div>"
    )


def _cell(text: str) -> str:
    """A CSV cell for display: decimals shown to 4 significant digits (the CSV keeps all)."""
    if "." in text or "e" in text.lower():
        try:
            return fmt(float(text))
        except ValueError:
            return text
    return text


def _td(text: str) -> str:
    """A CSV cell as ``<td>``: numbers right-aligned (the default), text left-aligned."""
    try:
        float(text)
    except ValueError:
        return f'<td class="t">{esc(text)}</td>'
    return f"<td>{esc(_cell(text))}</td>"


def text_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    """A table of text cells as read from a CSV file (numbers rounded for display, text
    left-aligned; an empty cell counts as text)."""
    head = "".join(f"<th>{esc(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(_td(c) for c in r) + "</tr>" for r in rows)
    return (
        f'<div class="scroll"><table class="data"><thead><tr>{head}</tr></thead>'
        f"<tbody>{body}</tbody></table></div>"
    )


def figure(svg: str | None, caption: str = "", *, png_uri: str | None = None) -> str:
    """A zoomable figure from inline SVG text, or an image from a PNG data URI."""
    if svg is None and png_uri is None:
        return ""
    inner = svg if svg is not None else f'<img alt="{esc(caption)}" src="{png_uri}">'
    cap = f"<figcaption>{esc(caption)}</figcaption>" if caption else ""
    zoom = ' class="zoom"' if svg is not None else ""
    return f"<figure{zoom}>{inner}{cap}</figure>"


def section(ident: str, title: str, body: str, *, fold: bool = False, open_: bool = True) -> str:
    """A section; ``fold``: its body in a ``<details>`` (open with ``open_``) under its title."""
    if not fold:
        return f'<section id="{esc(ident)}"><h2>{esc(title)}</h2>{body}</section>'
    state = " open" if open_ else ""
    return (
        f'<section id="{esc(ident)}"><details{state}><summary><h2>{esc(title)}</h2></summary>'
        f"{body}</details></section>"
    )


def para(text: str, cls: str = "") -> str:
    c = f' class="{cls}"' if cls else ""
    return f"<p{c}>{esc(text)}</p>"


def page(
    title: str,
    subtitle: str,
    sections: Sequence[tuple[str, str, str]],
    *,
    opened: Sequence[str] | None = None,
) -> str:
    """The whole page: header, a navigation bar of the sections, the sections, the script.

    ``sections`` are (id, title, body HTML); empty bodies are left out. With ``opened``, the
    first section is the verdict, always shown, and the others fold (``<details>``), open
    when their id is in ``opened``; a link to a folded section opens it.
    """
    kept = [(i, t, b) for i, t, b in sections if b]
    links = "".join(f'<a href="#{esc(i)}">{esc(t)}</a>' for i, t, _ in kept)
    body = "".join(
        section(i, t, b, fold=opened is not None and k > 0, open_=opened is None or i in opened)
        for k, (i, t, b) in enumerate(kept)
    )
    return (
        "<!DOCTYPE html>\n"
        '<html lang="en"><head><meta charset="utf-8">'
        '<meta name="viewport" content="width=device-width, initial-scale=1">'
        f"<title>{esc(title)}</title><style>{CSS}</style></head><body>"
        f"<header><h1>{esc(title)}</h1><p>{esc(subtitle)}</p></header>"
        f"<nav>{links}</nav><main>{body}</main>"
        f"<script>{ZOOM_JS}</script></body></html>\n"
    )
