"""Plate windows: one region of a frame around each readable plate's vehicle, scored on its own.

A plate is scored on a window instead of the whole frame so that many plates cost little: the
window holds the plate's whole vehicle plus a margin of context on every side (what a reader
that finds vehicles itself needs) and is at least ``min_size_px`` (the segmentation network's
sliding window, so it sees as much context per tile as on a full frame). Only the window's own
plate is scored in it; a plate whose window overlaps another's is still one sample, once.

How the window's sensor image is made equal to the full frame's inside it:
``benchmark.runner.sensing.sense_windows``.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

from .records import Box, Plate, Scene, Vehicle

WINDOW_MARGIN = 0.25
"""Context around the vehicle on every side, as a fraction of the vehicle's width / height."""

WINDOW_STEP_PX = 64
"""Window sides are rounded up to a multiple of this, so that windows share a few sizes and batch."""


@dataclass(frozen=True)
class PlateWindow:
    """One plate to score and the region of its frame that is simulated and read.

    Attributes:
        frame: Index of the frame (scene) in the list the windows were made from.
        box_xyxy: The window in frame pixels, (x0, y0, x1, y1), x1/y1 exclusive.
        plate: Index of the scored plate in that frame's ``plates``.
    """

    frame: int
    box_xyxy: Box
    plate: int

    @property
    def size_hw(self) -> tuple[int, int]:
        x0, y0, x1, y1 = self.box_xyxy
        return y1 - y0, x1 - x0


@dataclass
class WidthQuota:
    """At most ``per_bin[i]`` plates in width bin i (lower edges `bins_px`, the last bin open above;
    plates narrower than the first edge are never taken). `full` once every bin whose lower edge is
    below `required_below_px` holds its quota: the bins a plate set must fill; wider bins take what
    comes up to theirs.
    """

    bins_px: Sequence[float]
    per_bin: Sequence[int]
    required_below_px: float
    counts: list[int] = field(default_factory=list)

    def __post_init__(self) -> None:
        if list(self.bins_px) != sorted(self.bins_px) or not self.bins_px:
            raise ValueError(f"width bins must be increasing lower edges, got {tuple(self.bins_px)}")
        if len(self.per_bin) != len(self.bins_px):
            raise ValueError(f"one quota per width bin: {len(self.per_bin)} quotas for {len(self.bins_px)} bins")
        self.counts = [0] * len(self.bins_px)

    def bin_of(self, width_px: float) -> int | None:
        """The bin holding `width_px` (None below the first edge)."""
        i = bisect.bisect_right(self.bins_px, width_px) - 1
        return i if i >= 0 else None

    def take(self, width_px: float) -> bool:
        """Count a plate of `width_px` when its bin has room; whether it was taken."""
        i = self.bin_of(width_px)
        if i is None or self.counts[i] >= self.per_bin[i]:
            return False
        self.counts[i] += 1
        return True

    @property
    def full(self) -> bool:
        return all(c >= q for low, c, q in zip(self.bins_px, self.counts, self.per_bin) if low < self.required_below_px)


def window_box(target: Box, frame_hw: tuple[int, int], min_size_px: tuple[int, int],
               margin: float = WINDOW_MARGIN, step_px: int = WINDOW_STEP_PX) -> Box:
    """The window around ``target`` (a box in frame pixels) inside a frame of ``frame_hw = (H, W)``.

    Each side is the target's size times (1 + 2 margin), at least ``min_size_px = (h, w)``,
    rounded up to a multiple of ``step_px`` and at most the frame; the window is centred on the
    target and shifted to lie inside the frame (so it still holds the target and most of its margin).
    """
    height, width = frame_hw
    x0, y0, x1, y1 = target
    sides = []
    for extent, minimum, limit in ((y1 - y0, min_size_px[0], height), (x1 - x0, min_size_px[1], width)):
        side = max(math.ceil(extent * (1 + 2 * margin)), minimum)
        sides.append(min(math.ceil(side / step_px) * step_px, limit))
    h, w = sides
    left = min(max(round((x0 + x1 - w) / 2), 0), width - w)
    top = min(max(round((y0 + y1 - h) / 2), 0), height - h)
    return left, top, left + w, top + h


def plate_windows(frames: list[Scene], is_scored: Callable[[Plate], bool], min_size_px: tuple[int, int],
                  margin: float = WINDOW_MARGIN, step_px: int = WINDOW_STEP_PX) -> list[PlateWindow]:
    """One window per plate of ``frames`` that ``is_scored`` accepts, around the plate and its vehicle."""
    windows = []
    for f, frame in enumerate(frames):
        hw = frame.image.shape[:2]
        for p, plate in enumerate(frame.plates):
            if not is_scored(plate):
                continue
            vehicle = frame.vehicles[plate.vehicle_index].box_xyxy
            target = _union(vehicle, plate.box_xyxy)
            windows.append(PlateWindow(f, window_box(target, hw, min_size_px, margin, step_px), p))
    return windows


def window_scene(frame: Scene, window: PlateWindow) -> Scene:
    """The window as a scene record: image, labels and plate mask cropped; the scored plate and its
    vehicle, in window pixels, are its ground truth (the plate keeps its visibility in the frame).

    Other vehicles stay in the image but not in the ground truth: their plates are scored in their
    own windows, and an oracle reader need not spend time on them."""
    x0, y0, x1, y1 = window.box_xyxy
    plate = frame.plates[window.plate]
    vehicle = frame.vehicles[plate.vehicle_index]
    plate_box, vehicle_box = (_shift_clip(b, window.box_xyxy) for b in (plate.box_xyxy, vehicle.box_xyxy))
    if plate_box is None or vehicle_box is None:
        raise ValueError(f"window {window.box_xyxy} of {frame.name} misses its plate {plate.box_xyxy}")
    mask = None
    if frame.plate_mask is not None:
        # Only the scored plate is ground truth in the window: id 1.
        mask = (frame.plate_mask[y0:y1, x0:x1] == window.plate + 1).astype(frame.plate_mask.dtype)
    # Copies, not views: a view would keep the whole frame alive for every window cut from it
    # (about 1 GB for the 141 frames of a quick plate set).
    return Scene(frame.image[y0:y1, x0:x1].copy(), frame.labels[y0:y1, x0:x1].copy(),
                 [replace(plate, box_xyxy=plate_box, vehicle_index=0)], [Vehicle(vehicle.train_id, vehicle_box)],
                 frame.seed,
                 f"{frame.name}@x{x0}y{y0}p{window.plate}", mask)


def _union(a: Box, b: Box) -> Box:
    return min(a[0], b[0]), min(a[1], b[1]), max(a[2], b[2]), max(a[3], b[3])


def _shift_clip(box: Box, window: Box) -> Box | None:
    """``box`` clipped to ``window`` and shifted to window pixels; None when they do not overlap."""
    x0, y0 = max(box[0], window[0]) - window[0], max(box[1], window[1]) - window[1]
    x1, y1 = min(box[2], window[2]) - window[0], min(box[3], window[3]) - window[1]
    return (x0, y0, x1, y1) if x1 > x0 and y1 > y0 else None
