"""The ``cityscapes:PATH`` scene set: real Cityscapes frames, labels, vehicles and optional plates.

Layout under ``PATH`` (the official one; other files are ignored)::

    leftImg8bit/{split}/{city}/{stem}_leftImg8bit.png       8-bit RGB image (required)
    gtFine/{split}/{city}/{stem}_gtFine_labelIds.png        label ids (required for train and val)
    gtFine/{split}/{city}/{stem}_gtFine_instanceIds.png     instance ids (optional, for vehicles)
    plates/{split}.json                                     licence-plate annotations (optional)

with ``stem = {city}_{seq}_{frame}``, e.g. ``frankfurt_000000_000294``. Scene ``i`` of a split
is the ``i``-th image in sorted ``{city}/{file name}`` order, so it does not depend on ``n``.
The run seed only names scenes (and sets ``Scene.seed``); it selects nothing.

Labels: label ids map to train ids through ``cityscapesscripts.helpers.labels``
(``id2label[id].trainId``; train ids 255 and -1 become 255 = ignore). A label id that
``cityscapesscripts`` does not know is an error. Labels of the ``test`` split are not public:
a ``test`` image without its labelIds file gets labels all 255 (the placeholder maps of the
official download, where present, are read as they are).

Resizing to ``size = (H, W)``: images with PIL's bilinear filter on float channels (no
re-quantization; PIL widens the filter when reducing, so shrinking averages over the area each
output pixel covers), labels nearest-neighbour, boxes scaled outward (floor of the start, ceil of
the end). The aspect ratio follows ``size``; nothing is cropped. The paper evaluates at the
native 1024 x 2048, where nothing is resampled.

Vehicles (car, truck, bus, train, motorcycle, bicycle) come, at native resolution, from the
instanceIds file when it exists: one box per instance id ``>= 1000`` with ``id // 1000`` a vehicle
label id, in instance-id order (crowd regions such as "cargroup" carry no instance and give no
box). Without it they are the 8-connected components of each vehicle class in the label map,
ordered by train id, then raster order; a vehicle split by an occluder then gives several boxes.

Licence plates: ``PATH/plates/{split}.json`` (Cityscapes-LP and similar annotations converted to
this simple form) is one JSON object mapping an image stem to the list of its plates::

    {
      "frankfurt_000000_000294": [
        {"text": "F AB 1234", "box_xyxy": [1021, 611, 1068, 622], "visible_fraction": 1.0}
      ],
      "frankfurt_000000_000576": []
    }

- ``text``: the plate string; spaces and hyphens are dropped and letters upper-cased, after which
  it must be ``[A-Z0-9]+`` ("F AB 1234" -> "FAB1234").
- ``box_xyxy``: ``[x0, y0, x1, y1]`` in pixels of the native image (integers or decimals),
  ``0 <= x0 < x1 <= width`` and ``0 <= y0 < y1 <= height``; ``(x1, y1)`` is the first pixel past
  the box, as in ``records.Box``. It is scaled with the resize.
- ``visible_fraction`` (optional, default 1.0): the share of the plate not occluded, in [0, 1].

No other keys are accepted. A stem without an entry, or no file at all, means no plates; entries
for stems that are not images of the split are ignored. A plate belongs to the smallest vehicle
box that contains its centre (``vehicle_index = -1`` when none does). Scenes carry no per-pixel
plate mask (``plate_mask = None``).

Errors name the offending file: ``CityscapesNotFoundError`` (a ``FileNotFoundError``) for a
missing root, split folder or label file; ``CityscapesFormatError`` (a ``ValueError``) for an
undecodable PNG, an unknown label id, mismatched sizes or a malformed plates file.
"""

from __future__ import annotations

import json
import logging
import math
import re
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
from cityscapesscripts.helpers.labels import id2label
from PIL import Image
from scipy import ndimage

from .labels import IGNORE_ID
from .records import Box, Plate, Scene, Vehicle

log = logging.getLogger(__name__)

PREFIX = "cityscapes:"
IMAGE_SUFFIX = "_leftImg8bit.png"
LABEL_SUFFIX = "_gtFine_labelIds.png"
INSTANCE_SUFFIX = "_gtFine_instanceIds.png"
VEHICLE_CLASSES: tuple[str, ...] = ("car", "truck", "bus", "train", "motorcycle", "bicycle")
PLATE_KEYS: tuple[str, ...] = ("text", "box_xyxy", "visible_fraction")

_VEHICLE_LABEL_IDS: tuple[int, ...] = tuple(
    sorted(label.id for label in id2label.values() if label.name in VEHICLE_CLASSES))
_UNKNOWN = -2  # marks label ids that cityscapesscripts does not define in the lookup table


class CityscapesNotFoundError(FileNotFoundError):
    """A Cityscapes root, split folder or label file that should exist does not."""


