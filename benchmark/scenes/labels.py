"""Cityscapes train ids, class names and colours (from ``cityscapesscripts``)."""

from __future__ import annotations

import numpy as np
from cityscapesscripts.helpers.labels import labels as _cityscapes_labels

IGNORE_ID: int = 255
"""Label of unlabelled pixels, as in Cityscapes' train-id maps."""

CLASS_NAMES: tuple[str, ...] = tuple(
    label.name
    for label in sorted(_cityscapes_labels, key=lambda label: label.trainId)
    if 0 <= label.trainId < IGNORE_ID
)
"""The 19 evaluated classes, indexed by train id (0 = road ... 18 = bicycle)."""

TRAIN_ID: dict[str, int] = {name: i for i, name in enumerate(CLASS_NAMES)}
"""Class name -> train id."""

PALETTE: np.ndarray = np.array(
    [
        next(label.color for label in _cityscapes_labels if label.trainId == i)
        for i in range(len(CLASS_NAMES))
    ],
    dtype=np.uint8,
)
"""(19, 3) uint8 Cityscapes colour of each train id, for visualising label maps."""


def colorize(labels: np.ndarray) -> np.ndarray:
    """Map an (H, W) uint8 train-id map to (H, W, 3) uint8 Cityscapes colours (ignore = black)."""
    lut = np.zeros((256, 3), dtype=np.uint8)
    lut[: len(PALETTE)] = PALETTE
    return lut[labels]
