"""Training batches for co-design: seeded random crops and flips of the TRAIN split.

Batch `step` is a pure function of (seed, step), so an interrupted run that resumes from a
checkpoint sees exactly the batches the uninterrupted run would have seen.
"""

from __future__ import annotations

import numpy as np
import torch

from benchmark.scenes import Scene, load_scenes


class CropSampler:
    """Random (h, w) crops with horizontal flips of a fixed set of training scenes."""

    def __init__(self, scenes: list[Scene], crop: tuple[int, int], batch_size: int, seed: int):
        if not scenes:
            raise ValueError("co-design needs at least one training scene")
        self.images = np.stack([s.image for s in scenes])          # (N, H, W, 3) float32
        self.labels = np.stack([s.labels for s in scenes])         # (N, H, W) uint8
        h, w = crop
        if h > self.images.shape[1] or w > self.images.shape[2]:
            raise ValueError(f"training crop {crop} is larger than the scenes {self.images.shape[1:3]}")
        self.crop, self.batch_size, self.seed = crop, batch_size, seed

    @classmethod
    def from_split(cls, scene_set: str, n: int, size: tuple[int, int], crop: tuple[int, int], batch_size: int,
                   seed: int) -> "CropSampler":
        return cls(load_scenes(scene_set, "train", n, size, seed), crop, batch_size, seed)

    def batch(self, step: int, device: str = "cpu") -> tuple[torch.Tensor, torch.Tensor]:
        """Scenes (B,3,h,w) float32 in [0,1] and train-id labels (B,h,w) int64 of batch `step`."""
        rng = np.random.default_rng([self.seed, step, 7])
        h, w = self.crop
        xs, ys = [], []
        for i in rng.integers(0, len(self.images), self.batch_size):
            y0 = int(rng.integers(0, self.images.shape[1] - h + 1))
            x0 = int(rng.integers(0, self.images.shape[2] - w + 1))
            img = self.images[i, y0:y0 + h, x0:x0 + w]
            lab = self.labels[i, y0:y0 + h, x0:x0 + w]
            if rng.random() < 0.5:  # plate text mirrors too, but co-design never reads plates
                img, lab = img[:, ::-1], lab[:, ::-1]
            xs.append(np.ascontiguousarray(img))
            ys.append(np.ascontiguousarray(lab))
        x = torch.from_numpy(np.stack(xs)).permute(0, 3, 1, 2).to(device)
        y = torch.from_numpy(np.stack(ys).astype(np.int64)).to(device)
        return x, y


def step_generator(seed: int, step: int, device: str) -> torch.Generator:
    """Sensor-noise generator of one step (reproducible across resumes)."""
    return torch.Generator(device=device).manual_seed((seed * 1_000_003 + step) % (2**63))