class CityscapesFormatError(ValueError):
    """A Cityscapes file exists but cannot be used: undecodable, unknown ids, bad plates JSON."""


@dataclass(frozen=True)
class Frame:
    """One image of a split and the paths of its ground truth (which may not exist)."""

    stem: str
    image: Path
    label_ids: Path
    instance_ids: Path


def cityscapes_root(scene_set: str) -> Path:
    """The dataset root of ``"cityscapes:PATH"``, checked to be an existing folder."""
    if not scene_set[len(PREFIX):]:
        raise CityscapesNotFoundError(
            "scene set 'cityscapes:' has no path; use 'cityscapes:PATH' with PATH the folder that holds leftImg8bit/ "
            "and gtFine/")
    root = Path(scene_set[len(PREFIX):]).expanduser()
    if not root.is_dir():
        raise CityscapesNotFoundError(
            f"Cityscapes root {str(root)!r} (from scene set {scene_set!r}) is not an existing folder; "
            "PATH must be the folder that holds leftImg8bit/ and gtFine/")
    return root


def list_frames(root: Path, split: str) -> list[Frame]:
    """All frames of ``split`` under ``root`` in sorted ``{city}/{file name}`` order.

    Raises ``CityscapesNotFoundError`` when ``leftImg8bit/{split}`` is missing or holds no images.
    """
    split_dir = root / "leftImg8bit" / split
    if not split_dir.is_dir():
        present = sorted(p.name for p in (root / "leftImg8bit").glob("*") if p.is_dir())
        raise CityscapesNotFoundError(
            f"Cityscapes split folder {str(split_dir)!r} does not exist; expected "
            f"leftImg8bit/{split}/{{city}}/{{city}}_{{seq}}_{{frame}}{IMAGE_SUFFIX} under {str(root)!r} "
            f"(splits present: {', '.join(present) or 'none'})")
    frames = []
    for city in sorted(p for p in split_dir.iterdir() if p.is_dir()):
        for name in sorted(p.name for p in city.glob(f"*{IMAGE_SUFFIX}")):
            stem = name[: -len(IMAGE_SUFFIX)]
            gt = root / "gtFine" / split / city.name
            frames.append(Frame(stem, city / name, gt / f"{stem}{LABEL_SUFFIX}", gt / f"{stem}{INSTANCE_SUFFIX}"))
    if not frames:
        raise CityscapesNotFoundError(
            f"no images in Cityscapes split folder {str(split_dir)!r}; expected "
            f"{{city}}/{{city}}_{{seq}}_{{frame}}{IMAGE_SUFFIX} files")
    return frames


def count_available(root: Path, split: str, n: int) -> int:
    """``min(n, images in split)``, logging a warning when fewer than ``n`` exist."""
    available = len(list_frames(root, split))
    if n > available:
        log.warning("Cityscapes %s split at %s has %d images; loading those instead of the %d asked for",
                    split, root, available, n)
    return min(n, available)


def load_cityscapes_scene(root: Path, split: str, index: int, size: tuple[int, int], seed: int, name: str) -> Scene:
    """Scene ``index`` of ``split`` under ``root`` at ``size = (H, W)`` pixels.

    ``seed`` becomes ``Scene.seed``; the scene is named ``{name}-{stem}``. Image: (H, W, 3) float32
    in [0, 1]; labels: (H, W) uint8 train ids (255 = ignore); boxes in output pixels.
    """
    frames = list_frames(root, split)
    if not 0 <= index < len(frames):
        raise IndexError(f"scene index {index} out of range: the Cityscapes {split} split at {str(root)!r} has "
                         f"{len(frames)} images (valid indices 0..{len(frames) - 1})")
    frame = frames[index]
    image = _read_png(frame.image)
    native = (image.height, image.width)
    label_ids = _read_label_ids(frame, split, native)
    vehicles = _vehicles(frame, label_ids, native)
    scale = (size[0] / native[0], size[1] / native[1])
    return Scene(
        image=_resize_image(image, size),
        labels=_resize_labels(_to_train_ids(label_ids), size),
        plates=_plates(root, split, frame.stem, native, vehicles, scale, size),
        vehicles=[Vehicle(v.train_id, _scale_box(v.box_xyxy, scale, size)) for v in vehicles],
        seed=seed,
        name=f"{name}-{frame.stem}",
    )


def _read_png(path: Path) -> Image.Image:
    if not path.is_file():
        raise CityscapesNotFoundError(f"Cityscapes file {str(path)!r} does not exist")
    try:
        with Image.open(path) as img:
            img.load()
            return img.copy()
    except (OSError, SyntaxError, ValueError, Image.DecompressionBombError) as err:
        raise CityscapesFormatError(f"cannot decode Cityscapes PNG {str(path)!r}: {err}") from err


