"""Chart of the clean utility pre-training: its learning curve and the per-class IoU it ends at."""

from __future__ import annotations

from typing import Any

import numpy as np
from matplotlib.figure import Figure

from benchmark.results.charts import new_figure

TARGET_MIOU = 0.5  # the target for the sharp-scene mIoU on `quick` (docs/modelling.md, "Clean utility net")


def pretrain_figure(provenance: dict[str, Any]) -> Figure:
    """Left: sharp val mIoU and train cross-entropy against step, with the plateau verdict; right: the
    per-class IoU of the weights as shipped. ``provenance`` is the JSON written by
    ``python -m benchmark pretrain`` (``leaderboard/studies/utility_pretrain.json``)."""
    curve = provenance["curve"]
    fig = new_figure(figsize=(12, 4.4))
    ax, bars = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1.1, 1]})
    steps = [p["step"] for p in curve]
    ax.plot(steps, [p["miou"] for p in curve], "o-", color="tab:blue", label="sharp val mIoU")
    ax.axhline(TARGET_MIOU, color="grey", ls=":", lw=1, label=f"target {TARGET_MIOU:.2f}")
    ax.set_xlabel("training step")
    ax.set_ylabel("mIoU")
    ax.set_ylim(0, max(TARGET_MIOU + 0.1, max(p["miou"] for p in curve) + 0.05))
    ax.grid(alpha=0.3)
    twin = ax.twinx()
    twin.plot(steps, [p["train_ce"] for p in curve], "s--", color="tab:orange", ms=3, label="train CE")
    twin.set_ylabel("train cross-entropy (mean since the previous point)")
    handles, labels = ax.get_legend_handles_labels()
    more_handles, more_labels = twin.get_legend_handles_labels()
    ax.legend(handles + more_handles, labels + more_labels, loc="lower right", fontsize=8)
    r, p = provenance["recipe"], provenance["plateau"]
    gain = "n/a" if p["gain_last_fifth"] is None else f"{p['gain_last_fifth']:+.3f}"
    verdict = "plateau reached" if p["reached"] else "no plateau"
    ax.set_title(f"SegFormer-{r['model']} clean pre-training ({provenance['profile']}): {r['n_train_scenes']} scenes, "
                 f"{r['crop'][0]}x{r['crop'][1]} crops, batch {r['batch_size']}, peak lr {r['lr_schedule']['peak']:g}\n"
                 f"last-fifth mIoU gain {gain} (criterion < {p.get('threshold', 0.01):g}): {verdict}", fontsize=9)
    iou = provenance["final_shipped"]["class_iou"]
    names = list(iou)
    values = [np.nan if iou[n] is None else iou[n] for n in names]
    bars.barh(range(len(names)), values, color="tab:blue")
    for row, value in enumerate(values):
        bars.text(0.01 if np.isnan(value) else value + 0.01, row, "not in val" if np.isnan(value) else f"{value:.2f}",
                  va="center", fontsize=7)
    bars.set_yticks(range(len(names)), names, fontsize=8)
    bars.invert_yaxis()
    bars.set_xlim(0, 1)
    bars.grid(axis="x", alpha=0.3)
    bars.set_xlabel(f"IoU on the sharp val scenes (weights as shipped, {provenance['file']['dtype']})")
    val = provenance["val"]
    bars.set_title(f"per-class IoU: mIoU {provenance['final_shipped']['miou']:.3f} on {val['n_scenes']} val scenes "
                   f"(seed {val['seed']}, {val['image_size'][0]}x{val['image_size'][1]})", fontsize=9)
    return fig
