"""Stage 3 of the plate attack: read the characters of one plate crop with EasyOCR's english_g2.

An attacker upscales the crop (cubic) to the recognizer's input height, trims it to the text
(plate borders and the blue EU band otherwise read as 'I', 'L' or '1'), and restricts the
alphabet to plate characters. Text is normalised to upper-case letters and digits.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import sys
from collections.abc import Iterator
from typing import Any

import cv2
import numpy as np
import torch

from attacks.readers.plates.memo import content_key
from attacks.readers.plates.ocr_onnx import feature_extractor

__all__ = ["PLATE_ALPHABET", "OcrResult", "apply_format", "normalise", "padded_width", "prepare_crop", "read_plate",
           "read_plates", "recognize_rows", "one_thread", "SharedFeatures", "text_box"]

PLATE_ALPHABET = "ABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789"
"""Characters the recognizer may output (EasyOCR ``allowlist``)."""

OCR_HEIGHT_PX = 64
"""Height the crop is upscaled to before reading: english_g2's input height."""

FEATURE_BACKEND = "auto"
"""Where the recognizer's convolutions run by default: "auto" (on the CPU the faster of ONNX Runtime and torch
on this machine, timed once per process; ``attacks.readers.plates.ocr_onnx``), "onnx" (torch elsewhere or if the
export fails) or "torch"."""


@dataclasses.dataclass(frozen=True)
class OcrResult:
    """What the recognizer read from one crop: normalised ``text``, raw ``raw`` and ``score`` in [0, 1]."""

    text: str
    raw: str
    score: float


def normalise(text: str) -> str:
    """Upper-case and keep only ASCII letters and digits ('ab-12 c' -> 'AB12C')."""
    return "".join(ch for ch in text.upper() if ch.isascii() and ch.isalnum())


# Glyphs the recognizer confuses across the letter / digit divide, resolved by the plate syntax.
_TO_DIGIT = str.maketrans("OQDIZSBGTA", "0001258674")
_TO_LETTER = str.maketrans("0125867", "OIZSBGT")


def apply_format(text: str, fmt: str | None) -> str:
    """Resolve letter / digit look-alikes by position when ``text`` fits the plate syntax.

    ``fmt`` uses 'L' for a letter and 'D' for a digit (e.g. "LLDDDLL"); an attacker knows the
    plate syntax of the country it targets. Text of another length, or ``fmt`` None, is
    returned unchanged ('0L254VS' -> 'OL254VS', 'SEB94NH' -> 'SE894NH').
    """
    if fmt is None or len(text) != len(fmt):
        return text
    return "".join(ch.translate(_TO_DIGIT if kind == "D" else _TO_LETTER) for ch, kind in zip(text, fmt))


def prepare_crop(crop_rgb: np.ndarray, height_px: int = OCR_HEIGHT_PX) -> np.ndarray:
    """Single-channel uint8 plate image for the recognizer, ``height_px`` high.

    Uses the HSV value channel max(R, G, B) rather than luma: dark text stays dark while the
    saturated blue EU band turns light, so it is not read as a character. Upscales (bicubic,
    aspect kept) and then trims to the text found by ``text_box``.

    Args:
        crop_rgb: (h, w, 3) uint8 RGB plate crop, h, w >= 1.
        height_px: Output height in pixels.
    """
    if crop_rgb.ndim != 3 or crop_rgb.shape[2] != 3 or min(crop_rgb.shape[:2]) < 1:
        raise ValueError(f"crop_rgb must be a non-empty (h, w, 3) array, got shape {crop_rgb.shape}")
    value = crop_rgb.max(axis=2)
    h, w = value.shape
    width = max(1, round(w * height_px / h))
    big = cv2.resize(value, (width, height_px), interpolation=cv2.INTER_CUBIC)
    x0, y0, x1, y1 = text_box(big)
    return np.ascontiguousarray(big[y0:y1, x0:x1])


