"""Training crops for the clean utility pre-training, with rare-class sampling.

mIoU weighs every class equally, but uniform crops of street scenes are mostly road, building
and sky: a person or a bicycle is in few crops. With probability ``rare_fraction`` a crop is
therefore centred on a pixel of a class drawn uniformly among the classes present in the
training scenes (then a scene holding that class, then one of its pixels); otherwise it is a
uniform random crop. Batch ``step`` is a pure function of (seed, step), so a run resumed from a
checkpoint sees exactly the batches of the uninterrupted run.
"""

from __future__ import annotations

import numpy as np
import torch

from benchmark.scenes import Scene
from benchmark.codesign.utility.scoring import N_CLASSES

# Pixel positions kept per (scene, class) to centre rare-class crops on; a sample, to bound memory.
PIXELS_PER_CLASS = 64


class RareClassCropSampler:
    """Random (h, w) crops and horizontal flips of a fixed set of scenes.

    Images are held as float16 (3 bytes less per value than float32; the scenes' values are in
    [0, 1], where float16 keeps about 3 decimal digits) and returned as float32.
    """

    def __init__(self, scenes: list[Scene], crop: tuple[int, int], batch_size: int, seed: int,
                 rare_fraction: float):
        if not scenes:
            raise ValueError("utility pre-training needs at least one training scene")
        if not 0.0 <= rare_fraction <= 1.0:
            raise ValueError(f"rare_fraction must be in [0, 1], got {rare_fraction}")
        h, w = crop
        height, width = scenes[0].labels.shape
        if h > height or w > width:
            raise ValueError(f"training crop {crop} is larger than the scenes {(height, width)}")
        self.images = np.stack([s.image.astype(np.float16) for s in scenes])   # (N, H, W, 3)
        self.labels = np.stack([s.labels for s in scenes])                       # (N, H, W) uint8
        self.crop, self.batch_size, self.seed, self.rare_fraction = crop, batch_size, seed, rare_fraction
        rng = np.random.default_rng([seed, 11])
        # pixels[c] = list of (scene, (k, 2) int32 rows/cols) for the scenes that hold class c
        self.pixels: dict[int, list[tuple[int, np.ndarray]]] = {}
        for i, lab in enumerate(self.labels):
            counts = np.bincount(lab.ravel(), minlength=256)
            for c in np.flatnonzero(counts[:N_CLASSES]):
                rows, cols = np.nonzero(lab == c)
                pick = rng.choice(rows.size, size=min(PIXELS_PER_CLASS, rows.size), replace=False)
                self.pixels.setdefault(int(c), []).append((i, np.stack([rows[pick], cols[pick]], 1).astype(np.int32)))
        self.classes = sorted(self.pixels)

    def class_pixel_fraction(self) -> np.ndarray:
        """(N_CLASSES,) fraction of the labelled training pixels in each class (for the record)."""
        counts = np.bincount(self.labels.ravel(), minlength=256)[:N_CLASSES].astype(np.float64)
        return counts / max(counts.sum(), 1.0)

    def _corner(self, rng: np.random.Generator) -> tuple[int, int, int]:
        h, w = self.crop
        n, height, width = self.labels.shape
        if self.classes and rng.random() < self.rare_fraction:
            holders = self.pixels[self.classes[int(rng.integers(len(self.classes)))]]
            i, where = holders[int(rng.integers(len(holders)))]
            y, x = where[int(rng.integers(len(where)))]
            # Centre on the pixel, jittered by up to a quarter crop so it is not always in the middle.
            y0 = int(y) - h // 2 + int(rng.integers(-(h // 4), h // 4 + 1))
            x0 = int(x) - w // 2 + int(rng.integers(-(w // 4), w // 4 + 1))
            return i, min(max(y0, 0), height - h), min(max(x0, 0), width - w)
        return int(rng.integers(n)), int(rng.integers(0, height - h + 1)), int(rng.integers(0, width - w + 1))

    def batch(self, step: int, device: str = "cpu") -> tuple[torch.Tensor, torch.Tensor]:
        """Scenes (B,3,h,w) float32 in [0,1] and train-id labels (B,h,w) int64 (255 = ignore) of batch `step`."""
        rng = np.random.default_rng([self.seed, step, 13])
        h, w = self.crop
        xs, ys = [], []
        for _ in range(self.batch_size):
            i, y0, x0 = self._corner(rng)
            img = self.images[i, y0:y0 + h, x0:x0 + w]
            lab = self.labels[i, y0:y0 + h, x0:x0 + w]
            if rng.random() < 0.5:
                img, lab = img[:, ::-1], lab[:, ::-1]
            xs.append(np.ascontiguousarray(img, dtype=np.float32))
            ys.append(np.ascontiguousarray(lab))
        x = torch.from_numpy(np.stack(xs)).permute(0, 3, 1, 2).contiguous().to(device)
        y = torch.from_numpy(np.stack(ys).astype(np.int64)).to(device)
        return x, y

