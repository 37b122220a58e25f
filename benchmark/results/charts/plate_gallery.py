"""A gallery of plate crops: what each source (sharp, sensor, restorers) shows and what was read from it."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import torch
from matplotlib.figure import Figure

from attacks import PlateRead
from benchmark.results.charts import new_figure, save_figure
from benchmark.results.plate_scoring import readable, score_scene
from benchmark.scenes import Scene

__all__ = ["plate_gallery_figure", "write_plate_gallery"]


def write_plate_gallery(images: Mapping[str, torch.Tensor], scenes: Sequence[Scene],
                        reads: Mapping[str, Sequence[Sequence[PlateRead]]], path: Path,
                        max_plates: int = 8, context: float = 0.6) -> Path:
    """Write ``plate_gallery_figure`` (same arguments) to ``path`` (a PNG); returns ``path``."""
    return save_figure(plate_gallery_figure(images, scenes, reads, max_plates, context), path, dpi=110)


def plate_gallery_figure(images: Mapping[str, torch.Tensor], scenes: Sequence[Scene],
                         reads: Mapping[str, Sequence[Sequence[PlateRead]]], max_plates: int = 8,
                         context: float = 0.6) -> Figure:
    """Grid of plate crops: one row per plate (widest readable plates first), one column per source.

    Args:
        images: Source name -> images (N, 3, H, W) in [0, 1], e.g. {"sharp": ..., "sensor": ...,
            "nafnet-known-pairs": ...}, all aligned with ``scenes``.
        scenes: The N scenes (their plates are the ground truth).
        reads: Source name -> per image the reads a reader made on that source (``Reader.read``);
            a source without reads is shown without text.
        max_plates: At most this many rows.
        context: The crop extends the plate box by this fraction of its width on each side
            (and as many pixels vertically), so blur spreading out of the plate stays visible.

    Each cell is titled with what was read (green when it equals the truth, red otherwise).
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
    fig = new_figure(figsize=(2.2 * len(sources), 1.2 * len(plates) + 0.4))
    axes = fig.subplots(len(plates), len(sources), squeeze=False)
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
    return fig


def _read_texts(scenes: Sequence[Scene], per_image: Sequence[Sequence[PlateRead]]) -> dict[tuple[int, int], str]:
    """(scene index, plate index) -> text the runner's scoring matched to that readable plate."""
    texts = {}
    for i, (scene, image_reads) in enumerate(zip(scenes, per_image)):
        readable_ids = [k for k, p in enumerate(scene.plates) if readable(p)]
        for k, outcome in zip(readable_ids, score_scene(list(image_reads), scene)):
            texts[(i, k)] = outcome.read
    return texts

