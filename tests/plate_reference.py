"""The reference of the batched plate reader's tests and benchmark: EasyOCR's own ``recognize``, one crop
per call, as ``attacks.plates.ocr.read_plates`` read before it batched (tests/ is on sys.path through
its conftest.py)."""

from __future__ import annotations

from attacks.plates import ocr as plate_ocr


def recognize_one_at_a_time(ocr, crops_rgb, plate_format=None):
    """The reference: each prepared crop read alone by EasyOCR's public ``Reader.recognize``."""
    results = []
    for crop in crops_rgb:
        if crop.ndim != 3 or min(crop.shape[:2]) < 2:
            results.append(plate_ocr.OcrResult("", "", 0.0))
            continue
        row = plate_ocr.prepare_crop(crop)
        lines = ocr.recognize(row, horizontal_list=[[0, row.shape[1], 0, row.shape[0]]], free_list=[],
                              allowlist=plate_ocr.PLATE_ALPHABET, detail=1)
        raw, score = max(((r, float(s)) for _, r, s in lines), key=lambda rs: rs[1], default=("", 0.0))
        results.append(plate_ocr.OcrResult(plate_ocr.apply_format(plate_ocr.normalise(raw), plate_format), raw, score)
                       if lines else plate_ocr.OcrResult("", "", 0.0))
    return results
