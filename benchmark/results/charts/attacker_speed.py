"""Attackers' speed against accuracy on the leaderboard: restorers (images/s vs PSNR) and plate
readers (images/s vs plate accuracy, chains included), one point per lens."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib.ticker
from matplotlib.figure import Figure

from benchmark.results.charts import new_figure, save_figure
from benchmark.results.entries import Entry

_PANELS = (("psnr_db", 1.0, "PSNR dB against the sharp scene", "Restorers"),
           ("plate_acc", 100.0, "plate accuracy %", "Plate readers and chains"))


def attacker_speed_figure(entries: Sequence[Entry]) -> Figure | None:
    """Two panels (restorers, readers); one colour per attack chain. None when no chain has both figures."""
    series: list[dict[str, list[tuple[float, float]]]] = [{} for _ in _PANELS]
    for e in entries:
        for chain in e.chains():
            mt = chain.metrics
            for (name, scale, _, _), found in zip(_PANELS, series):
                if name in mt and "images_per_s" in mt:
                    found.setdefault(chain.attack, []).append((mt["images_per_s"].mean, mt[name].mean * scale))
    if not any(series):
        return None
    fig = new_figure(figsize=(13, 5))
    for ax, (_, _, ylabel, title), found in zip(fig.subplots(1, 2), _PANELS, series):
        for name, pts in sorted(found.items()):
            ax.scatter([p[0] for p in pts], [p[1] for p in pts], label=name, s=18)
        ax.set_xscale("log")
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.set_xlabel("images / s (log)")
        ax.set_ylabel(ylabel)
        ax.set_title(f"{title}: speed against accuracy (one point per lens)", fontsize=10)
        ax.grid(alpha=0.3)
        if found:
            ax.legend(fontsize=6)
    return fig


def write_attacker_speed_chart(entries: Sequence[Entry], path: Path) -> Path | None:
    fig = attacker_speed_figure(entries)
    return None if fig is None else save_figure(fig, path, dpi=100)
