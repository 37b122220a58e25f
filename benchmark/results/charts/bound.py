"""Chart of the privacy bound: ceiling on any attacker's plate accuracy against plate width, per lens."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from benchmark.results.charts import new_figure, save_figure
from lenses.bound import ASSUMPTIONS


def write_bound_chart(curves: dict[str, tuple[np.ndarray, np.ndarray]], path: Path, eps: float | None = 0.05) -> Path:
    """PNG of the Fano accuracy ceiling (0-1) against plate width (px, log axis), one line per lens.

    `curves` maps a lens name to (widths_px, ceiling) arrays, e.g. from `lenses.bound.bound_curve`.
    A dotted line marks `eps`. Returns `path`; the caption
    states that these are upper bounds under `lenses.bound.ASSUMPTIONS`.
    """
    if not curves:
        raise ValueError("no bound curves to chart: pass {lens name: (widths_px, ceiling)}")
    fig = new_figure(figsize=(6.4, 4.2))
    ax = fig.subplots()
    for name, (widths, ceiling) in curves.items():
        widths, ceiling = np.asarray(widths), np.asarray(ceiling)
        if widths.shape != ceiling.shape:
            raise ValueError(f"lens {name!r}: widths {widths.shape} and ceiling {ceiling.shape} differ in shape")
        ax.plot(widths, ceiling, marker=".", label=f"{name} (bound)")
    if eps is not None:
        ax.axhline(eps, color="grey", linestyle=":", linewidth=1, label=f"eps = {eps:g}")
    ax.set_xscale("log", base=2)
    ax.set_ylim(0, 1.05)
    ax.set_xlabel("plate width (px)")
    ax.set_ylabel("plate accuracy ceiling, any attacker")
    ax.set_title("Attack-independent ceiling (Fano), upper bound", fontsize=10)
    ax.legend(fontsize=8, loc="lower right")
    ax.grid(True, which="both", alpha=0.3)
    fig.text(0.01, 0.005, "Under the assumptions of lenses.bound.ASSUMPTIONS; an upper bound, not a prediction.",
             fontsize=6, color="grey")
    return save_figure(fig, path, dpi=100, metadata={"Description": ASSUMPTIONS}, layout=(0, 0.03, 1, 1))
