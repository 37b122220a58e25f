"""Licence-plate detection and recognition (LPDR): vehicles -> plates -> characters.

Sensor-access attack of the paper's section 4.2, in three pluggable stages
(``attacks/readers/plates/``): vehicles from a segmentation network's car / truck / bus components
(``lpdr``) or from ground truth (``lpdr-oracle``, the attacker's upper bound); plates inside
each vehicle's lower part by EasyOCR's CRAFT or an OpenCV morphology detector
(``plate_detector``); characters by EasyOCR's english_g2 on the upscaled plate crop.
``reader.last_trace`` keeps every stage's output of the last ``read`` so that an error can
be attributed to the stage that made it, and ``reader.stage_seconds`` their cumulative time.
Segmentations and OCR reads are remembered by input content and shared by every reader and chain
of a process (``attacks/readers/plates/memo.py``, which argues why that gives no attacker anything it would
not compute itself): ``vehicle_cache_hits`` and ``ocr_cache_hits`` count what was reused.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Iterable
from typing import Any, ClassVar

import numpy as np
import torch
from torch import Tensor

from attacks.base import FitContext, FitReport, PlateRead, ReadHints, Reader, ThreatModel, box_iou
from attacks.readers.plates.detect_craft import detect_craft
from attacks.readers.plates.detect_opencv import detect_opencv
from attacks.readers.plates.easyocr_models import load_easyocr
from attacks.readers.plates.memo import content_key, ocr_memo, vehicles_memo
from attacks.readers.plates.ocr import FEATURE_BACKEND, OcrResult, apply_format, normalise, read_plates
from attacks.readers.plates.vehicles import expand_box, oracle_vehicles, segmentation_vehicles

__all__ = ["Lpdr", "LpdrCraft", "LpdrOracle", "PlateReaderBase", "StageTrace", "content_key"]

Box = tuple[int, int, int, int]
PLATE_DETECTORS = ("craft", "opencv")
STAGES = ("vehicles", "plates", "ocr")


@dataclasses.dataclass
class StageTrace:
    """Every stage's output for one image, in full-image pixels.

    Attributes:
        vehicles: Vehicle boxes from stage 1 (before the size filter).
        searched: Regions searched for plates (vehicle box + margin, lower part only).
        plates: Plate boxes from stage 2, each with the index of its vehicle in ``vehicles``.
        raw_texts: Recognizer output per entry of ``plates``: (raw string, normalised text, score).
        reads: The reads returned for this image (after filtering and de-duplication).
    """

    vehicles: list[Box] = dataclasses.field(default_factory=list)
    searched: list[Box] = dataclasses.field(default_factory=list)
    plates: list[tuple[int, Box]] = dataclasses.field(default_factory=list)
    raw_texts: list[tuple[str, str, float]] = dataclasses.field(default_factory=list)
    reads: list[PlateRead] = dataclasses.field(default_factory=list)


class PlateReaderBase(Reader):
    """The LPDR pipeline; subclasses fix the vehicle stage (``vehicle_source``).

    Args:
        plate_detector: "opencv" (morphology, the default) or "craft" (EasyOCR's pretrained text
            detector; about 10x slower per image on the CPU; registered as lpdr-craft).
        vehicle_margin: Each vehicle box grows by this fraction of its size on every side.
        plate_band_top: Only the part of the (grown) vehicle box below this fraction of its
            height is searched: plates sit on bumpers, in the lower part of a vehicle.
        min_vehicle_width_px: Narrower vehicles are skipped: an EU plate is at most ~0.29 of a
            car's width, so a 100 px car carries a plate under 29 px: english_g2 reads none of those
            on sharp scenes, so skipping them saves OCR time (the runner scores plates from 8 px and
            pools them from 24 px: ``benchmark.results.plate_scoring``).
        plate_format: Plate syntax known to the attacker ('L' letter, 'D' digit) used to resolve
            letter / digit look-alikes in reads of that length; None to read without it.
        min_chars: Reads with fewer characters are dropped (not a plate).
        target_width_px, max_mag: Vehicle crops narrower than ``target_width_px`` are magnified
            (at most ``max_mag`` times) before plate detection.
    """

    threat_model: ClassVar[ThreatModel] = ThreatModel.SENSOR_ACCESS
    vehicle_source: ClassVar[str]

    def __init__(self, plate_detector: str = "opencv", vehicle_margin: float = 0.1, plate_band_top: float = 0.4,
                 min_vehicle_width_px: int = 100, plate_format: str | None = "LLDDDLL", min_chars: int = 3,
                 target_width_px: int = 256, max_mag: float = 3.0) -> None:
        if plate_detector not in PLATE_DETECTORS:
            raise ValueError(f"plate_detector must be one of {PLATE_DETECTORS}, got {plate_detector!r}")
        if not 0.0 <= plate_band_top < 1.0:
            raise ValueError(f"plate_band_top must be in [0, 1), got {plate_band_top}")
        self.plate_detector = plate_detector
        self.vehicle_margin = vehicle_margin
        self.plate_band_top = plate_band_top
        self.min_vehicle_width_px = min_vehicle_width_px
        self.plate_format = plate_format
        self.min_chars = min_chars
        self.target_width_px = target_width_px
        self.max_mag = max_mag
        self.gpu = False
        self.last_trace: list[StageTrace] = []
        self.stage_seconds: dict[str, float] = dict.fromkeys(STAGES, 0.0)
        self.images_read = 0
        self.vehicle_cache_hits = 0
        self.ocr_cache_hits = 0
        self._ocr: Any = None

    def fit(self, ctx: FitContext) -> FitReport:
        """Load EasyOCR (offline, once per process); nothing is trained."""
        self.gpu = ctx.device.startswith("cuda")
        self._ocr = None
        self._ocr = self.ocr
        return FitReport()

    @property
    def ocr(self) -> Any:
        """The shared ``easyocr.Reader`` (CRAFT only for the craft plate detector), loaded on first use."""
        if self._ocr is None:
            self._ocr = load_easyocr(self.gpu, detector=self.plate_detector == "craft")
        return self._ocr

    def describe(self) -> dict[str, Any]:
        options = ("plate_detector", "vehicle_margin", "plate_band_top", "min_vehicle_width_px", "plate_format",
                   "min_chars", "target_width_px", "max_mag")
        # The OCR convolutions' backend policy ("auto": the faster on this machine, decided on first use and
        # logged; the same reads either way, to float rounding: attacks.readers.plates.ocr_onnx).
        return {**super().describe(), "vehicles": self.vehicle_source, **{k: getattr(self, k) for k in options},
                "ocr_features": FEATURE_BACKEND}

    def read(self, images: Tensor, hints: ReadHints | None = None) -> list[list[PlateRead]]:
        """Read the plates of every image; see ``Reader.read``. Also sets ``last_trace``.

        The plate crops of all images are recognised together (``read_plates`` batches them by size).
        """
        return self._read_pooled([(images, hints)])[0]

    def read_batches(self, batches: Iterable[tuple[Tensor, ReadHints | None]]) -> list[list[list[PlateRead]]]:
        """``read`` of each batch, with the plate crops of every batch recognised together: stages 1-2
        run batch by batch, stage 3 once over all their crops, so crops of one padded width from
        different batches share a forward pass. Each crop reads as it would alone
        (``SharedFeatures``), so the reads equal those of ``read`` batch by batch. ``last_trace``
        holds the traces of every image of every batch, in order. A subclass that overrides ``read``
        is read batch by batch through its own ``read``."""
        if type(self).read is not PlateReaderBase.read:
            return super().read_batches(batches)
        return self._read_pooled(batches)

    def _read_pooled(self, batches: Iterable[tuple[Tensor, ReadHints | None]]) -> list[list[list[PlateRead]]]:
        located = [self._locate(images, hints) for images, hints in batches]
        t0 = time.perf_counter()
        results = iter(self._recognise([c for _, crops in located for image_crops in crops for c in image_crops]))
        self.stage_seconds["ocr"] += time.perf_counter() - t0
        self.last_trace = []
        out = []
        for traces, _ in located:
            for trace in traces:
                candidates = []
                for _, box in trace.plates:
                    result = next(results)
                    trace.raw_texts.append((result.raw, result.text, result.score))
                    if len(result.text) >= self.min_chars:
                        candidates.append(PlateRead(result.text, (float(box[0]), float(box[1]), float(box[2]),
                                                                  float(box[3])), result.score))
                trace.reads = _deduplicate(candidates)
            self.last_trace.extend(traces)
            out.append([trace.reads for trace in traces])
        return out

    def _locate(self, images: Tensor, hints: ReadHints | None) -> tuple[list[StageTrace], list[list[np.ndarray]]]:
        """Stages 1-2 on a batch: each image's trace so far and its plate crops (copies, so that the
        batch's pixels are not kept alive by them)."""
        if images.ndim != 4 or images.shape[1] != 3:
            raise ValueError(f"images must be (B, 3, H, W), got shape {tuple(images.shape)}")
        t0 = time.perf_counter()
        vehicles = self._vehicles(images, hints)
        self.stage_seconds["vehicles"] += time.perf_counter() - t0
        rgb = (images.detach().clamp(0, 1) * 255).round().byte().permute(0, 2, 3, 1).cpu().numpy()
        traces, crops = [], []
        for im, boxes in zip(rgb, vehicles):
            trace, image_crops = self._find_plates(np.ascontiguousarray(im), boxes)
            traces.append(trace)
            crops.append([c.copy() for c in image_crops])
        self.images_read += len(rgb)
        return traces, crops

    def _vehicles(self, images: Tensor, hints: ReadHints | None) -> list[list[Box]]:
        raise NotImplementedError

    def _recognise(self, crops: list[np.ndarray]) -> list[OcrResult]:
        """Stage 3 on (h, w, 3) uint8 plate crops: what ``read_plates`` reads, each distinct crop read once
        per process (``ocr_memo``; identical crops read alike in any batch, see ``SharedFeatures``)."""
        memo = ocr_memo(self.ocr)
        if memo is None:
            return read_plates(self.ocr, crops, self.plate_format)
        keys = [content_key(c) for c in crops]
        missing: dict[str, np.ndarray] = {}
        for key, crop in zip(keys, crops):
            if key not in memo:
                missing.setdefault(key, crop)
        # Read without the plate syntax: it is the reader's own setting, applied below to every read.
        for key, result in zip(missing, read_plates(self.ocr, list(missing.values()), None) if missing else []):
            memo[key] = (result.raw, result.score)
        self.ocr_cache_hits += len(keys) - len(missing)
        return [OcrResult(apply_format(normalise(raw), self.plate_format), raw, score)
                for raw, score in (memo[key] for key in keys)]

    def _find_plates(self, image: np.ndarray, vehicles: list[Box]) -> tuple[StageTrace, list[np.ndarray]]:
        """Stages 1-2 on one (H, W, 3) uint8 image: the trace so far and one crop per plate found."""
        trace = StageTrace(vehicles=vehicles)
        hw = image.shape[:2]
        crops = []
        t0 = time.perf_counter()
        for index, vehicle in enumerate(vehicles):
            if vehicle[2] - vehicle[0] < self.min_vehicle_width_px:
                continue
            x0, y0, x1, y1 = expand_box(vehicle, self.vehicle_margin, hw)
            y0 += int(self.plate_band_top * (y1 - y0))
            trace.searched.append((x0, y0, x1, y1))
            for px0, py0, px1, py1 in self._detect(image[y0:y1, x0:x1]):
                box = (px0 + x0, py0 + y0, px1 + x0, py1 + y0)
                cx0, cy0, cx1, cy1 = _grow(box, max(1, round(self._crop_margin * (box[3] - box[1]))), hw)
                trace.plates.append((index, box))
                crops.append(image[cy0:cy1, cx0:cx1])
        self.stage_seconds["plates"] += time.perf_counter() - t0
        return trace, crops

    @property
    def _crop_margin(self) -> float:
        # CRAFT boxes hug the characters, and the recognizer's crop preparation drops glyphs that
        # touch the crop edge: give them room. OpenCV boxes already hold the plate border.
        return 0.3 if self.plate_detector == "craft" else 0.1

    def _detect(self, crop: np.ndarray) -> list[Box]:
        if self.plate_detector == "craft":
            return detect_craft(self.ocr, crop, self.target_width_px, self.max_mag)
        return detect_opencv(crop, self.target_width_px, self.max_mag)


