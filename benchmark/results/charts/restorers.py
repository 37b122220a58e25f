"""Restorer speed against accuracy: images per second against PSNR, one point per (lens, restorer)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib
from matplotlib.lines import Line2D

from benchmark.results.charts import new_figure, save_figure
from benchmark.results.schema import SHARP_LENS, Row, rows_of_kind

__all__ = ["restorer_points", "write_restorer_speed_chart"]

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


def write_restorer_speed_chart(rows: Sequence[Row], path: Path) -> Path:
    """Scatter of restorer throughput (images/s, log axis) against PSNR (dB).

    Colour is the restorer (legend lists its threat model), marker the lens; up and to the
    right is a faster, stronger attack. Rows other than restorers' are ignored.

    Args:
        rows: Result rows.
        path: Output image file (format from the suffix, e.g. ``.png``); parents are created.

    Returns:
        ``path``.
    """
    points = restorer_points(rows)
    restorers = sorted({attack for _, attack in points})
    lens_names = sorted({lens for lens, _ in points})
    colours = {a: matplotlib.colormaps["tab10"](i % 10) for i, a in enumerate(restorers)}
    markers = {lens: _MARKERS[i % len(_MARKERS)] for i, lens in enumerate(lens_names)}
    fig = new_figure(figsize=(7.5, 4.8), constrained_layout=True)
    ax = fig.subplots()
    for (lens, attack), (speed, psnr, _) in points.items():
        ax.scatter(speed, psnr, color=colours[attack], marker=markers[lens], s=50, edgecolor="black", linewidth=0.5)
    threat = {attack: tm for (_, attack), (_, _, tm) in points.items()}
    handles = [Line2D([], [], color=colours[a], marker="o", linestyle="", label=f"{a} ({threat[a]})")
               for a in restorers]
    handles += [Line2D([], [], color="gray", marker=markers[lens], linestyle="", label=f"lens: {lens}")
                for lens in lens_names]
    if points:
        ax.set_xscale("log")
        ax.legend(handles=handles, fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5), frameon=False)
    else:
        ax.text(0.5, 0.5, "no restorer rows", ha="center", va="center", transform=ax.transAxes)
    ax.set_xlabel("throughput (images / s, log scale)")
    ax.set_ylabel("PSNR (dB)")
    ax.set_title("Restorers: speed against accuracy")
    ax.grid(True, which="both", alpha=0.3)
    return save_figure(fig, path, dpi=120, layout=False)
