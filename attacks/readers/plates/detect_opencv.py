"""Stage 2 (classical): plate candidates by OpenCV morphology, for comparison with CRAFT.

A plate is a light rectangle (about 4.7:1 for EU plates) on a darker vehicle, crossed by the
dense vertical edges of its characters. Candidates come from two masks, closed horizontally so
that the characters merge into one blob: bright regions (Otsu on max(R, G, B)) and strong
vertical edges (Sobel x, Otsu). Each candidate rectangle of plate-like aspect is scored by
its vertical-edge density times how much brighter it is than the ring around it.
"""

from __future__ import annotations

import cv2
import numpy as np

from attacks.readers.plates.detect_craft import magnification

__all__ = ["detect_opencv"]

Box = tuple[int, int, int, int]


def detect_opencv(crop_rgb: np.ndarray, target_width_px: int = 320, max_mag: float = 4.0,
                  aspect: tuple[float, float] = (2.0, 8.0), max_candidates: int = 1) -> list[Box]:
    """Plate-like boxes in one vehicle crop.

    Args:
        crop_rgb: (h, w, 3) uint8 RGB vehicle crop; an empty or flat crop gives no boxes.
        target_width_px, max_mag: Magnification before the morphology (as for CRAFT).
        aspect: Accepted width / height range of a candidate.
        max_candidates: At most this many boxes, best first, none overlapping another (IoU > 0.3).

    Returns:
        Boxes (x0, y0, x1, y1) in crop pixels, best first.
    """
    h, w = crop_rgb.shape[:2]
    if h < 4 or w < 4:
        return []
    mag = magnification(w, target_width_px, max_mag)
    big = cv2.resize(crop_rgb, (round(w * mag), round(h * mag)), interpolation=cv2.INTER_CUBIC)
    value = big.max(axis=2)
    if int(value.max()) - int(value.min()) < 16:
        return []
    gray = cv2.cvtColor(big, cv2.COLOR_RGB2GRAY)
    edges = np.abs(cv2.Sobel(gray, cv2.CV_32F, 1, 0, ksize=3))
    edges = cv2.convertScaleAbs(edges, alpha=255.0 / max(float(edges.max()), 1e-6))
    _, edge_mask = cv2.threshold(edges, 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
    _, bright_mask = cv2.threshold(value, 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
    # A character is ~3 % of a vehicle's width: closing over that merges a plate's characters.
    k = max(3, round(0.03 * big.shape[1]))
    close = cv2.getStructuringElement(cv2.MORPH_RECT, (k, max(1, k // 3)))
    scored: list[tuple[float, Box]] = []
    for mask in (edge_mask, bright_mask):
        merged = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, close)
        contours, _ = cv2.findContours(merged, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        for contour in contours:
            x, y, cw, ch = cv2.boundingRect(contour)
            if ch < 4 or not aspect[0] <= cw / ch <= aspect[1] or cw > 0.7 * big.shape[1]:
                continue
            scored.append((_score(value, edge_mask, (x, y, x + cw, y + ch)), (x, y, x + cw, y + ch)))
    chosen: list[Box] = []
    for score, box in sorted(scored, key=lambda sb: -sb[0]):
        if score <= 0 or len(chosen) == max_candidates:
            break
        if all(_iou(box, c) <= 0.3 for c in chosen):
            chosen.append(box)
    return [(int(b[0] / mag), int(b[1] / mag), min(w, int(np.ceil(b[2] / mag))), min(h, int(np.ceil(b[3] / mag))))
            for b in chosen]


def _score(value: np.ndarray, edge_mask: np.ndarray, box: Box) -> float:
    """Vertical-edge density inside ``box`` times its brightness above the surrounding ring (0..1)."""
    x0, y0, x1, y1 = box
    pad = max(2, (y1 - y0) // 2)
    ox0, oy0 = max(0, x0 - pad), max(0, y0 - pad)
    ox1, oy1 = min(value.shape[1], x1 + pad), min(value.shape[0], y1 + pad)
    inner = value[y0:y1, x0:x1].astype(np.float32)
    outer = value[oy0:oy1, ox0:ox1].astype(np.float32)
    ring_area = outer.size - inner.size
    if ring_area <= 0:
        return 0.0
    ring_mean = (outer.sum() - inner.sum()) / ring_area
    # The plate background (upper half of the brightness inside) is what must be light.
    background = float(np.percentile(inner, 75))
    density = float(edge_mask[y0:y1, x0:x1].mean()) / 255.0
    return density * max(0.0, background - ring_mean) / 255.0


def _iou(a: Box, b: Box) -> float:
    ix = max(0, min(a[2], b[2]) - max(a[0], b[0]))
    iy = max(0, min(a[3], b[3]) - max(a[1], b[1]))
    inter = ix * iy
    union = (a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter
    return inter / union if union else 0.0