def text_box(plate: np.ndarray) -> tuple[int, int, int, int]:
    """Box (x0, y0, x1, y1) around the dark characters of a light plate, with a small margin.

    Characters are the dark (Otsu) connected components that do not touch the crop's edge
    (borders and background do) and are 30-100 % of the crop height and narrower than it.
    Returns the whole crop when no component qualifies.
    """
    h, w = plate.shape
    full = (0, 0, w, h)
    if h < 4 or w < 4 or int(plate.max()) - int(plate.min()) < 16:
        return full
    _, dark = cv2.threshold(plate, 0, 1, cv2.THRESH_BINARY_INV + cv2.THRESH_OTSU)
    n, _, stats, _ = cv2.connectedComponentsWithStats(dark, connectivity=8)
    keep = [(x, y, x + cw, y + ch) for x, y, cw, ch, _ in stats[1:n]
            if x > 0 and y > 0 and x + cw < w and y + ch < h and 0.3 * h <= ch and cw < h]
    if not keep:
        return full
    margin = round(0.12 * h)
    x0, y0 = min(b[0] for b in keep) - margin, min(b[1] for b in keep) - margin
    x1, y1 = max(b[2] for b in keep) + margin, max(b[3] for b in keep) + margin
    return max(0, x0), max(0, y0), min(w, x1), min(h, y1)


def read_plate(ocr: Any, crop_rgb: np.ndarray, plate_format: str | None = None) -> OcrResult:
    """Read one plate crop; see ``read_plates``."""
    return read_plates(ocr, [crop_rgb], plate_format)[0]


def read_plates(ocr: Any, crops_rgb: list[np.ndarray], plate_format: str | None = None) -> list[OcrResult]:
    """Read several plate crops, batched by the width the recognizer pads them to.

    Each crop is prepared by ``prepare_crop``. EasyOCR's ``recognize`` reads one box at a time on
    the CPU, padding each crop (right, by repeating its last column) to the next multiple of its
    input height; crops that pad to the same width are therefore stacked here and recognised in one
    forward pass (``recognize_rows``): every crop reaches the network exactly as it would alone.

    Args:
        ocr: An ``easyocr.Reader`` (see ``attacks.readers.plates.easyocr_models.load_easyocr``).
        crops_rgb: (h, w, 3) uint8 RGB crops around one plate each; empty crops read as "".
        plate_format: Plate syntax for ``apply_format`` ('L' letter, 'D' digit), or None.

    Returns:
        Per crop, the recognised line's normalised text, its raw string and confidence in [0, 1];
        "" with score 0 when the crop is empty or nothing was recognised.
    """
    results = [OcrResult("", "", 0.0)] * len(crops_rgb)
    rows = {i: prepare_crop(c) for i, c in enumerate(crops_rgb) if c.ndim == 3 and min(c.shape[:2]) >= 2}
    for i, (raw, score) in recognize_rows(ocr, rows).items():
        results[i] = OcrResult(apply_format(normalise(raw), plate_format), raw, score)
    return results


_MODEL_PARTS = ("FeatureExtraction", "AdaptiveAvgPool", "SequenceModeling", "Prediction")


class SharedFeatures(torch.nn.Module):
    """EasyOCR's recognizer (``easyocr.model.vgg_model.Model``, english_g2) with its convolutional
    feature extractor run once on a batch and the rest run per crop.

    On the CPU EasyOCR quantizes the BiLSTM and the classifier dynamically: their activations are
    scaled by the min / max of the whole input, so a crop's output depends on the crops batched
    with it. The convolutions (most of the time) do not, up to float rounding (none on some CPUs,
    ~3e-6 of the features' scale on one with AVX2 and no AVX-512); running the quantized tail one crop
    at a time keeps every crop's output what it is when read alone. ``backend`` "onnx" runs the
    convolutions through ONNX Runtime (``attacks.readers.plates.ocr_onnx``; equal to torch to float rounding).

    An input row it has already seen returns its earlier output instead of being recomputed. EasyOCR's
    second pass (``get_text``) re-reads every crop read with confidence < 0.1 with its contrast stretched,
    but leaves a crop whose contrast is already at the target as it is: that crop reaches the network as
    the very tensor of the first pass, and its scores, and so its read, are the first pass's. Such crops
    are a sizeable share of the second pass in a quick evaluation (docs/modelling.md, "Second OCR pass
    only where it changes the input"; EasyOCR pads a crop to a multiple of 64 columns).
    """

    def __init__(self, model: Any, backend: str = "torch") -> None:  # EasyOCR's Model: parts in _MODEL_PARTS
        super().__init__()
        self.model = model
        self.features = feature_extractor(model, backend)  # the convolutions; "onnx": ONNX Runtime (CPU)
        self.seen: dict[str, torch.Tensor] = {}  # input row's content -> its output row (one per row computed)
        self.rows_remembered = 0

    def forward(self, image: torch.Tensor, text: torch.Tensor | None = None) -> torch.Tensor:
        """(B, 1, 64, W) normalised crops -> (B, T, classes) per-column class scores; ``text`` is unused (CTC)."""
        keys = [content_key(row) for row in image]
        new: dict[str, int] = {}  # each content not seen yet -> its first row
        for i, key in enumerate(keys):
            if key not in self.seen:
                new.setdefault(key, i)
        if new:
            m: Any = self.model
            features = self.features(image[list(new.values())])
            with one_thread():
                for key, one in zip(new, features.split(1)):
                    sequence = m.AdaptiveAvgPool(one.permute(0, 3, 1, 2)).squeeze(3)
                    self.seen[key] = m.Prediction(m.SequenceModeling(sequence).contiguous())
        self.rows_remembered += len(keys) - len(new)
        return torch.cat([self.seen[key] for key in keys])


