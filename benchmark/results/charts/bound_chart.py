"""Chart of the privacy bound: ceiling on any attacker's plate accuracy against plate width, per lens."""

from __future__ import annotations

import textwrap
from pathlib import Path

import matplotlib
import matplotlib.ticker
import numpy as np
from matplotlib.figure import Figure

from benchmark.results.charts import new_figure, save_figure
from lenses.bound import ASSUMPTIONS


# Shown about 1000 px wide at DPI: the fonts are their printed size. Geometry in inches.
DPI = 100
FONT_PT, LEGEND_PT, NOTE_PT = 10.0, 9.0, 9.0
_LEFT_IN, _AXES_W_IN, _LEGEND_W_IN, _TOP_IN, _AXES_H_IN, _BOTTOM_IN, _NOTE_LINE_IN = 0.85, 5.4, 2.9, 0.45, 3.4, 0.6, 0.2
_NOTE_CHARS = 115


def saturation_width(curves: dict[str, tuple[np.ndarray, np.ndarray]]) -> float | None:
    """The narrowest width from which every lens's ceiling stays at 1 (the bound allows every attacker
    every plate from there on); None when some lens stays below 1 at its widest width."""
    widths = []
    for w, c in curves.values():
        w, c = np.asarray(w, dtype=float), np.asarray(c, dtype=float)
        below = np.nonzero(c < 1.0 - 1e-9)[0]
        if len(below) and below[-1] == len(c) - 1:
            return None
        widths.append(w[below[-1] + 1] if len(below) else w[0])
    return max(widths) if widths else None


def bound_figure(curves: dict[str, tuple[np.ndarray, np.ndarray]], eps: float | None = 0.05) -> Figure:
    """The chart of ``write_bound_chart``. The width axis ends one octave past ``saturation_width`` (the
    flat stretch at 1 says nothing more), and a note under the axes says where the ceiling reaches 1."""
    if not curves:
        raise ValueError("no bound curves to chart: pass {lens name: (widths_px, ceiling)}")
    full = saturation_width(curves)
    notes = ["An attack-independent upper bound under the assumptions of lenses.bound.ASSUMPTIONS (Fano's "
             "inequality on the bits a plate can carry to any attacker), not a prediction: real readers and the "
             "ideal observer stay below it."]
    if full is not None:
        notes.append(f"From {full:g} px on the ceiling is 1 for every lens: there the bound certifies no privacy, "
                     f"and the widths past {2 * full:g} px are left out.")
    note = "\n".join(line for text in notes for line in textwrap.wrap(text, _NOTE_CHARS))
    note_h = (note.count("\n") + 1) * _NOTE_LINE_IN + 0.15
    width, height = _LEFT_IN + _AXES_W_IN + _LEGEND_W_IN, _TOP_IN + _AXES_H_IN + _BOTTOM_IN + note_h
    fig = new_figure(figsize=(width, height))
    ax = fig.add_axes((_LEFT_IN / width, (_BOTTOM_IN + note_h) / height, _AXES_W_IN / width, _AXES_H_IN / height))
    lowest = np.inf
    colours = [matplotlib.colormaps["tab10"](i) for i in range(10) if i != 7]
    for k, (name, (widths, ceiling)) in enumerate(curves.items()):
        widths, ceiling = np.asarray(widths, dtype=float), np.asarray(ceiling, dtype=float)
        if widths.shape != ceiling.shape:
            raise ValueError(f"lens {name!r}: widths {widths.shape} and ceiling {ceiling.shape} differ in shape")
        lowest = min(lowest, float(widths.min()))
        ax.plot(widths, ceiling, marker=".", ms=7, lw=1.5, color=colours[k % len(colours)], label=name)
    if eps is not None:
        ax.axhline(eps, color="0.4", linestyle=":", linewidth=1.2, label=f"eps = {eps:g} (W_5% threshold)")
    ax.set_xscale("log", base=2)
    ax.xaxis.set_major_formatter(matplotlib.ticker.ScalarFormatter())
    if full is not None:
        ax.set_xlim(lowest / 1.15, 2 * full * 1.15)
    ax.set_ylim(0, 1.05)
    ax.set_xlabel("plate width (px)", fontsize=FONT_PT)
    ax.set_ylabel("ceiling on plate accuracy,\nany attacker", fontsize=FONT_PT)
    ax.set_title("Attack-independent ceiling (Fano bound) per lens", fontsize=FONT_PT + 1, loc="left")
    ax.tick_params(labelsize=FONT_PT - 1)
    ax.legend(fontsize=LEGEND_PT, loc="upper left", bbox_to_anchor=(1.03, 1.0), borderaxespad=0.0, frameon=False,
              title="lens", title_fontsize=LEGEND_PT, alignment="left")
    ax.grid(True, which="both", alpha=0.3)
    fig.text(_LEFT_IN / width, 0.1 / height, note, fontsize=NOTE_PT, color="0.2", ha="left", va="bottom")
    return fig


def write_bound_chart(curves: dict[str, tuple[np.ndarray, np.ndarray]], path: Path, eps: float | None = 0.05) -> Path:
    """PNG of the Fano accuracy ceiling (0-1) against plate width (px, log axis), one line per lens
    (``bound_figure``).

    `curves` maps a lens name to (widths_px, ceiling) arrays, e.g. from `lenses.bound.bound_curve`.
    A dotted line marks `eps`. Returns `path`; the note under the chart (and the PNG's Description)
    states that these are upper bounds under `lenses.bound.ASSUMPTIONS`.
    """
    return save_figure(bound_figure(curves, eps), path, dpi=DPI, metadata={"Description": ASSUMPTIONS}, layout=False)