class Lpdr(PlateReaderBase):
    """LPDR with vehicles from a segmentation network (``hints.segment``): the realistic attack.

    Vehicles are found once per image content and segmenter within a process (``vehicles_memo``); a
    batch with any image not seen before is segmented whole, as a reader without the memory would.
    ``vehicle_cache_hits`` counts images served from it.
    """

    name: ClassVar[str] = "lpdr"
    hints: ClassVar[frozenset[str]] = frozenset({"segment"})
    vehicle_source: ClassVar[str] = "segmentation"

    def __init__(self, vehicle_scale: float = 0.5, **options: Any) -> None:
        """``vehicle_scale``: the images are segmented at this fraction of their size (area-averaged),
        the label map brought back to full size (nearest), so the boxes are in full-size pixels;
        plates are searched and read at full size whatever it is. See ``__init__`` of
        ``PlateReaderBase`` for the other options.

        Why half size by default: only vehicles at least ``min_vehicle_width_px`` (100) wide are
        searched, and they are still >= 50 px wide at half size, where the segmentation finds them as
        well: it reads the same plates (no difference McNemar can tell) for a vehicle stage several
        times faster (docs/modelling.md). ``vehicle_scale=1`` gives the full-size segmentation."""
        if not 0.0 < vehicle_scale <= 1.0:
            raise ValueError(f"vehicle_scale must be in (0, 1], got {vehicle_scale}")
        super().__init__(**options)
        self.vehicle_scale = vehicle_scale

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "vehicle_scale": self.vehicle_scale}

    def _segment(self, images: Tensor, segment: Any) -> Tensor:
        """Train ids (B, H, W) of `images` (B, 3, H, W), segmented at ``vehicle_scale``."""
        h, w = int(images.shape[2]), int(images.shape[3])
        if self.vehicle_scale == 1.0:
            small = images
        else:
            size = (max(1, round(h * self.vehicle_scale)), max(1, round(w * self.vehicle_scale)))
            small = torch.nn.functional.interpolate(images, size=size, mode="area")
        labels = segment(small)
        if tuple(labels.shape) != (small.shape[0], *small.shape[2:]):
            raise ValueError(f"hints.segment returned shape {tuple(labels.shape)}, expected (B, H, W) = "
                             f"{(small.shape[0], *small.shape[2:])}")
        if small is not images:
            labels = torch.nn.functional.interpolate(labels[:, None].float(), size=(h, w), mode="nearest")[:, 0]
        return labels.to(torch.int64)

    def skip_reason(self, ctx: FitContext) -> str | None:
        if ctx.segmenter is None:
            return ("lpdr finds vehicles with a segmentation network, and this context has none "
                    "(FitContext.segmenter is None); lpdr-oracle reads with ground-truth vehicles")
        return None

    def _vehicles(self, images: Tensor, hints: ReadHints | None) -> list[list[Box]]:
        if hints is None or hints.segment is None:
            raise ValueError("lpdr needs ReadHints(segment=...) (a network mapping images to Cityscapes train "
                             "ids); got no segment callable. Use lpdr-oracle to read with ground-truth vehicles.")
        found = vehicles_memo(hints.segment)
        keys = [f"{content_key(im)}@{self.vehicle_scale}" for im in images]
        if found is None or any(k not in found for k in keys):
            # The whole batch, as a reader without the cache would: the same segmentation, bit for bit.
            labels = self._segment(images, hints.segment)
            boxes = [segmentation_vehicles(m) for m in labels.detach().cpu().numpy()]
            if found is None:
                return boxes
            found.update(zip(keys, boxes))
        else:
            self.vehicle_cache_hits += len(keys)
        return [list(found[k]) for k in keys]


