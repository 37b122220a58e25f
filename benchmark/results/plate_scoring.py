"""Plate-reading scores, computed by the runner for every reader and chain.

Plate accuracy (the paper's LPDR accuracy): correctly detected and fully recognised plates over
readable plates. A plate is *scored* when it is fully visible (at least 99 % of its pixels in the
image and unoccluded), not mirrored by augmentation, and at least SCORED_MIN_WIDTH_PX (8 px) wide:
every scored plate gets an outcome, so every reader has an accuracy-against-width curve from 8 px
(WIDTH_BINS_PX). A scored plate is *readable*, and counts in the pooled accuracy, from
READABLE_MIN_WIDTH_PX: the smallest width bin where the strongest reader reads at least half of
the sharp plates (``benchmark.results.readable_start``, measured and shipped with the package).
A read detects a plate when its box overlaps the plate box with IoU >= MATCH_IOU or its centre
falls inside it. One read per plate counts, as a detector pipeline is judged: of the reads that
detect it, the reader's own best-scored one (the first of equal scores); the plate counts as read when
that read's text equals the ground truth exactly (case and spaces ignored), and the other reads on it
count for nothing, so many guesses score no better than the one the reader trusts most. Character
error rate: Levenshtein distance between that read (or the empty string) and the truth, over the
truth's length. A reader gives at most MAX_READS_PER_IMAGE reads per image, each at most
MAX_READ_CHARS characters (``check_read_limits``); past either its row fails.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from attacks import PlateRead
from attacks.base import box_iou as iou
from benchmark.results.readable_start import measured_start
from benchmark.scenes import Plate, Scene

SCORED_MIN_WIDTH_PX = 8
WIDTH_BINS_PX = (8, 12, 16, 24, 32, 48, 64, 96, 128, 192)
READABLE_MIN_WIDTH_PX = measured_start(WIDTH_BINS_PX)
# Entries published before plates were scored from 8 px scored them from 32 px: where their units
# record no widths, that is what their pooled accuracy covers.
LEGACY_READABLE_MIN_WIDTH_PX = 32
READABLE_MIN_VISIBLE = 0.99
MATCH_IOU = 0.3
# A plate window holds one scored plate and a quick frame a few dozen; plate strings are a few characters.
MAX_READS_PER_IMAGE = 64
MAX_READ_CHARS = 32


@dataclass(frozen=True)
class PlateOutcome:
    """One readable ground-truth plate and what a reader made of it."""

    scene: str
    truth: str
    width_px: int
    read: str
    detected: bool
    correct: bool
    cer: float


def scored(plate: Plate) -> bool:
    """Whether the plate gets an outcome: fully visible, not mirrored, >= SCORED_MIN_WIDTH_PX wide."""
    x0, _, x1, _ = plate.box_xyxy
    return (not plate.mirrored and plate.visible_fraction >= READABLE_MIN_VISIBLE
            and x1 - x0 >= SCORED_MIN_WIDTH_PX)


def readable(plate: Plate) -> bool:
    """Whether the plate counts in the pooled accuracy: scored and >= READABLE_MIN_WIDTH_PX wide."""
    x0, _, x1, _ = plate.box_xyxy
    return scored(plate) and x1 - x0 >= READABLE_MIN_WIDTH_PX


def pooled(outcomes: list[PlateOutcome]) -> list[PlateOutcome]:
    """The outcomes that count in the pooled accuracy: plates >= READABLE_MIN_WIDTH_PX wide."""
    return [o for o in outcomes if o.width_px >= READABLE_MIN_WIDTH_PX]


def normalise(text: str) -> str:
    return "".join(ch for ch in text.upper() if ch.isalnum())


def levenshtein(a: str, b: str) -> int:
    prev = list(range(len(b) + 1))
    for i, ca in enumerate(a, 1):
        cur = [i]
        for j, cb in enumerate(b, 1):
            cur.append(min(prev[j] + 1, cur[j - 1] + 1, prev[j - 1] + (ca != cb)))
        prev = cur
    return prev[-1]




def _matches(read: PlateRead, plate: Plate) -> bool:
    cx, cy = (read.box_xyxy[0] + read.box_xyxy[2]) / 2, (read.box_xyxy[1] + read.box_xyxy[3]) / 2
    x0, y0, x1, y1 = plate.box_xyxy
    return iou(read.box_xyxy, plate.box_xyxy) >= MATCH_IOU or (x0 <= cx < x1 and y0 <= cy < y1)


def check_read_limits(reads: list[PlateRead]) -> str | None:
    """Why one image's reads break the limits (too many, a text too long, a score outside [0, 1] or a box
    that is not four finite numbers), or None when they keep them."""
    if len(reads) > MAX_READS_PER_IMAGE:
        return f"{len(reads)} reads of one image, more than MAX_READS_PER_IMAGE = {MAX_READS_PER_IMAGE}"
    for r in reads:
        if not isinstance(r.text, str) or len(r.text) > MAX_READ_CHARS:
            shown = f"{len(r.text)} characters" if isinstance(r.text, str) else type(r.text).__name__
            return f"a read's text is {shown}; at most MAX_READ_CHARS = {MAX_READ_CHARS} characters are scored"
        if not (isinstance(r.score, (int, float)) and 0.0 <= r.score <= 1.0):
            return f"a read's score is {r.score!r:.40}; scores lie in [0, 1]"
        box = r.box_xyxy
        if (not isinstance(box, tuple) or len(box) != 4
                or not all(isinstance(v, (int, float)) and np.isfinite(v) for v in box)):
            return f"a read's box is {box!r:.60}; boxes are four finite numbers (x0, y0, x1, y1)"
    return None


def score_scene(reads: list[PlateRead], scene: Scene) -> list[PlateOutcome]:
    """Outcomes for every scored plate of one scene: each plate takes the best-scored of the reads
    that detect it and that no earlier plate took (each read is used for one plate at most)."""
    outcomes, used = [], set()
    for plate in scene.plates:
        if not scored(plate):
            continue
        truth = normalise(plate.text)
        candidates = [(i, r) for i, r in enumerate(reads) if i not in used and _matches(r, plate)]
        best = max(candidates, key=lambda ir: (ir[1].score, -ir[0]), default=None)
        text = ""
        if best is not None:
            used.add(best[0])
            text = normalise(best[1].text)
        outcomes.append(PlateOutcome(scene.name, truth, int(plate.box_xyxy[2] - plate.box_xyxy[0]), text,
                                     best is not None, text == truth, levenshtein(text, truth) / len(truth)))
    return outcomes


def summarise(outcomes: list[PlateOutcome]) -> dict[str, float | int]:
    """Row metrics: plate_acc, plate_cer, plate_det (detection rate) and n_plates, over `outcomes`
    (the runner passes the readable ones: ``pooled``)."""
    if not outcomes:
        return {"n_plates": 0}
    return {"plate_acc": float(np.mean([o.correct for o in outcomes])),
            "plate_cer": float(np.mean([o.cer for o in outcomes])),
            "plate_det": float(np.mean([o.detected for o in outcomes])),
            "n_plates": len(outcomes)}
