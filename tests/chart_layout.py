"""Layout checks shared by the chart tests: render a figure with the Agg canvas, then compare the window
extents (display pixels) of its legends, labels and notes with each other and with the axes' data areas.

Imported as ``from chart_layout import ...`` (tests/ is on sys.path: the rootdir conftest lives there).
"""

from __future__ import annotations

import itertools

from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.text import Text
from matplotlib.transforms import Bbox


def rendered_labels(fig: Figure):
    """Draw ``fig`` once; returns ({axes: its texts (annotations included)}, the renderer)."""
    FigureCanvasAgg(fig).draw()
    renderer = fig.canvas.get_renderer()
    return {ax: [t for t in ax.texts] for ax in fig.axes}, renderer


def _visible_text_box(text: Text, renderer) -> Bbox | None:
    if not text.get_visible() or not text.get_text().strip():
        return None
    return Text.get_window_extent(text, renderer)  # the text's own box, not an annotation's leader line


def data_areas(fig: Figure) -> dict[Axes, Bbox]:
    """Each visible axes' data area (its patch: where the data are drawn) in display pixels."""
    return {ax: ax.get_window_extent() for ax in fig.axes if ax.get_visible() and ax.axison}


def legend_boxes(fig: Figure, renderer) -> list[Bbox]:
    """The window extents of every legend of the figure (per-axes legends and figure legends)."""
    legends = [ax.get_legend() for ax in fig.axes if ax.get_visible()] + list(fig.legends)
    return [leg.get_window_extent(renderer) for leg in legends if leg is not None and leg.get_visible()]


def label_boxes(fig: Figure, renderer) -> list[tuple[str, Bbox]]:
    """(what, window extent) of every visible axis label and title, and of the figure's own texts
    (captions, notes, suptitle)."""
    boxes = []
    for ax in fig.axes:
        if not ax.get_visible():
            continue
        for what, text in (("xlabel", ax.xaxis.label), ("ylabel", ax.yaxis.label), ("title", ax.title),
                           ("title", ax._left_title), ("title", ax._right_title)):
            box = _visible_text_box(text, renderer)
            if box is not None:
                boxes.append((f"{what} {text.get_text()!r}", box))
    texts = list(fig.texts) + [t for t in (fig._suptitle,) if t is not None and t not in fig.texts]
    for text in texts:
        box = _visible_text_box(text, renderer)
        if box is not None:
            boxes.append((f"figure text {text.get_text()[:40]!r}", box))
    return boxes


def assert_legible_layout(fig: Figure, min_font_pt: float = 0.0) -> None:
    """Render ``fig`` and assert that no legend overlaps any axes' data area, any axis label, title or
    figure text, or another legend; that no figure text (caption, note) overlaps a data area; that
    every legend and label lies inside the figure; and that no legend, label or tick label is set
    smaller than ``min_font_pt``."""
    _, renderer = rendered_labels(fig)
    areas = data_areas(fig)
    legends = legend_boxes(fig, renderer)
    labels = label_boxes(fig, renderer)
    width, height = fig.canvas.get_width_height()
    for legend in legends:
        for ax, area in areas.items():
            assert not legend.overlaps(area), f"a legend {legend} covers the data of {ax.get_title()!r} {area}"
        for what, box in labels:
            assert not legend.overlaps(box), f"a legend {legend} covers the {what} {box}"
    for a, b in itertools.combinations(legends, 2):
        assert not a.overlaps(b), (a, b)
    for text in fig.texts:
        box = _visible_text_box(text, renderer)
        if box is None:
            continue
        for ax, area in areas.items():
            assert not box.overlaps(area), f"the note {text.get_text()[:40]!r} {box} covers the data of {ax.get_title()!r}"
    for (what, box), (other, box2) in itertools.combinations(labels, 2):
        assert not box.overlaps(box2), f"the {what} {box} overlaps the {other} {box2}"
    for box in legends + [b for _, b in labels]:
        assert -1 <= box.x0 and box.x1 <= width + 1 and -1 <= box.y0 and box.y1 <= height + 1, (box, width, height)
    if min_font_pt:
        sizes = []
        for ax in fig.axes:
            if not ax.get_visible():
                continue
            legend = ax.get_legend()
            if legend is not None:
                sizes += [t.get_fontsize() for t in legend.get_texts()]
            sizes += [t.get_fontsize() for t in (ax.xaxis.label, ax.yaxis.label, ax.title) if t.get_text()]
            sizes += [t.get_fontsize() for t in ax.get_xticklabels() + ax.get_yticklabels() if t.get_text()]
        for leg in fig.legends:
            sizes += [t.get_fontsize() for t in leg.get_texts()]
        sizes += [t.get_fontsize() for t in fig.texts if t.get_text()]
        assert sizes and min(sizes) >= min_font_pt, f"smallest font {min(sizes)} pt < {min_font_pt} pt"
