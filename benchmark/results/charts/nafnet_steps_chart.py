"""Chart of the known-pairs NAFNet step study (``benchmark/studies/nafnet_steps_study.py``): held-out PSNR
against fit steps and against fit seconds, with the chosen and the profile's step budget marked."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from matplotlib.figure import Figure

from benchmark.results.charts import new_figure, save_figure


def nafnet_steps_figure(study: dict[str, Any]) -> Figure:
    """Two panels (held-out PSNR dB vs steps, vs fit seconds) of one long fit's checkpoints (the training
    batches' PSNR stays in the study JSON: it is noisy and on another scale)."""
    records = sorted(study["records"], key=lambda r: r["step"])
    fig = new_figure(figsize=(10, 4.2))
    axes = fig.subplots(1, 2, sharey=True)
    marks = {"chosen": study.get("chosen_steps"), "profile default": study.get("profile_steps")}
    for ax, key, label in ((axes[0], "step", "fit steps"), (axes[1], "fit_s", "fit seconds (training only)")):
        ax.plot([r[key] for r in records], [r["psnr_db"] for r in records], "o-", ms=4, label="held-out val")
        for (name, step), style in zip(marks.items(), ("C3", "C2")):
            hit = [r for r in records if r["step"] == step]
            if hit:
                ax.plot(hit[0][key], hit[0]["psnr_db"], "o", ms=12, mfc="none", color=style, label=f"{name}: {step}")
        ax.set_xlabel(label)
        ax.grid(alpha=0.3)
    crop = (study.get("eval") or {}).get("crop_hw")
    axes[0].set_ylabel("held-out PSNR dB (val scenes)")
    axes[0].legend(fontsize=7)
    rule = study.get("rule", {}).get("text", "")
    profile = study.get("profile", {}).get("name", "?")
    scored = f"{crop[0]}x{crop[1]} centre crops of the val scenes" if crop else "whole val scenes"
    fig.suptitle(f"nafnet-known-pairs on {study.get('lens')} ({profile} profile, seed {study.get('seed')}): checkpoints of "
                 f"one fit, scored on {scored}\ndefault = {rule}", fontsize=9)
    return fig


def write_nafnet_steps_chart(study: dict[str, Any], path: Path | str) -> Path:
    """Save ``nafnet_steps_figure(study)`` as a PNG at ``path``."""
    return save_figure(nafnet_steps_figure(study), path, layout=(0, 0, 1, 0.9))
