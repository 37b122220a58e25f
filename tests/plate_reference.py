"""The reference of the batched plate reader's tests and benchmark: ``attacks.readers.plates.ocr.read_plates`` as it
was before it batched (2026-11-24), i.e. EasyOCR's public ``Reader.recognize`` on one canvas of the
prepared crops, which reads them one box at a time on the CPU. tests/ is on sys.path through its conftest.py.
"""

from __future__ import annotations

import numpy as np
import torch

import attacks
from attacks.readers.plates import ocr as plate_ocr
from benchmark.scenes import load_scenes


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


def plate_crop_rows(frames: int) -> dict[int, np.ndarray]:
    """lpdr-oracle's prepared plate crops of ``frames`` quick synthetic val frames, sharp and box-blurred
    (blurred crops take EasyOCR's second, contrast-adjusted pass, as a lens's do)."""
    scenes = load_scenes("synthetic", "val", frames, (512, 1024), 0)
    images = torch.from_numpy(np.stack([s.image for s in scenes])).permute(0, 3, 1, 2).float()
    reader = attacks.load("lpdr-oracle")
    hints = attacks.ReadHints(vehicle_boxes=[[v.box_xyxy for v in s.vehicles] for s in scenes])
    rows: dict[int, np.ndarray] = {}
    for im in (images, torch.nn.functional.avg_pool2d(images, 5, 1, 2, count_include_pad=False)):
        reader.read(im, hints)
        for crop in plate_crops(reader, im):
            rows[len(rows)] = plate_ocr.prepare_crop(crop)
    return rows


def plate_crops(reader, images):
    """The (h, w, 3) uint8 plate crops ``reader`` found in its last ``read`` of ``images``, image by image."""
    rgb = (images.clamp(0, 1) * 255).round().byte().permute(0, 2, 3, 1).numpy()
    for image, trace in zip(rgb, reader.last_trace):
        for _, (x0, y0, x1, y1) in trace.plates:
            yield image[y0:y1, x0:x1]


def assert_backends_read_alike(reference: dict[int, tuple[str, float]], other: dict[int, tuple[str, float]]) -> None:
    """Two backends' ``recognize_rows`` reads agree except where the recognizer is unsure: the same crops,
    confident reads (>= 0.8) the same text, at most 1 crop in 20 (at least 1) a different text, every
    confidence within 0.05 (tests/attacks/readers/test_ocr_onnx.py says why)."""
    assert set(other) == set(reference)
    confident = [k for k, (_, score) in reference.items() if score >= 0.8]
    assert all(other[k][0] == reference[k][0] for k in confident)
    differing = [k for k in reference if other[k][0] != reference[k][0]]
    assert len(differing) <= max(1, len(reference) // 20), [(reference[k], other[k]) for k in differing]
    assert max(abs(other[k][1] - reference[k][1]) for k in reference) < 0.05
