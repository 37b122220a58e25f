"""Stage 1 of the plate attack: where the vehicles are.

Two sources, both returning integer boxes ``(x0, y0, x1, y1)`` in pixels (x1, y1 exclusive):
``segmentation_vehicles`` finds connected components of car / truck / bus in a Cityscapes
train-id map (what a sensor-access attacker gets from a segmentation network), and
``oracle_vehicles`` takes the ground-truth boxes (the attacker's upper bound).
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

__all__ = ["PLATE_VEHICLE_TRAIN_IDS", "expand_box", "oracle_vehicles", "segmentation_vehicles"]

Box = tuple[int, int, int, int]

PLATE_VEHICLE_TRAIN_IDS = (13, 14, 15)
"""Cityscapes train ids of the vehicles that carry plates: car, truck, bus."""


def segmentation_vehicles(train_ids: np.ndarray, min_area_px: int = 64,
                          vehicle_ids: Sequence[int] = PLATE_VEHICLE_TRAIN_IDS) -> list[Box]:
    """Boxes of the 8-connected components of ``vehicle_ids`` in a train-id map.

    Args:
        train_ids: (H, W) integer Cityscapes train ids (255 = ignore).
        min_area_px: Components with fewer pixels are dropped as segmentation noise.
        vehicle_ids: Train ids that count as vehicles.

    Returns:
        One box per component, largest first. Touching vehicles merge into one box, which
        the plate detector then searches as a whole.
    """
    if train_ids.ndim != 2:
        raise ValueError(f"train_ids must be (H, W), got shape {train_ids.shape}")
    mask = np.isin(train_ids, list(vehicle_ids)).astype(np.uint8)
    n, _, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    boxes = [(int(x), int(y), int(x + w), int(y + h), int(a)) for x, y, w, h, a in stats[1:n] if a >= min_area_px]
    return [b[:4] for b in sorted(boxes, key=lambda b: -b[4])]


def oracle_vehicles(boxes: Sequence[Sequence[float]], image_hw: tuple[int, int]) -> list[Box]:
    """Ground-truth vehicle boxes, rounded outwards to whole pixels and clipped to the image.

    Args:
        boxes: (x0, y0, x1, y1) per vehicle, pixels.
        image_hw: (H, W) of the image, pixels.
    """
    clipped = (_clip((int(np.floor(b[0])), int(np.floor(b[1])), int(np.ceil(b[2])), int(np.ceil(b[3]))), image_hw)
               for b in boxes)
    return [b for b in clipped if b[2] > b[0] and b[3] > b[1]]


def expand_box(box: Box, margin: float, image_hw: tuple[int, int]) -> Box:
    """``box`` grown by ``margin`` times its width / height on every side, clipped to the image.

    The margin catches plates that stick out of a tight vehicle box (bumper, occlusion edge).
    """
    x0, y0, x1, y1 = box
    dx, dy = round(margin * (x1 - x0)), round(margin * (y1 - y0))
    return _clip((x0 - dx, y0 - dy, x1 + dx, y1 + dy), image_hw)


def _clip(box: Box, image_hw: tuple[int, int]) -> Box:
    h, w = image_hw
    return (min(max(box[0], 0), w), min(max(box[1], 0), h), min(max(box[2], 0), w), min(max(box[3], 0), h))
