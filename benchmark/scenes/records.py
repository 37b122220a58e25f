"""The scene record every stage of the benchmark consumes, with its plate and vehicle ground truth."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

Box = tuple[int, int, int, int]
"""(x1, y1, x2, y2) in pixels; (x2, y2) is the first pixel past the box, so width = x2 - x1."""


@dataclass(frozen=True)
class Plate:
    """Ground truth of one licence plate.

    ``text`` is uppercase ``[A-Z0-9]`` without spaces. ``box_xyxy`` is clipped to the image.
    ``visible_fraction`` is the fraction of the whole plate's pixels that are inside the image
    and not occluded by nearer objects. ``vehicle_index`` indexes ``Scene.vehicles``.
    ``mirrored`` marks a horizontally flipped plate, whose text no reader should be scored on.
    """

    text: str
    box_xyxy: Box
    vehicle_index: int
    visible_fraction: float
    mirrored: bool = False


@dataclass(frozen=True)
class Vehicle:
    """A vehicle (car, truck, bus, train, motorcycle or bicycle): Cityscapes train id and box."""

    train_id: int
    box_xyxy: Box


@dataclass
class Scene:
    """One scene.

    ``image``: (H, W, 3) float32 in [0, 1], scene radiance, treated as linear by the lenses.
    ``labels``: (H, W) uint8 Cityscapes train ids 0..18, 255 = ignore.
    ``plate_mask``: (H, W) uint8, ``k + 1`` where plate ``k`` is visible, else 0; ``None`` when
    the source has no per-pixel plate ground truth. Crops use it to keep ``visible_fraction`` exact.
    """

    image: np.ndarray
    labels: np.ndarray
    plates: list[Plate]
    vehicles: list[Vehicle]
    seed: int
    name: str
    plate_mask: np.ndarray | None = field(default=None, repr=False)