def _read_label_ids(frame: Frame, split: str, native: tuple[int, int]) -> np.ndarray | None:
    """(H, W) label ids at native size, or ``None`` for a test image without labels."""
    if not frame.label_ids.is_file():
        if split == "test":
            return None
        raise CityscapesNotFoundError(
            f"image {str(frame.image)!r} has no label file {str(frame.label_ids)!r}; every {split} image needs "
            f"gtFine/{split}/{{city}}/{{stem}}{LABEL_SUFFIX} (only 'test' images may lack labels)")
    ids = _single_channel(frame.label_ids, "label ids", native, frame.image)
    table = _label_lut()
    counts = np.bincount(ids.ravel(), minlength=len(table))
    present = np.flatnonzero(counts)
    unknown = [int(i) for i in present if i >= len(table) or table[i] == _UNKNOWN]
    if unknown:
        raise CityscapesFormatError(
            f"label file {str(frame.label_ids)!r} holds label ids {unknown[:10]} unknown to cityscapesscripts; "
            f"valid ids are {min(id2label)}..{max(id2label)} (is this a {LABEL_SUFFIX} file, not labelTrainIds "
            "or color?)")
    return ids


def _single_channel(path: Path, what: str, native: tuple[int, int], image_path: Path) -> np.ndarray:
    img = _read_png(path)
    if img.mode not in ("L", "P", "I", "I;16"):
        raise CityscapesFormatError(
            f"{what} file {str(path)!r} has PIL mode {img.mode!r}; expected a single-channel PNG of ids "
            "(mode L, P, I or I;16), not a colour visualisation")
    if (img.height, img.width) != native:
        raise CityscapesFormatError(
            f"{what} file {str(path)!r} is {img.height}x{img.width} but its image {str(image_path)!r} is "
            f"{native[0]}x{native[1]}; both must have the same size")
    return np.asarray(img).astype(np.int64)


@lru_cache(maxsize=1)
def _label_lut() -> np.ndarray:
    table = np.full(max(id2label) + 1, _UNKNOWN, dtype=np.int64)
    for label_id, label in id2label.items():
        if label_id >= 0:
            table[label_id] = IGNORE_ID if label.trainId in (-1, IGNORE_ID) else label.trainId
    return table


def _to_train_ids(label_ids: np.ndarray | None) -> np.ndarray | None:
    return None if label_ids is None else _label_lut()[label_ids].astype(np.uint8)


