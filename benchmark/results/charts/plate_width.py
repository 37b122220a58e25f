"""Plate accuracy against plate width: one panel per lens, one line per reader chain (at most ~6, the
rest grouped), Wilson 95 % error bars, the legend beside each panel."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import textwrap

import matplotlib
import matplotlib.ticker
import numpy as np
from matplotlib.container import ErrorbarContainer
from matplotlib.figure import Figure

from benchmark.results.charts import new_figure, save_figure
from benchmark.results.charts.point_labels import wrap_label
from benchmark.results.plate_scoring import WIDTH_BINS_PX
from benchmark.results.stats import wilson_interval

__all__ = ["panel_chains", "plate_width_figure", "width_accuracy", "write_plate_width_chart"]


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
    return save_figure(plate_width_figure(records, bins_px, ceilings), path, dpi=DPI, layout=False)


# Drawn at DPI and shown about 1000 px wide, the figure's inches are about its inches on a page: the fonts
# below are their printed size. Panel geometry in inches: the legend sits right of each panel, outside it.
DPI = 100
FONT_PT, LEGEND_PT, NOTE_PT = 10.0, 8.5, 8.5
_LEFT_IN, _AXES_W_IN, _GAP_IN, _LEGEND_W_IN = 0.8, 4.9, 0.2, 3.7
_HEADER_IN, _PANEL_TOP_IN, _PANEL_BOTTOM_IN, _NOTE_IN, _MIN_AXES_H_IN = 0.45, 0.3, 0.55, 0.55, 2.5
# At most this many chains are drawn per panel; past it the strongest MAX_CHAINS - 1 are drawn and the
# others become one grey range, so that no panel carries more than ~6 lines.
MAX_CHAINS = 6
# tab10 without its grey (index 7): grey is the "other chains" range's.
PALETTE = tuple(matplotlib.colormaps["tab10"](i) for i in range(10) if i != 7)
_MARKERS = "os^Dv<P"


def chain_strength(acc: np.ndarray, counts: np.ndarray) -> float:
    """A chain's accuracy over all its plates (the count-weighted mean of its bins)."""
    keep = counts > 0
    return float((acc[keep] * counts[keep]).sum() / counts[keep].sum()) if keep.any() else 0.0


def panel_chains(curves: Mapping[tuple[str, str], tuple[np.ndarray, np.ndarray, np.ndarray]], lens: str,
                 max_chains: int = MAX_CHAINS) -> tuple[list[str], list[str]]:
    """(chains drawn, chains grouped) of ``lens``'s panel: all of them when there are at most
    ``max_chains``, else the ``max_chains - 1`` strongest (by ``chain_strength``, then name) drawn and
    the rest grouped."""
    chains = sorted((attack for name, attack in curves if name == lens),
                    key=lambda a: (-chain_strength(curves[(lens, a)][1], curves[(lens, a)][2]), a))
    if len(chains) <= max_chains:
        return chains, []
    return chains[:max_chains - 1], chains[max_chains - 1:]


