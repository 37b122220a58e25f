"""Plate-reading charts: accuracy against plate width per chain, and a gallery of plate crops."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import matplotlib
import matplotlib.ticker

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402

from attacks import PlateRead  # noqa: E402
from benchmark.charts import save_figure  # noqa: E402
from benchmark.plates import WIDTH_BINS_PX, readable, score_scene  # noqa: E402
from benchmark.scenes import Scene  # noqa: E402

__all__ = ["width_accuracy", "write_plate_gallery", "write_plate_width_chart"]


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
    """PNG of plate accuracy (0-1) against plate width (px, log axis): one panel per lens (the sharp
    reference first), one line per reader chain in it.

    Each point sits at the geometric centre of its width bin (the open last bin at 1.25 x its
    left edge); empty bins are left out. ``ceilings`` (lens -> (widths px, Fano ceiling)) are drawn
    dashed in their lens's panel: no attacker may read more than that (lenses.bound). Returns ``path``.
    """
    if not records:
        raise ValueError("no plate records to chart: pass the per-plate dicts of plates.csv")
    curves = width_accuracy(records, bins_px)
    edges = list(bins_px)
    centres = np.array([np.sqrt(lo * hi) for lo, hi in zip(edges[:-1], edges[1:])] + [edges[-1] * 1.25])
    lenses = sorted({lens for lens, _ in curves}, key=lambda name: (name != "sharp", name))
    ncols = min(3, len(lenses))
    nrows = -(-len(lenses) // ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(5.2 * ncols, 3.6 * nrows), squeeze=False, sharey=True)
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
    return save_figure(fig, path, dpi=100)


def write_plate_gallery(images: Mapping[str, torch.Tensor], scenes: Sequence[Scene],
                        reads: Mapping[str, Sequence[Sequence[PlateRead]]], path: Path,
                        max_plates: int = 8, context: float = 0.6) -> Path:
    """PNG grid of plate crops: one row per plate (widest readable plates first), one column per source.

    Args:
        images: Source name -> images (N, 3, H, W) in [0, 1], e.g. {"sharp": ..., "sensor": ...,
            "nafnet-known-pairs": ...}, all aligned with ``scenes``.
        scenes: The N scenes (their plates are the ground truth).
        reads: Source name -> per image the reads a reader made on that source (``Reader.read``);
            a source without reads is shown without text.
        path: Where to write the PNG.
        max_plates: At most this many rows.
        context: The crop extends the plate box by this fraction of its width on each side
            (and as many pixels vertically), so blur spreading out of the plate stays visible.

    Each cell is titled with what was read (green when it equals the truth, red otherwise).
    Returns ``path``.
    """
    if not images:
        raise ValueError("no images for the gallery: pass {source name: (N, 3, H, W) tensor}")
    for name, batch in images.items():
        if batch.ndim != 4 or batch.shape[0] != len(scenes) or batch.shape[1] != 3:
            raise ValueError(f"images[{name!r}] has shape {tuple(batch.shape)}; expected ({len(scenes)}, 3, H, W)")
    plates = sorted(((i, k, p) for i, s in enumerate(scenes) for k, p in enumerate(s.plates) if readable(p)),
                    key=lambda ikp: ikp[2].box_xyxy[0] - ikp[2].box_xyxy[2])[:max_plates]
    if not plates:
        raise ValueError("the scenes have no readable plate to show")
    texts = {name: _read_texts(scenes, per_image) for name, per_image in reads.items()}
    sources = list(images)
    fig, axes = plt.subplots(len(plates), len(sources), figsize=(2.2 * len(sources), 1.2 * len(plates) + 0.4),
                             squeeze=False)
    for row, (i, k, plate) in enumerate(plates):
        x0, y0, x1, y1 = plate.box_xyxy
        pad = max(4, round(context * (x1 - x0)))
        for col, name in enumerate(sources):
            image = images[name][i].detach().float().clamp(0, 1).permute(1, 2, 0).cpu().numpy()
            h, w = image.shape[:2]
            ax = axes[row][col]
            ax.imshow(image[max(0, y0 - pad):min(h, y1 + pad), max(0, x0 - pad):min(w, x1 + pad)],
                      interpolation="nearest")
            ax.set_xticks([])
            ax.set_yticks([])
            if row == 0:
                ax.set_xlabel(name, fontsize=8)
                ax.xaxis.set_label_position("top")
            if col == 0:
                ax.set_ylabel(f"{plate.text}\n{x1 - x0} px", fontsize=7)
            if name in texts:
                read = texts[name].get((i, k), "")
                ax.set_title(read or "-", fontsize=8, color="green" if read == plate.text else "red")
    return save_figure(fig, path, dpi=110)


def _read_texts(scenes: Sequence[Scene], per_image: Sequence[Sequence[PlateRead]]) -> dict[tuple[int, int], str]:
    """(scene index, plate index) -> text the runner's scoring matched to that readable plate."""
    texts = {}
    for i, (scene, image_reads) in enumerate(zip(scenes, per_image)):
        readable_ids = [k for k, p in enumerate(scene.plates) if readable(p)]
        for k, outcome in zip(readable_ids, score_scene(list(image_reads), scene)):
            texts[(i, k)] = outcome.read
    return texts


def _truthy(value: object) -> bool:
    """A ``correct`` field from a dict or from plates.csv ("True" / "False" / "1" / "0")."""
    if isinstance(value, str):
        return value.strip().lower() in ("true", "1", "yes")
    return bool(value)
