"""Utility and the ensemble's PSNR of each lens per training profile (smoke vs quick vs paper), the tables' figures."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from matplotlib.figure import Figure

from benchmark.results import pooled
from benchmark.results.charts import new_figure, save_figure
from benchmark.results.ensemble import scene_ensemble
from benchmark.results.entries import Entry

PROFILE_ORDER = ("smoke", "quick", "paper")


def utility_params(variant: str) -> int:
    """Parameter count of the SegFormer variant a profile trains (built offline, random weights)."""
    from benchmark.codesign.utility.segformer import build_segformer
    return sum(p.numel() for p in build_segformer(variant).parameters())


def profile_figure(entries: Sequence[Entry]) -> Figure | None:
    """Lenses measured under more than one profile; the x labels name each profile's utility model
    and its size, which grows with the budget. None when no lens has two profiles."""
    by_lens: dict[str, dict[str, tuple[float, float]]] = {}
    models: dict[str, str] = {}
    for e in entries:
        util, scenes = pooled.miou(e), scene_ensemble(e.rows, "psnr_db")
        if util is not None and scenes is not None:
            by_lens.setdefault(e.lens, {})[e.profile] = (util.value, scenes.mean)
            models[e.profile] = e.profile_values["utility_model"]
    by_lens = {k: v for k, v in by_lens.items() if len(v) > 1}
    if not by_lens:
        return None
    order = [p for p in PROFILE_ORDER if p in models]
    ticks = [f"{p}\n{models[p]}, {utility_params(models[p]) / 1e6:.2f} M params" for p in order]
    fig = new_figure(figsize=(10, 4))
    axes = fig.subplots(1, 2)
    for lens, per in sorted(by_lens.items()):
        xs = [order.index(p) for p in order if p in per]
        axes[0].plot(xs, [per[order[x]][0] for x in xs], "o-", label=lens)
        axes[1].plot(xs, [per[order[x]][1] for x in xs], "o-", label=lens)
    axes[0].set_ylabel("mIoU")
    axes[1].set_ylabel("ensemble PSNR dB (each scene at its best restorer)")
    for ax in axes:
        ax.set_xticks(range(len(order)), ticks, fontsize=8)
        ax.set_xlabel("profile (training budget, utility model)")
        ax.grid(alpha=0.3)
    axes[1].legend(fontsize=7)
    return fig


def write_profile_chart(entries: Sequence[Entry], path: Path) -> Path | None:
    fig = profile_figure(entries)
    return None if fig is None else save_figure(fig, path, dpi=100)