def _wilson_errors(acc: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """(2, n) distances from each accuracy to its Wilson 95 % interval's ends."""
    bounds = np.array([wilson_interval(int(round(a * n)), int(n)) for a, n in zip(acc, counts)]).reshape(-1, 2)
    return np.stack([acc - bounds[:, 0], bounds[:, 1] - acc]).clip(min=0)


def plate_width_figure(records: list[dict], bins_px: Sequence[int] = WIDTH_BINS_PX,
                       ceilings: Mapping[str, tuple[np.ndarray, np.ndarray]] | None = None,
                       max_chains: int = MAX_CHAINS) -> Figure:
    """Plate accuracy (0-1) against plate width (px, log axis): one panel per lens (the sharp
    reference first), its legend beside it, one line per reader chain with Wilson 95 % error bars.

    Each point sits at the geometric centre of its width bin (the open last bin at 1.25 x its
    left edge), the chains of a panel nudged apart so their error bars stay distinct; empty bins
    are left out. A panel with more than ``max_chains`` chains draws the strongest ``max_chains - 1``
    and shows the others as one grey range (their lowest to highest accuracy per bin). Colours never
    repeat within a panel, and a chain keeps its colour across panels while the drawn chains fit the
    palette. ``ceilings`` (lens -> (widths px, Fano ceiling)) are drawn dashed in their lens's panel:
    no attacker may read more than that (lenses.bound).
    """
    if not records:
        raise ValueError("no plate records to chart: pass the per-plate dicts of plates.csv")
    curves = width_accuracy(records, bins_px)
    edges = list(bins_px)
    centres = np.array([np.sqrt(lo * hi) for lo, hi in zip(edges[:-1], edges[1:])] + [edges[-1] * 1.25])
    lenses = sorted({lens for lens, _ in curves}, key=lambda name: (name != "sharp", name))
    panels = {lens: panel_chains(curves, lens, max_chains) for lens in lenses}
    drawn = list(dict.fromkeys(a for shown, _ in panels.values() for a in shown))
    shared = len(drawn) <= len(PALETTE)  # one colour per chain across panels, else per panel
    line_in = LEGEND_PT * 1.5 / 72
    heights = []
    for lens in lenses:
        shown, grouped = panels[lens]
        lines = sum(wrap_label(f"{a} (n=0000)").count("\n") + 1 for a in shown) + bool(grouped) * 2 + 1
        heights.append(max(_MIN_AXES_H_IN, lines * line_in + 0.3))
    width = _LEFT_IN + _AXES_W_IN + _GAP_IN + _LEGEND_W_IN
    total = _HEADER_IN + sum(h + _PANEL_TOP_IN + _PANEL_BOTTOM_IN for h in heights) + _NOTE_IN
    fig = new_figure(figsize=(width, total))
    top = total - _HEADER_IN
    x_low, x_high = edges[0] / 1.12, centres[-1] * 1.12
    for lens, axes_h in zip(lenses, heights):
        shown, grouped = panels[lens]
        bottom = top - _PANEL_TOP_IN - axes_h
        ax = fig.add_axes((_LEFT_IN / width, bottom / total, _AXES_W_IN / width, axes_h / total))
        top = bottom - _PANEL_BOTTOM_IN
        if grouped:
            accs = np.array([curves[(lens, a)][1] for a in grouped])
            has = np.array([curves[(lens, a)][2] > 0 for a in grouped])
            keep = has.any(axis=0)
            low = np.where(has, accs, np.inf).min(axis=0)
            high = np.where(has, accs, -np.inf).max(axis=0)
            ax.fill_between(centres[keep], low[keep], high[keep], color="0.55", alpha=0.3, lw=0,
                            label=wrap_label(f"{len(grouped)} other chains: range of their accuracy"))
        for k, attack in enumerate(shown):
            _, acc, counts = curves[(lens, attack)]
            keep = counts > 0
            colour = PALETTE[(drawn.index(attack) if shared else k) % len(PALETTE)]
            nudge = np.exp(0.035 * (k - (len(shown) - 1) / 2))
            ax.errorbar(centres[keep] * nudge, acc[keep], yerr=_wilson_errors(acc[keep], counts[keep]),
                        marker=_MARKERS[k % len(_MARKERS)], ms=4.5, lw=1.3, elinewidth=0.9, capsize=2.5,
                        color=colour, label=wrap_label(f"{attack} (n={int(counts.sum())})"))
        if ceilings and lens in ceilings:
            widths, ceiling = ceilings[lens]
            ax.plot(widths, ceiling, "k--", lw=1.1, label=wrap_label("ceiling for any attacker (Fano bound)"))
        ax.set_xscale("log")
        ax.set_xlim(x_low, x_high)
        ax.set_xticks(edges)
        ax.set_xticklabels([str(e) for e in edges])
        ax.xaxis.set_minor_locator(matplotlib.ticker.NullLocator())
        ax.set_ylim(-0.03, 1.03)
        ax.grid(True, alpha=0.3)
        ax.tick_params(labelsize=FONT_PT - 1)
        ax.set_xlabel("plate width (px; ticks at bin edges)", fontsize=FONT_PT - 1)
        ax.set_ylabel("plate accuracy", fontsize=FONT_PT)
        ax.set_title(f"lens: {lens}", fontsize=FONT_PT + 1, loc="left")
        handles, labels = ax.get_legend_handles_labels()
        order = sorted(range(len(labels)), key=lambda i: (not isinstance(handles[i], ErrorbarContainer), i))
        ax.legend([handles[i] for i in order], [labels[i] for i in order], loc="upper left",
                  bbox_to_anchor=(1.0 + _GAP_IN / _AXES_W_IN, 1.0), borderaxespad=0.0,
                  fontsize=LEGEND_PT, frameon=False, handlelength=2.2)
    fig.suptitle("Licence-plate accuracy against plate width", fontsize=FONT_PT + 2, x=_LEFT_IN / width,
                 y=1 - 0.12 / total, ha="left", va="top")
    fig.text(_LEFT_IN / width, 0.1 / total, "\n".join(textwrap.wrap(
        "Points: accuracy per plate-width bin (pooled over seeds and scenes) with its Wilson 95 % interval; "
        "n = plates read. A panel with more than "
        f"{max_chains} chains draws its {max_chains - 1} strongest (by accuracy over all plates) and shows the "
        "others as a grey range.", 125)), fontsize=NOTE_PT, color="0.25", ha="left", va="bottom")
    return fig


def _truthy(value: object) -> bool:
    """A ``correct`` field from a dict or from plates.csv ("True" / "False" / "1" / "0")."""
    if isinstance(value, str):
        return value.strip().lower() in ("true", "1", "yes")
    return bool(value)
