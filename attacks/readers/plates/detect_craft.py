"""Stage 2 (pretrained): plate candidates from EasyOCR's CRAFT text detector.

CRAFT finds text, not plates; on a vehicle crop the text it finds is the plate (or a badge),
and the text box is exactly what the recognizer needs. Small vehicles are magnified before
detection so that plate characters reach the few pixels CRAFT needs to fire.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["detect_craft", "magnification"]

Box = tuple[int, int, int, int]


def magnification(crop_width_px: int, target_width_px: int = 320, max_mag: float = 4.0) -> float:
    """Upscale factor bringing a crop to ``target_width_px`` (never below 1, at most ``max_mag``)."""
    return float(min(max_mag, max(1.0, target_width_px / max(crop_width_px, 1))))


def detect_craft(ocr: Any, crop_rgb: np.ndarray, target_width_px: int = 320, max_mag: float = 4.0,
                 text_threshold: float = 0.7, low_text: float = 0.4, width_ths: float = 1.5) -> list[Box]:
    """Text boxes in one vehicle crop, by CRAFT.

    Args:
        ocr: An ``easyocr.Reader`` with its detector loaded.
        crop_rgb: (h, w, 3) uint8 RGB vehicle crop; an empty crop gives no boxes.
        target_width_px, max_mag: Magnification before detection (``magnification``).
        text_threshold, low_text: CRAFT's character and text-region score thresholds.
        width_ths: Boxes on one line closer than this many box heights merge into one: a plate
            is one line, and CRAFT often splits a wide proportional glyph ('T', 'W') off its
            neighbours (EasyOCR's default, 0.5, lost the first letter of 3 of 5 large plates).

    Returns:
        Boxes (x0, y0, x1, y1) in crop pixels, clipped to the crop, widest first.
    """
    h, w = crop_rgb.shape[:2]
    if h < 4 or w < 4:
        return []
    horizontal, _ = ocr.detect(crop_rgb, min_size=0, text_threshold=text_threshold, low_text=low_text,
                               mag_ratio=magnification(w, target_width_px, max_mag), width_ths=width_ths)
    boxes = [(max(0, int(b[0])), max(0, int(b[2])), min(w, int(b[1])), min(h, int(b[3]))) for b in horizontal[0]]
    return sorted((b for b in boxes if b[2] > b[0] and b[3] > b[1]), key=lambda b: b[0] - b[2])