@contextlib.contextmanager
def one_thread() -> Iterator[None]:
    """Torch on one intra-op thread within the block (the caller's count is back after it).

    The quantized BiLSTM of one crop is a chain of (1 x 256) x (256 x 1024) products, one per time
    step: splitting each over threads costs more than it saves, many times more on a loaded machine
    (docs/modelling.md, "Speed of the evaluation"; tests/speed/test_lpdr_chain_speed.py). Integer
    accumulation makes the output the same at any thread count (tests/attacks/readers/test_ocr_threads.py).
    """
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(before)


def padded_width(row: np.ndarray, height_px: int = OCR_HEIGHT_PX) -> int:
    """Width (pixels) EasyOCR pads a single-line crop to: its aspect ratio (>= 1, inverted for a tall
    crop) rounded up, times the recognizer's input height (``easyocr.utils.get_image_list``)."""
    h, w = row.shape[:2]
    return math.ceil(max(max(w / h, h / w), 1.0)) * height_px


def recognize_rows(ocr: Any, rows: dict[int, np.ndarray], backend: str | None = None) -> dict[int, tuple[str, float]]:
    """EasyOCR's english_g2 on prepared crops, one batch per padded width.

    Does what ``ocr.recognize(image, horizontal_list=[box], allowlist=PLATE_ALPHABET)`` does per crop
    (the same resize, padding, second low-contrast pass and greedy decoding, through EasyOCR's own
    ``get_image_list`` and ``get_text``), with every crop of one padded width in one batch through
    ``SharedFeatures`` (a recognizer of another layout reads one crop at a time).

    Args:
        ocr: An ``easyocr.Reader``.
        rows: Key -> (h, w) uint8 single-channel crop (``prepare_crop``), h, w >= 1.
        backend: Where the convolutions run, "auto", "onnx" or "torch" (None: ``FEATURE_BACKEND``).

    Returns:
        Key -> (raw string, confidence in [0, 1]) for every crop the recognizer returned a line for.
    """
    from easyocr.recognition import get_text
    from easyocr.utils import get_image_list

    model_height = sys.modules[type(ocr).__module__].imgH
    recognizer: torch.nn.Module = ocr.recognizer
    batched = all(hasattr(getattr(recognizer, "module", recognizer), part) for part in _MODEL_PARTS)
    if batched:
        recognizer = SharedFeatures(getattr(recognizer, "module", recognizer), backend or FEATURE_BACKEND)
    ignore = "".join(sorted(set(ocr.character) - set(PLATE_ALPHABET)))
    groups: dict[int, list[int]] = {}
    for key, row in rows.items():
        groups.setdefault(padded_width(row, model_height), []).append(key)
    read: dict[int, tuple[str, float]] = {}
    for keys in groups.values():
        canvas = np.full((OCR_HEIGHT_PX * len(keys), max(rows[k].shape[1] for k in keys)), 255, np.uint8)
        boxes = []
        for slot, key in enumerate(keys):
            row, y0 = rows[key], slot * OCR_HEIGHT_PX
            canvas[y0:y0 + row.shape[0], :row.shape[1]] = row
            boxes.append([0, row.shape[1], y0, y0 + row.shape[0]])
        image_list, max_width = get_image_list(boxes, [], canvas, model_height=model_height)
        lines = get_text(ocr.character, model_height, int(max_width), recognizer, ocr.converter, image_list,
                         ignore, "greedy", 5, len(image_list) if batched else 1, 0.1, 0.5, 0.003, 0, ocr.device)
        for box, raw, score in lines:
            key = keys[int(box[0][1]) // OCR_HEIGHT_PX]
            if key not in read or float(score) > read[key][1]:
                read[key] = (raw, float(score))
    return read
