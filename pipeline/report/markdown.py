"""Markdown notes of experiment stages as safe, self-contained HTML.

``to_html(text)`` renders CommonMark with pipe tables (markdown-it-py). Raw HTML in the text
is escaped, not passed through, and images are not loaded (an ``![..](http://..)`` would make
the page fetch from the network): each shows as the text ``[image: ALT (ADDRESS)]``.
Headings are shifted down to ``<h4>``..``<h6>`` so a note sits inside its report section.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from functools import lru_cache
from html import escape
from typing import Any

from markdown_it import MarkdownIt
from markdown_it.token import Token

_HEADING = re.compile(r"<(/?)h([1-6])>")


def _image_as_text(_self: Any, tokens: Sequence[Token], idx: int, _options: Any, _env: Any) -> str:
    tok = tokens[idx]
    return escape(f"[image: {tok.content} ({tok.attrGet('src') or ''})]")


@lru_cache(maxsize=1)
def _parser() -> MarkdownIt:
    md = MarkdownIt("commonmark", {"html": False}).enable("table")
    md.add_render_rule("image", _image_as_text)
    return md


def to_html(text: str) -> str:
    """``text`` (Markdown) as an HTML fragment (see the module docstring)."""
    html = _parser().render(text)
    html = _HEADING.sub(lambda m: f"<{m[1]}h{min(6, int(m[2]) + 3)}>", html)
    return html.replace("<table>", '<div class="scroll"><table class="data">').replace(
        "</table>", "</table></div>"
    )
