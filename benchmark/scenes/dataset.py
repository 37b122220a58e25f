"""``SceneDataset``: scenes as a torch dataset, with crops and flips that keep plate ground truth honest."""

from __future__ import annotations

import dataclasses

import numpy as np
import torch

from .loading import load_scene, load_scenes
from .records import Box, Scene, Vehicle


class SceneDataset(torch.utils.data.Dataset):
    """``n`` scenes of a scene set as (image, labels) tensors, generated lazily and cached.

    Items are ``{"image": float32 (3, h, w) in [0, 1], "labels": int64 (h, w), "index": int}``.
    With ``crop = (h, w)`` each item is a random crop; with ``flip`` a random horizontal flip.
    Augmentation of item ``i`` is drawn from ``default_rng([seed, i, epoch])`` (``set_epoch``
    changes it), so runs are reproducible. ``sample(i, rng)`` returns the transformed ``Scene``
    itself, with plate and vehicle boxes shifted, clipped or mirrored to match.
    ``cache`` keeps generated scenes in memory (about 8 MB each at 512 x 1024).
    """

    def __init__(self, scene_set: str, split: str, n: int, size: tuple[int, int] = (512, 1024),
                 crop: tuple[int, int] | None = None, flip: bool = False, seed: int = 0, cache: bool = True) -> None:
        load_scenes(scene_set, split, 0, size, seed)  # validates the arguments now, not at the first item
        if crop is not None and (crop[0] > size[0] or crop[1] > size[1] or min(crop) < 1):
            raise ValueError(f"crop {crop} must be positive and fit in the scene size {size}")
        self.scene_set, self.split, self.n, self.size = scene_set, split, n, size
        self.crop, self.flip, self.seed, self.epoch = crop, flip, seed, 0
        self._cache: dict[int, Scene] | None = {} if cache else None
        self.scenes = _LazyScenes(self)

    def __len__(self) -> int:
        return self.n

    def set_epoch(self, epoch: int) -> None:
        """Draw different crops and flips for each epoch."""
        self.epoch = epoch

    def scene(self, index: int) -> Scene:
        """The untransformed scene ``index``."""
        if not 0 <= index < self.n:
            raise IndexError(f"scene index {index} out of range for {self.n} scenes")
        if self._cache is not None and index in self._cache:
            return self._cache[index]
        scene = load_scene(self.scene_set, self.split, index, self.size, self.seed)
        if self._cache is not None:
            self._cache[index] = scene
        return scene

    def sample(self, index: int, rng: np.random.Generator | torch.Generator) -> Scene:
        """Scene ``index`` after this dataset's random crop and flip, drawn from ``rng``."""
        if isinstance(rng, torch.Generator):
            rng = np.random.default_rng(int(torch.randint(2**62, (1,), generator=rng)))
        scene = self.scene(index)
        if self.crop is not None:
            height, width = scene.labels.shape
            top = int(rng.integers(height - self.crop[0] + 1))
            left = int(rng.integers(width - self.crop[1] + 1))
            scene = crop_scene(scene, (left, top, left + self.crop[1], top + self.crop[0]))
        if self.flip and rng.random() < 0.5:
            scene = flip_scene(scene)
        return scene

    def __getitem__(self, index: int) -> dict[str, torch.Tensor | int]:
        scene = self.sample(index, np.random.default_rng([self.seed, index, self.epoch]))
        return {
            "image": torch.from_numpy(np.ascontiguousarray(scene.image.transpose(2, 0, 1))),
            "labels": torch.from_numpy(scene.labels.astype(np.int64)),
            "index": index,
        }


class _LazyScenes:
    """Read-only sequence view ``dataset.scenes[i]`` that generates scenes on demand."""

    def __init__(self, dataset: SceneDataset) -> None:
        self._dataset = dataset

    def __len__(self) -> int:
        return self._dataset.n

    def __getitem__(self, index: int) -> Scene:
        return self._dataset.scene(index if index >= 0 else index + self._dataset.n)


def crop_scene(scene: Scene, box: Box) -> Scene:
    """Crop ``scene`` to pixel box (x1, y1, x2, y2); boxes are shifted and clipped, objects outside dropped.

    A plate's ``visible_fraction`` is rescaled by the share of its visible pixels kept, counted
    exactly on ``plate_mask`` when the scene has one, else estimated from box areas.
    """
    x1, y1, x2, y2 = box
    vehicles, new_index = [], {}
    for i, vehicle in enumerate(scene.vehicles):
        clipped = _shift_clip(vehicle.box_xyxy, box)
        if clipped is not None:
            new_index[i] = len(vehicles)
            vehicles.append(Vehicle(vehicle.train_id, clipped))
    mask = None if scene.plate_mask is None else scene.plate_mask[y1:y2, x1:x2]
    counts_before = None if mask is None else np.bincount(scene.plate_mask.ravel(), minlength=256)
    counts_after = None if mask is None else np.bincount(mask.ravel(), minlength=256)
    plates, renumber = [], np.zeros(256, dtype=np.uint8)
    for k, plate in enumerate(scene.plates):
        clipped = _shift_clip(plate.box_xyxy, box)
        if clipped is None or plate.vehicle_index not in new_index:
            continue
        if counts_before is not None and counts_after is not None:
            kept = counts_after[k + 1] / max(counts_before[k + 1], 1)
        else:
            kept = _area(clipped) / _area(plate.box_xyxy)
        if kept == 0:
            continue
        plates.append(dataclasses.replace(plate, box_xyxy=clipped, vehicle_index=new_index[plate.vehicle_index],
                                          visible_fraction=plate.visible_fraction * float(kept)))
        renumber[k + 1] = len(plates)
    return Scene(scene.image[y1:y2, x1:x2].copy(), scene.labels[y1:y2, x1:x2].copy(), plates, vehicles, scene.seed,
                 f"{scene.name}@crop{x1},{y1},{x2},{y2}", None if mask is None else renumber[mask])


def flip_scene(scene: Scene) -> Scene:
    """Mirror ``scene`` left-right; boxes are mirrored and plates marked ``mirrored`` (their text reads backwards)."""
    width = scene.labels.shape[1]

    def mirror(b: Box) -> Box:
        return (width - b[2], b[1], width - b[0], b[3])

    return Scene(
        scene.image[:, ::-1].copy(), scene.labels[:, ::-1].copy(),
        [dataclasses.replace(p, box_xyxy=mirror(p.box_xyxy), mirrored=not p.mirrored) for p in scene.plates],
        [Vehicle(v.train_id, mirror(v.box_xyxy)) for v in scene.vehicles],
        scene.seed, f"{scene.name}@flip", None if scene.plate_mask is None else scene.plate_mask[:, ::-1].copy())


def _shift_clip(b: Box, crop: Box) -> Box | None:
    x1, y1 = max(b[0], crop[0]) - crop[0], max(b[1], crop[1]) - crop[1]
    x2, y2 = min(b[2], crop[2]) - crop[0], min(b[3], crop[3]) - crop[1]
    return (x1, y1, x2, y2) if x2 > x1 and y2 > y1 else None


def _area(b: Box) -> int:
    return (b[2] - b[0]) * (b[3] - b[1])
