"""Loading scenes by scene-set name and split, with one seed per scene.

Scene ``i`` of a split is generated from its own seed, drawn from
``SeedSequence([split_code, seed, i])``: it does not depend on ``n``, and the three splits
never share a scene seed.
"""

from __future__ import annotations

import difflib

import numpy as np

from .cityscapes import PREFIX as CITYSCAPES_PREFIX
from .cityscapes import cityscapes_root, count_available, load_cityscapes_scene
from .labels import IGNORE_ID
from .photos import load_photo
from .records import Scene
from .synthetic import generate_synthetic

SCENE_SETS: dict[str, str] = {
    "synthetic": "procedural street scenes, 19 Cityscapes classes, cars with ground-truth plates (embedded default)",
    "photos": "colour photographs bundled with scikit-image, no labels or plates (restoration metrics)",
    "cityscapes:PATH": "Cityscapes at PATH (leftImg8bit/, gtFine/), optional plate annotations",
}

SPLITS: tuple[str, ...] = ("train", "val", "test")


def scene_seed(split: str, seed: int, index: int) -> int:
    """The 63-bit seed of scene ``index`` of ``split`` under run seed ``seed``."""
    _check_split(split)
    state = np.random.SeedSequence([SPLITS.index(split), seed, index]).generate_state(1, np.uint64)
    return int(state[0]) >> 1


def load_scene(scene_set: str, split: str, index: int, size: tuple[int, int] = (512, 1024), seed: int = 0) -> Scene:
    """Scene ``index`` of ``split`` in ``scene_set`` at ``size = (H, W)`` pixels (see ``load_scenes``)."""
    _check_arguments(scene_set, split, size)
    s = scene_seed(split, seed, index)
    if scene_set.startswith(CITYSCAPES_PREFIX):
        root = cityscapes_root(scene_set)
        return load_cityscapes_scene(root, split, index, size, s, f"cityscapes/{split}/{seed}/{index:05d}")
    if scene_set == "photos":
        name, image = load_photo(split, index, size, np.random.default_rng(s))
        labels = np.full(size, IGNORE_ID, dtype=np.uint8)
        return Scene(image, labels, [], [], s, f"photos/{split}/{seed}/{index:05d}-{name}")
    return generate_synthetic(size, s, f"synthetic/{split}/{seed}/{index:05d}")


def load_scenes(scene_set: str, split: str, n: int, size: tuple[int, int] = (512, 1024), seed: int = 0) -> list[Scene]:
    """Load ``n`` scenes of ``split`` ("train" | "val" | "test") from ``scene_set``.

    ``scene_set``: "synthetic", "photos" or "cityscapes:PATH". ``size`` = (H, W) in pixels.
    Bit-identical for identical arguments; scene i is the same whatever ``n`` is.
    Cityscapes returns ``min(n, images in the split)`` scenes, with a logged warning when fewer.
    """
    _check_arguments(scene_set, split, size)
    if n < 0:
        raise ValueError(f"number of scenes must be >= 0, got {n}")
    if scene_set.startswith(CITYSCAPES_PREFIX):
        n = count_available(cityscapes_root(scene_set), split, n)
    return [load_scene(scene_set, split, i, size, seed) for i in range(n)]


def _check_arguments(scene_set: str, split: str, size: tuple[int, int]) -> None:
    _check_scene_set(scene_set)
    _check_split(split)
    if len(size) != 2 or min(size) < 1:
        raise ValueError(f"scene size must be (H, W) in pixels, both >= 1; got {size}")


def _check_scene_set(scene_set: str) -> None:
    if scene_set.startswith(CITYSCAPES_PREFIX):
        cityscapes_root(scene_set)
    elif scene_set not in ("synthetic", "photos"):
        raise ValueError(_unknown("scene set", scene_set, list(SCENE_SETS)))


def _check_split(split: str) -> None:
    if split not in SPLITS:
        raise ValueError(_unknown("split", split, list(SPLITS)))


def _unknown(what: str, name: str, valid: list[str]) -> str:
    close = difflib.get_close_matches(name, valid, n=3, cutoff=0.5)
    hint = f" Did you mean {' or '.join(repr(c) for c in close)}?" if close else ""
    return f"unknown {what} {name!r}; valid: {', '.join(valid)}.{hint}"
