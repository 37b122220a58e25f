"""Text from users (lens, attacker, scene and error names) made inert in Markdown tables.

Lens and attacker names come from plugins and spec files, error messages from plugins' exceptions;
the leaderboard README and a run's table.md show them, and Markdown passes raw HTML through to
renderers that do not sanitise it (`<script>`, `<img onerror=...>`). The web page escapes them as
HTML (benchmark.publish.page); here a cell is escaped only where text could become markup, so that
ordinary cells (`identity>lpdr`, `< 0.001`, `[+0.03, +0.05]`) read exactly as before:

- ``<`` that could open a tag, comment or autolink (before a letter, ``/``, ``!`` or ``?``) -> ``&lt;``;
- ``](`` that would close a link or image's text -> ``\\](``;
- ``|`` (a new cell) -> ``\\|``, and a backslash (which could escape the cell's closing ``|``) -> ``\\\\``;
- line breaks (a new row, or any Markdown at all) -> spaces.
"""

from __future__ import annotations

import re

_TAG_OPEN = re.compile(r"<(?=[A-Za-z/!?])")
_LINE_BREAK = re.compile(r"[\r\n\u2028\u2029\x0b\x0c\x85]+")


def md_cell(text: object) -> str:
    """`text` as the content of one Markdown table cell, inert (see the module docstring)."""
    out = _LINE_BREAK.sub(" ", str(text)).replace("\\", "\\\\").replace("|", "\\|")
    return _TAG_OPEN.sub("&lt;", out).replace("](", "\\](")


def md_code(text: object) -> str:
    """`text` as an inline code span (never markup): fenced by more backticks than it holds in a row."""
    text = _LINE_BREAK.sub(" ", str(text))
    fence = "`" * (max((len(run) for run in re.findall(r"`+", text)), default=0) + 1)
    pad = " " if text.startswith("`") or text.endswith("`") else ""
    return f"{fence}{pad}{text}{pad}{fence}"
