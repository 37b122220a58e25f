"""Restorer speed against accuracy: images per second against PSNR, one point per (lens, restorer)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from benchmark.charts import save_figure  # noqa: E402

__all__ = ["restorer_points", "write_restorer_speed_chart"]

_MARKERS = "os^Dv<>pP*X"


def restorer_points(rows: Sequence[Mapping]) -> dict[tuple[str, str], tuple[float, float, str]]:
    """Mean (images/s, PSNR dB) and threat model per (lens, restorer), pooled over seeds.

    A restorer row is one with finite ``psnr_db`` and positive ``images_per_s`` whose ``attack``
    is not a chain (no ``>``) on a real lens (not ``sharp``); reader, lens and utility rows
    lack one of these and are left out.

    Returns:
        {(lens, attack): (images per second, PSNR in dB, threat model)}.
    """
    groups: dict[tuple[str, str], list[Mapping]] = {}
    for row in rows:
        psnr, speed = row.get("psnr_db"), row.get("images_per_s")
        if psnr is None or speed is None or ">" in str(row["attack"]) or row["lens"] == "sharp":
            continue
        if not (math.isfinite(float(psnr)) and float(speed) > 0):
            continue
        groups.setdefault((str(row["lens"]), str(row["attack"])), []).append(row)
    return {
        key: (sum(float(r["images_per_s"]) for r in g) / len(g), sum(float(r["psnr_db"]) for r in g) / len(g),
              str(g[0].get("threat_model", "")))
        for key, g in sorted(groups.items())
    }


def write_restorer_speed_chart(rows: list[dict], path: Path) -> Path:
    """Scatter of restorer throughput (images/s, log axis) against PSNR (dB).

    Colour is the restorer (legend lists its threat model), marker the lens; up and to the
    right is a faster, stronger attack. Rows as produced by the runner (keys ``lens``,
    ``attack``, ``psnr_db``, ``images_per_s``, ``threat_model``); others are ignored.

    Args:
        rows: Result rows.
        path: Output image file (format from the suffix, e.g. ``.png``); parents are created.

    Returns:
        ``path``.
    """
    points = restorer_points(rows)
    restorers = sorted({attack for _, attack in points})
    lens_names = sorted({lens for lens, _ in points})
    colours = {a: plt.get_cmap("tab10")(i % 10) for i, a in enumerate(restorers)}
    markers = {lens: _MARKERS[i % len(_MARKERS)] for i, lens in enumerate(lens_names)}
    fig, ax = plt.subplots(figsize=(7.5, 4.8), constrained_layout=True)
    for (lens, attack), (speed, psnr, _) in points.items():
        ax.scatter(speed, psnr, color=colours[attack], marker=markers[lens], s=50, edgecolor="black", linewidth=0.5)
    threat = {attack: tm for (_, attack), (_, _, tm) in points.items()}
    handles = [plt.Line2D([], [], color=colours[a], marker="o", linestyle="", label=f"{a} ({threat[a]})")
               for a in restorers]
    handles += [plt.Line2D([], [], color="gray", marker=markers[lens], linestyle="", label=f"lens: {lens}")
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
