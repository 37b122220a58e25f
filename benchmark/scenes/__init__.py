"""Scene sets of the benchmark: ``synthetic`` (default), ``photos`` and ``cityscapes:PATH``.

``load_scenes(scene_set, split, n, size, seed)`` returns ``n`` deterministic ``Scene`` records
(image, Cityscapes train-id labels, licence plates, vehicles); ``SceneDataset`` wraps them for
torch with ground-truth-preserving crops and flips.
"""

from __future__ import annotations

from .dataset import SceneDataset
from .labels import CLASS_NAMES, IGNORE_ID, PALETTE, TRAIN_ID, colorize
from .loading import SCENE_SETS, SPLITS, load_scene, load_scenes, scene_seed
from common.plate_render import PLATE_FORMAT, matches_format, plate_entropy_bits, random_plate_text, render_plate
from .records import Box, Plate, Scene, Vehicle

__all__ = [
    "CLASS_NAMES", "IGNORE_ID", "PALETTE", "PLATE_FORMAT", "SCENE_SETS", "SPLITS", "TRAIN_ID", "Box", "Plate",
    "Scene", "SceneDataset", "Vehicle", "colorize", "load_scene", "load_scenes", "matches_format",
    "plate_entropy_bits", "random_plate_text", "render_plate", "scene_seed",
]
