"""A gallery of plate crops: what each source (sharp, sensor, restorers) shows and what was read from it,
with a caption saying how to read it."""

from __future__ import annotations

import textwrap
from collections.abc import Mapping, Sequence
from pathlib import Path

import torch
from matplotlib.figure import Figure

from attacks import PlateRead
from benchmark.results.charts import new_figure, save_figure
from benchmark.results.plate_scoring import readable, score_scene, scored
from benchmark.scenes import Scene

__all__ = ["plate_gallery_figure", "write_plate_gallery"]


DPI = 100
FONT_PT, READ_PT, NOTE_PT = 9.0, 9.0, 9.0
# Geometry in inches: a crop cell, the read under it, the column titles, the caption.
_CELL_W_IN, _CELL_H_IN, _READ_IN, _LEFT_IN, _HEADER_IN, _NOTE_LINE_IN = 2.2, 0.95, 0.3, 0.9, 0.75, 0.19
# At most this many sources side by side (about 1200 px); more go into further blocks below, each
# with its own column titles, so that the gallery stays legible at page width.
MAX_COLUMNS = 5
_BLOCK_GAP_IN = 0.45


def write_plate_gallery(images: Mapping[str, torch.Tensor], scenes: Sequence[Scene],
                        reads: Mapping[str, Sequence[Sequence[PlateRead]]], path: Path,
                        max_plates: int = 8, context: float = 0.6, reader: str | None = None) -> Path:
    """Write ``plate_gallery_figure`` (same arguments) to ``path`` (a PNG); returns ``path``."""
    return save_figure(plate_gallery_figure(images, scenes, reads, max_plates, context, reader), path, dpi=DPI,
                       layout=False)


def plate_gallery_figure(images: Mapping[str, torch.Tensor], scenes: Sequence[Scene],
                         reads: Mapping[str, Sequence[Sequence[PlateRead]]], max_plates: int = 8,
                         context: float = 0.6, reader: str | None = None) -> Figure:
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

        reader: The reader's name, for the title.

    Columns are titled with their source (at most MAX_COLUMNS side by side, further sources in blocks
    below); under each crop is what was read there (green when it
    equals the truth, red otherwise, "-" for nothing read); each row is labelled with the true text
    and the plate's width; a caption under the grid says so.
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
    blocks = [sources[b:b + MAX_COLUMNS] for b in range(0, len(sources), MAX_COLUMNS)]
    width = _LEFT_IN + _CELL_W_IN * len(blocks[0]) + 0.1
    caption = "\n".join(textwrap.wrap(
        "Columns: the sharp scene, the sensor image and each restorer's output, cropped around one plate "
        f"(rows: the widest readable plates first; left: the true text and the plate's width in px). Under a crop: "
        f"what {reader or 'the reader'} read there, green when it is exactly the true text, red when it is not, "
        "'-' when nothing was read there.", int((width - 0.2) * 72 / (0.56 * NOTE_PT))))
    note_h = (caption.count("\n") + 1) * _NOTE_LINE_IN + 0.2
    row_h = _CELL_H_IN + _READ_IN
    block_h = row_h * len(plates) + _BLOCK_GAP_IN
    height = _HEADER_IN + block_h * len(blocks) - _BLOCK_GAP_IN + note_h
    fig = new_figure(figsize=(width, height))
    for row, (i, k, plate) in enumerate(plates):
        x0, y0, x1, y1 = plate.box_xyxy
        pad = max(4, round(context * (x1 - x0)))
        for block, col, name in ((b, c, n) for b, names in enumerate(blocks) for c, n in enumerate(names)):
            image = images[name][i].detach().float().clamp(0, 1).permute(1, 2, 0).cpu().numpy()
            h, w = image.shape[:2]
            bottom = height - _HEADER_IN - block_h * block - row_h * row - _CELL_H_IN
            ax = fig.add_axes(((_LEFT_IN + _CELL_W_IN * col + 0.05) / width, bottom / height,
                               (_CELL_W_IN - 0.1) / width, _CELL_H_IN / height))
            ax.imshow(image[max(0, y0 - pad):min(h, y1 + pad), max(0, x0 - pad):min(w, x1 + pad)],
                      interpolation="nearest", aspect="auto")
            ax.set_xticks([])
            ax.set_yticks([])
            if row == 0:
                ax.set_title(name, fontsize=FONT_PT, fontweight="bold")
            if col == 0:
                ax.set_ylabel(f"{plate.text}\n{x1 - x0} px", fontsize=FONT_PT)
            if name in texts:
                read = texts[name].get((i, k), "")
                ax.set_xlabel(read or "-", fontsize=READ_PT, labelpad=2, family="monospace",
                              color="green" if read == plate.text else "red")
    fig.suptitle(f"Plates read by {reader}" if reader else "Plates read", fontsize=FONT_PT + 2,
                 x=_LEFT_IN / width, y=1 - 0.08 / height, ha="left", va="top")
    fig.text(0.1 / width, 0.1 / height, caption, fontsize=NOTE_PT, color="0.2", ha="left", va="bottom")
    return fig


def _read_texts(scenes: Sequence[Scene], per_image: Sequence[Sequence[PlateRead]]) -> dict[tuple[int, int], str]:
    """(scene index, plate index) -> text the runner's scoring matched to that scored plate."""
    texts = {}
    for i, (scene, image_reads) in enumerate(zip(scenes, per_image)):
        scored_ids = [k for k, p in enumerate(scene.plates) if scored(p)]
        for k, outcome in zip(scored_ids, score_scene(list(image_reads), scene)):
            texts[(i, k)] = outcome.read
    return texts

