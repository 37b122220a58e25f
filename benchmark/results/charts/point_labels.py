"""Labels: point labels that never overlap (stacked in a column beside the axes, each joined to its point by a
leader line) and legend labels wrapped to a width (`wrap_label`)."""

from __future__ import annotations

import textwrap
from collections.abc import Sequence

from matplotlib.axes import Axes

LABEL_FONT_PT = 8.0
# Vertical room per label as a multiple of the font size: text height plus a little air.
LINE_SPACING = 1.5


def line_height_in(fontsize_pt: float = LABEL_FONT_PT) -> float:
    """Height one stacked label needs, in inches."""
    return fontsize_pt * LINE_SPACING / 72.0


def spread(targets: Sequence[float], gap: float, low: float = 0.0, high: float = 1.0) -> list[float]:
    """Positions as near their targets as a 1-D stack allows: same order as the targets, every two at
    least ``gap`` apart, all within [low, high]. Returned in the order of ``targets``.

    Raises ValueError when (n - 1) * gap exceeds high - low (the caller must make room).
    """
    n = len(targets)
    if n and (n - 1) * gap > high - low + 1e-12:
        raise ValueError(f"{n} labels {gap:.3g} apart do not fit in [{low}, {high}]; make the panel taller")
    order = sorted(range(n), key=lambda i: (targets[i], i))
    pos = [min(max(targets[i], low), high) for i in order]
    for k in range(1, n):
        pos[k] = max(pos[k], pos[k - 1] + gap)
    if n and pos[-1] > high:
        pos[-1] = high
        for k in range(n - 2, -1, -1):
            pos[k] = min(pos[k], pos[k + 1] - gap)
    out = [0.0] * n
    for k, i in enumerate(order):
        out[i] = pos[k]
    return out


def label_points(ax: Axes, points: Sequence[tuple[float, float]], texts: Sequence[str], colors: Sequence,
                 axes_height_in: float, fontsize: float = LABEL_FONT_PT) -> list:
    """Label each (x, y) data point with its text in a column just right of ``ax`` (call after the
    axis limits are final). ``axes_height_in`` is the axes' height in inches, which sets the gap.
    The leader line takes the point's colour; the text stays dark so that pale colours stay legible.
    Returns the annotations."""
    y0, y1 = ax.get_ylim()
    targets = [(y - y0) / (y1 - y0) for _, y in points]
    gap = line_height_in(fontsize) / axes_height_in
    half = gap / 2
    placed = spread(targets, gap, half, 1.0 - half) if len(points) > 1 else [min(max(t, half), 1 - half)
                                                                              for t in targets]
    return [ax.annotate(text, xy=point, xycoords="data", xytext=(1.03, pos), textcoords="axes fraction",
                        va="center", ha="left", fontsize=fontsize, color="#222222", annotation_clip=False,
                        arrowprops={"arrowstyle": "-", "color": color, "lw": 0.6, "alpha": 0.7,
                                    "shrinkA": 1, "shrinkB": 3})
            for point, text, color, pos in zip(points, texts, colors, placed)]


def wrap_label(text: str, width: int = 40) -> str:
    """A legend label over lines of at most ``width`` characters, broken at spaces and after a chain's
    ``>`` (a word longer than ``width`` is cut)."""
    lines = textwrap.wrap(text.replace(">", "> "), width, break_on_hyphens=False)
    return "\n".join(line.replace("> ", ">") for line in lines)
