"""Restorer speed against accuracy: images per second against PSNR, one point per (lens, restorer)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from benchmark.results.charts import new_figure, save_figure
from benchmark.results.schema import SHARP_LENS, Row, rows_of_kind

__all__ = ["psnr_intervals", "restorer_points", "restorer_speed_figure", "write_restorer_speed_chart"]

_MARKERS = "os^Dv<>pP*X"


def restorer_points(rows: Sequence[Row]) -> dict[tuple[str, str], tuple[float, float, str]]:
    """Mean (images/s, PSNR dB) and threat model per (lens, restorer), pooled over seeds.

    Only restorer rows that succeeded on a real lens (not ``sharp``), with ``psnr_db`` and a
    positive ``images_per_s``, count.

    Returns:
        {(lens, attack): (images per second, PSNR in dB, threat model)}.
    """
    groups: dict[tuple[str, str], list[Row]] = {}
    for row in rows_of_kind(rows, "restorer"):
        psnr, speed = row.metric("psnr_db"), row.metric("images_per_s")
        if psnr is None or speed is None or speed <= 0 or row.lens == SHARP_LENS:
            continue
        groups.setdefault((row.lens, row.attack), []).append(row)
    return {
        key: (sum(r.metrics["images_per_s"] for r in g) / len(g), sum(r.metrics["psnr_db"] for r in g) / len(g),
              g[0].threat_model or "")
        for key, g in sorted(groups.items())
    }


def psnr_intervals(rows: Sequence[Row]) -> dict[tuple[str, str], tuple[float, float]]:
    """The 95 % PSNR interval (dB) per (lens, restorer) of ``restorer_points``: the row's own with one
    seed, the span from the lowest to the highest of the seeds' intervals with several. A point
    whose rows carry no interval has none here."""
    spans: dict[tuple[str, str], tuple[float, float]] = {}
    for row in rows_of_kind(rows, "restorer"):
        interval = row.interval("psnr_db")
        key = (row.lens, row.attack)
        if interval is None or row.lens == SHARP_LENS:
            continue
        low, high = spans.get(key, interval)
        spans[key] = (min(low, interval[0]), max(high, interval[1]))
    return spans


# Shown about 1000 px wide at DPI: the fonts are their printed size.
DPI = 100
FONT_PT, LEGEND_PT = 10.0, 9.0
_LEFT_IN, _AXES_W_IN, _LEGEND_W_IN, _BOTTOM_IN, _TOP_IN, _MIN_AXES_H_IN = 0.85, 5.6, 3.3, 0.6, 0.45, 3.6


def _colours(n: int) -> list:
    """``n`` distinct colours without grey or black (those mark lenses in the legend): tab10's nine,
    tab20's eighteen past nine."""
    if n <= 9:
        return [matplotlib.colormaps["tab10"](i) for i in range(10) if i != 7][:n]
    palette = [matplotlib.colormaps["tab20"](i) for i in range(20) if i not in (14, 15)]
    return [palette[i % len(palette)] for i in range(n)]


def restorer_speed_figure(rows: Sequence[Row]) -> Figure:
    """The chart of ``write_restorer_speed_chart``."""
    points = restorer_points(rows)
    intervals = psnr_intervals(rows)
    restorers = sorted({attack for _, attack in points})
    lens_names = sorted({lens for lens, _ in points})
    colours = dict(zip(restorers, _colours(len(restorers))))
    markers = {lens: _MARKERS[i % len(_MARKERS)] for i, lens in enumerate(lens_names)}
    entries = len(restorers) + len(lens_names) + 3
    axes_h = max(_MIN_AXES_H_IN, entries * LEGEND_PT * 1.45 / 72 + 0.3)
    width, height = _LEFT_IN + _AXES_W_IN + _LEGEND_W_IN, _BOTTOM_IN + axes_h + _TOP_IN
    fig = new_figure(figsize=(width, height))
    ax = fig.add_axes((_LEFT_IN / width, _BOTTOM_IN / height, _AXES_W_IN / width, axes_h / height))
    for (lens, attack), (speed, psnr, _) in points.items():
        low, high = intervals.get((lens, attack), (psnr, psnr))
        ax.errorbar([speed], [psnr], yerr=[[max(psnr - low, 0.0)], [max(high - psnr, 0.0)]], fmt=markers[lens],
                    color=colours[attack], ms=7, mec="black", mew=0.5, ecolor=colours[attack], elinewidth=1.2,
                    capsize=3)
    threat = {attack: tm for (_, attack), (_, _, tm) in points.items()}
    handles = [Line2D([], [], color=colours[a], marker="o", linestyle="", ms=7, mec="black", mew=0.5,
                      label=f"{a} ({threat[a]})" if threat[a] else a) for a in restorers]
    handles += [Line2D([], [], color="black", marker=markers[lens], mfc="none", linestyle="", ms=7,
                       label=f"lens: {lens}") for lens in lens_names]
    if points:
        ax.set_xscale("log")
        ax.legend(handles=handles, fontsize=LEGEND_PT, loc="upper left", bbox_to_anchor=(1.02, 1.0),
                  borderaxespad=0.0, frameon=False, title="colour: restorer (threat model)\nmarker: lens",
                  title_fontsize=LEGEND_PT, alignment="left")
    else:
        ax.text(0.5, 0.5, "no restorer rows", ha="center", va="center", transform=ax.transAxes)
    ax.set_xlabel("throughput (images / s, log scale)", fontsize=FONT_PT)
    ax.set_ylabel("PSNR (dB), 95 % interval", fontsize=FONT_PT)
    ax.set_title("Restorers: speed against accuracy (up and right: a faster, stronger attack)", fontsize=FONT_PT + 1,
                 loc="left")
    ax.tick_params(labelsize=FONT_PT - 1)
    ax.grid(True, which="both", alpha=0.3)
    return fig


def write_restorer_speed_chart(rows: Sequence[Row], path: Path) -> Path:
    """Scatter of restorer throughput (images/s, log axis) against PSNR (dB) with its 95 % interval.

    Colour is the restorer (legend lists its threat model; never grey, which is no restorer's), marker
    the lens (black in the legend); up and to the right is a faster, stronger attack. Rows other than
    restorers' are ignored.

    Args:
        rows: Result rows.
        path: Output image file (format from the suffix, e.g. ``.png``); parents are created.

    Returns:
        ``path``.
    """
    return save_figure(restorer_speed_figure(rows), path, dpi=DPI, layout=False)
