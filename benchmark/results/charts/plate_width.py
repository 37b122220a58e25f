"""Plate accuracy against plate width: one panel per lens, one line per reader chain."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import matplotlib.ticker
import numpy as np
from matplotlib.figure import Figure

from benchmark.results.charts import new_figure, save_figure
from benchmark.results.plate_scoring import WIDTH_BINS_PX

__all__ = ["plate_width_figure", "width_accuracy", "write_plate_width_chart"]


def width_accuracy(records: Sequence[Mapping], bins_px: Sequence[int] = WIDTH_BINS_PX
                   ) -> dict[tuple[str, str], tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Plate accuracy per width bin, per (lens, chain), pooled over seeds and scenes.

    Args:
        records: Per-plate dicts as in plates.csv (keys ``lens``, ``attack``, ``width_px``, ``correct``).
        bins_px: Left edges of the width bins in pixels; the last bin is open-ended.

    Returns:
        {(lens, attack): (bin left edges px, accuracy in [0, 1] (NaN where empty), plate counts)}.
    """
    edges = np.asarray(list(bins_px) + [np.inf], dtype=float)
    groups: dict[tuple[str, str], list[Mapping]] = {}
    for record in records:
        groups.setdefault((str(record["lens"]), str(record["attack"])), []).append(record)
    out = {}
    for key, group in sorted(groups.items()):
        widths = np.array([float(r["width_px"]) for r in group])
        correct = np.array([_truthy(r["correct"]) for r in group], dtype=float)
        which = np.digitize(widths, edges) - 1
        counts = np.array([(which == b).sum() for b in range(len(bins_px))])
        acc = np.array([correct[which == b].mean() if counts[b] else np.nan for b in range(len(bins_px))])
        out[key] = (edges[:-1], acc, counts)
    return out


def write_plate_width_chart(records: list[dict], path: Path, bins_px: Sequence[int] = WIDTH_BINS_PX,
                            ceilings: Mapping[str, tuple[np.ndarray, np.ndarray]] | None = None) -> Path:
    """Write ``plate_width_figure`` to ``path`` (a PNG); returns ``path``."""
    return save_figure(plate_width_figure(records, bins_px, ceilings), path, dpi=100)


def plate_width_figure(records: list[dict], bins_px: Sequence[int] = WIDTH_BINS_PX,
                       ceilings: Mapping[str, tuple[np.ndarray, np.ndarray]] | None = None) -> Figure:
    """Plate accuracy (0-1) against plate width (px, log axis): one panel per lens (the sharp
    reference first), one line per reader chain in it.

    Each point sits at the geometric centre of its width bin (the open last bin at 1.25 x its
    left edge); empty bins are left out. ``ceilings`` (lens -> (widths px, Fano ceiling)) are drawn
    dashed in their lens's panel: no attacker may read more than that (lenses.bound).
    """
    if not records:
        raise ValueError("no plate records to chart: pass the per-plate dicts of plates.csv")
    curves = width_accuracy(records, bins_px)
    edges = list(bins_px)
    centres = np.array([np.sqrt(lo * hi) for lo, hi in zip(edges[:-1], edges[1:])] + [edges[-1] * 1.25])
    lenses = sorted({lens for lens, _ in curves}, key=lambda name: (name != "sharp", name))
    ncols = min(3, len(lenses))
    nrows = -(-len(lenses) // ncols)
    fig = new_figure(figsize=(5.2 * ncols, 3.6 * nrows))
    axes = fig.subplots(nrows, ncols, squeeze=False, sharey=True)
    for ax, lens in zip(axes.flat, lenses):
        for (name, attack), (_, acc, counts) in curves.items():
            if name == lens:
                keep = counts > 0
                ax.plot(centres[keep], acc[keep], marker="o", ms=4, label=f"{attack} (n={int(counts.sum())})")
        if ceilings and lens in ceilings:
            widths, ceiling = ceilings[lens]
            ax.plot(widths, ceiling, "k--", lw=1.0, label="ceiling for any attacker (bound)")
        ax.set_xscale("log")
        ax.set_xticks(edges)
        ax.set_xticklabels([str(e) for e in edges])
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.set_ylim(-0.02, 1.02)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=6, loc="upper left")
        ax.set_title(lens, fontsize=10)
    for ax in axes.flat[len(lenses):]:
        ax.set_visible(False)
    for ax in axes[-1]:
        ax.set_xlabel("plate width (px, bin left edge)")
    for ax in axes[:, 0]:
        ax.set_ylabel("plate accuracy")
    fig.suptitle("Licence-plate accuracy against plate width")
    return fig


def _truthy(value: object) -> bool:
    """A ``correct`` field from a dict or from plates.csv ("True" / "False" / "1" / "0")."""
    if isinstance(value, str):
        return value.strip().lower() in ("true", "1", "yes")
    return bool(value)