class LpdrOracle(PlateReaderBase):
    """LPDR with ground-truth vehicle boxes (``hints.vehicle_boxes``): the attacker's upper bound."""

    name: ClassVar[str] = "lpdr-oracle"
    hints: ClassVar[frozenset[str]] = frozenset({"vehicle_boxes"})
    vehicle_source: ClassVar[str] = "oracle"

    def _vehicles(self, images: Tensor, hints: ReadHints | None) -> list[list[Box]]:
        if hints is None or hints.vehicle_boxes is None:
            raise ValueError("lpdr-oracle needs ReadHints(vehicle_boxes=...) (ground-truth vehicle boxes per "
                             "image); got none")
        if len(hints.vehicle_boxes) != images.shape[0]:
            raise ValueError(f"hints.vehicle_boxes has {len(hints.vehicle_boxes)} entries for "
                             f"{images.shape[0]} images; need one list of boxes per image")
        hw = (int(images.shape[2]), int(images.shape[3]))
        return [oracle_vehicles(boxes, hw) for boxes in hints.vehicle_boxes]


def _grow(box: Box, pad: int, image_hw: tuple[int, int]) -> Box:
    """``box`` grown by ``pad`` pixels on every side, clipped to the image."""
    h, w = image_hw
    return max(0, box[0] - pad), max(0, box[1] - pad), min(w, box[2] + pad), min(h, box[3] + pad)


def _deduplicate(reads: list[PlateRead], max_iou: float = 0.5) -> list[PlateRead]:
    """Drop reads overlapping a more confident one (the same plate seen from overlapping vehicles)."""
    kept: list[PlateRead] = []
    for read in sorted(reads, key=lambda r: -r.score):
        if all(box_iou(read.box_xyxy, k.box_xyxy) <= max_iou for k in kept):
            kept.append(read)
    return kept


class LpdrCraft(LpdrOracle):
    """lpdr-oracle with EasyOCR's CRAFT plate detector, to compare the detectors.

    Not run by default (about 10x slower per image on the CPU than the OpenCV detector): name it
    with ``--attack lpdr-craft``.
    """

    name: ClassVar[str] = "lpdr-craft"
    run_by_default: ClassVar[bool] = False

    def __init__(self, **options: Any) -> None:
        super().__init__(**{"plate_detector": "craft", **options})