def _vehicles(frame: Frame, label_ids: np.ndarray | None, native: tuple[int, int]) -> list[Vehicle]:
    """Vehicle boxes at native resolution, from instance ids when present, else label components."""
    if frame.instance_ids.is_file():
        instances = _single_channel(frame.instance_ids, "instance ids", native, frame.image)
        is_vehicle = (instances >= 1000) & np.isin(instances // 1000, _VEHICLE_LABEL_IDS)
        return [Vehicle(id2label[instance // 1000].trainId, box)
                for instance, box in _boxes(np.where(is_vehicle, instances, 0))]
    if label_ids is None:
        return []
    eight_connected = np.ones((3, 3), dtype=bool)
    return [Vehicle(id2label[label_id].trainId, box)
            for label_id in _VEHICLE_LABEL_IDS
            for _, box in _boxes(ndimage.label(label_ids == label_id, structure=eight_connected)[0])]


def _boxes(labelled: np.ndarray) -> list[tuple[int, Box]]:
    """(label, bounding box) of every positive label present in ``labelled``, in label order."""
    boxes = []
    for label, found in enumerate(ndimage.find_objects(labelled), start=1):
        if found is not None:
            rows, cols = found
            boxes.append((label, (int(cols.start), int(rows.start), int(cols.stop), int(rows.stop))))
    return boxes


def _plates(root: Path, split: str, stem: str, native: tuple[int, int], vehicles: list[Vehicle],
            scale: tuple[float, float], size: tuple[int, int]) -> list[Plate]:
    """The stem's plates; ownership is decided on native boxes (``vehicles``), then boxes are scaled."""
    path = root / "plates" / f"{split}.json"
    if not path.is_file():
        return []
    entries = _read_plates_file(path).get(stem, [])
    plates = []
    for k, (text, box, visible) in enumerate(entries):
        x0, y0, x1, y1 = box
        if not (0 <= x0 < x1 <= native[1] and 0 <= y0 < y1 <= native[0]):
            raise CityscapesFormatError(
                f"plates file {str(path)!r}, {stem!r} plate {k}: box_xyxy {list(box)} must satisfy 0 <= x0 < x1 <= "
                f"{native[1]} and 0 <= y0 < y1 <= {native[0]} (native pixels of the image)")
        plates.append(Plate(text, _scale_box(box, scale, size), _owner(box, vehicles), visible))
    return plates


def _read_plates_file(path: Path) -> dict[str, list[tuple[str, tuple[float, ...], float]]]:
    """Parse and validate a whole plates file, so that a bad entry fails whichever scenes are loaded."""
    expected = ('expected {"<city>_<seq>_<frame>": [{"text": "ABC123", "box_xyxy": [x0, y0, x1, y1], '
                '"visible_fraction": 1.0}, ...], ...} (see benchmark/scenes/cityscapes.py)')
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise CityscapesFormatError(f"plates file {str(path)!r} is not valid JSON ({err}); {expected}") from err
    if not isinstance(data, dict):
        raise CityscapesFormatError(
            f"plates file {str(path)!r} holds a {type(data).__name__}, not an object; {expected}")
    parsed = {}
    for stem, plates in data.items():
        if not isinstance(plates, list):
            raise CityscapesFormatError(
                f"plates file {str(path)!r}, {stem!r}: a list of plates is needed, got {type(plates).__name__}; "
                f"{expected}")
        parsed[stem] = [_parse_plate(plate, f"plates file {str(path)!r}, {stem!r} plate {k}")
                        for k, plate in enumerate(plates)]
    return parsed


def _parse_plate(plate: Any, where: str) -> tuple[str, tuple[float, ...], float]:
    if not isinstance(plate, dict):
        raise CityscapesFormatError(f"{where}: a plate is an object with keys {list(PLATE_KEYS)}, got {plate!r}")
    extra = sorted(set(plate) - set(PLATE_KEYS))
    missing = [key for key in PLATE_KEYS[:2] if key not in plate]
    if extra or missing:
        raise CityscapesFormatError(
            f"{where}: unknown keys {extra} / missing keys {missing}; valid keys are {list(PLATE_KEYS)} "
            "(visible_fraction optional)")
    raw = plate["text"]
    text = re.sub(r"[\s-]", "", raw).upper() if isinstance(raw, str) else None
    if not text or not re.fullmatch(r"[A-Z0-9]+", text):
        raise CityscapesFormatError(
            f"{where}: text {raw!r} must be letters and digits (spaces and hyphens are dropped, case is ignored)")
    box = plate["box_xyxy"]
    if (not isinstance(box, list) or len(box) != 4
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in box)):
        raise CityscapesFormatError(f"{where}: box_xyxy {box!r} must be four numbers [x0, y0, x1, y1] in native pixels")
    visible = plate.get("visible_fraction", 1.0)
    if isinstance(visible, bool) or not isinstance(visible, (int, float)) or not 0.0 <= visible <= 1.0:
        raise CityscapesFormatError(f"{where}: visible_fraction {visible!r} must be a number in [0, 1]")
    return text, tuple(box), float(visible)


def _owner(box: tuple[float, ...], vehicles: list[Vehicle]) -> int:
    """Index of the smallest vehicle box that contains the plate centre, else -1."""
    cx, cy = (box[0] + box[2]) / 2, (box[1] + box[3]) / 2
    inside = [(v.box_xyxy[2] - v.box_xyxy[0]) * (v.box_xyxy[3] - v.box_xyxy[1])
              if v.box_xyxy[0] <= cx < v.box_xyxy[2] and v.box_xyxy[1] <= cy < v.box_xyxy[3] else math.inf
              for v in vehicles]
    return int(np.argmin(inside)) if inside and min(inside) < math.inf else -1


def _scale_box(box: tuple[float, ...], scale: tuple[float, float], size: tuple[int, int]) -> Box:
    """Native box -> output box, rounded outward, clipped, at least one pixel wide and high."""
    sy, sx = scale
    x0 = min(max(math.floor(box[0] * sx), 0), size[1] - 1)
    y0 = min(max(math.floor(box[1] * sy), 0), size[0] - 1)
    x1 = max(min(math.ceil(box[2] * sx), size[1]), x0 + 1)
    y1 = max(min(math.ceil(box[3] * sy), size[0]), y0 + 1)
    return (x0, y0, x1, y1)


def _resize_image(image: Image.Image, size: tuple[int, int]) -> np.ndarray:
    rgb = image.convert("RGB")
    if (rgb.height, rgb.width) == size:
        return np.asarray(rgb, dtype=np.float32) / np.float32(255.0)
    channels = [np.asarray(ch.convert("F").resize((size[1], size[0]), Image.Resampling.BILINEAR))
                for ch in rgb.split()]
    return np.clip(np.stack(channels, axis=-1) / np.float32(255.0), 0.0, 1.0).astype(np.float32)


def _resize_labels(train_ids: np.ndarray | None, size: tuple[int, int]) -> np.ndarray:
    if train_ids is None:
        return np.full(size, IGNORE_ID, dtype=np.uint8)
    if train_ids.shape == size:
        return train_ids
    return np.asarray(Image.fromarray(train_ids).resize((size[1], size[0]), Image.Resampling.NEAREST))
