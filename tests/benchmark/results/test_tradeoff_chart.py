"""The utility-vs-privacy chart: one panel per profile, error bars from the data, labels that never overlap."""

from __future__ import annotations

import itertools

import pytest
from matplotlib.text import Text

from benchmark.results.charts.point_labels import spread
from benchmark.results.charts.tradeoff import TradeoffPoint, tradeoff_figure
from chart_layout import rendered_labels  # tests/chart_layout.py, shared with the run charts' legibility test


def point(lens: str, profile: str, privacy: float, utility: float, err: float = 0.5) -> TradeoffPoint:
    return TradeoffPoint(lens, profile, "synthetic", "lpdr", privacy, privacy - err, privacy + err,
                         utility, utility - 0.01, utility + 0.01, "seed std")


def crowded() -> list[TradeoffPoint]:
    """Twelve lenses piled at 0 % plate accuracy with nearly equal utility, plus a second profile."""
    pts = [point(f"lens-{i:02d}-with-a-long-name", "quick", 0.0, 0.160 + 0.0005 * (i % 3)) for i in range(12)]
    pts += [point("far", "quick", 60.0, 0.21, 5.0)]
    return pts + [point(name, "smoke", 0.0, 0.047) for name in ("ideal", "defocus", "sharp")]


def test_crowded_labels_never_overlap_and_stay_in_the_figure():
    fig = tradeoff_figure(crowded(), "worst-case plate accuracy %")
    texts, renderer = rendered_labels(fig)
    # The text's own box (an Annotation's extent would include its leader line).
    boxes = [Text.get_window_extent(t, renderer) for ax_texts in texts.values() for t in ax_texts]
    assert len(boxes) == 16
    for a, b in itertools.combinations(boxes, 2):
        assert not a.overlaps(b), (a, b)
    width, height = fig.canvas.get_width_height()
    assert all(0 <= b.x0 and b.x1 <= width and 0 <= b.y0 and b.y1 <= height for b in boxes)


def test_one_panel_per_profile_with_error_bars_and_ranges_from_the_data():
    fig = tradeoff_figure(crowded(), "worst-case plate accuracy %")
    quick, smoke = fig.axes
    assert "profile quick" in quick.get_title(loc="left") and "profile smoke" in smoke.get_title(loc="left")
    assert {t.get_text() for t in smoke.texts} == {"ideal", "defocus", "sharp"}
    lo, hi = quick.get_xlim()
    assert lo < -0.5 and 65.0 < hi < 72.0  # the error bars' extent (-0.5 .. 65) plus a margin
    lo, hi = smoke.get_xlim()
    assert hi - lo == pytest.approx(2.0)  # all at 0 %: the narrowest span, centred
    assert len(quick.containers) == 13  # one errorbar container per lens


def test_spread_keeps_order_gap_and_bounds():
    pos = spread([0.5, 0.5, 0.5, 0.1, 0.95], gap=0.2, low=0.0, high=1.0)
    order = sorted(range(5), key=lambda i: ([0.5, 0.5, 0.5, 0.1, 0.95][i], i))
    placed = [pos[i] for i in order]
    assert all(b - a >= 0.2 - 1e-12 for a, b in zip(placed, placed[1:]))
    assert 0.0 <= min(pos) and max(pos) <= 1.0
    with pytest.raises(ValueError, match="make the panel taller"):
        spread([0.5] * 7, gap=0.2)
