"""The reference of the batched plate reader's tests and benchmark: ``attacks.plates.ocr.read_plates`` as it
was before it batched (commit 34064c6), i.e. EasyOCR's public ``Reader.recognize`` on one canvas of the
prepared crops, which reads them one box at a time on the CPU. tests/ is on sys.path through its conftest.py.
"""

from __future__ import annotations

import numpy as np

from attacks.plates import ocr as plate_ocr


def recognize_one_at_a_time(ocr, crops_rgb, plate_format=None):
    """Per crop, the OcrResult that EasyOCR's ``recognize`` gives it (one recognizer pass per crop)."""
    results = [plate_ocr.OcrResult("", "", 0.0)] * len(crops_rgb)
    rows = {i: plate_ocr.prepare_crop(c) for i, c in enumerate(crops_rgb) if c.ndim == 3 and min(c.shape[:2]) >= 2}
    if not rows:
        return results
    order = list(rows)
    height = plate_ocr.OCR_HEIGHT_PX
    canvas = np.full((height * len(order), max(r.shape[1] for r in rows.values())), 255, np.uint8)
    boxes = []
    for slot, i in enumerate(order):
        row = rows[i]
        canvas[slot * height:slot * height + row.shape[0], :row.shape[1]] = row
        boxes.append([0, row.shape[1], slot * height, slot * height + row.shape[0]])
    lines = ocr.recognize(canvas, horizontal_list=boxes, free_list=[], allowlist=plate_ocr.PLATE_ALPHABET, detail=1,
                          batch_size=len(boxes))
    best: dict[int, tuple[str, float]] = {}
    for box, raw, score in lines:
        slot = int(box[0][1]) // height
        if slot not in best or float(score) > best[slot][1]:
            best[slot] = (raw, float(score))
    for slot, (raw, score) in best.items():
        results[order[slot]] = plate_ocr.OcrResult(plate_ocr.apply_format(plate_ocr.normalise(raw), plate_format),
                                                   raw, score)
    return results
