"""Scenes to tensors, tensors through a lens to sensor images, and attackers' training pairs."""

from __future__ import annotations

from collections.abc import Callable, Iterator

import numpy as np
import torch

import lenses
from attacks.crops import random_crops
from benchmark.run_config import RunConfig
from benchmark.scenes import Scene, load_scenes


def to_tensor(scenes: list[Scene]) -> torch.Tensor:
    """Scene images -> (N,3,H,W) float32 in [0,1]."""
    return torch.from_numpy(np.stack([s.image for s in scenes])).permute(0, 3, 1, 2).contiguous()


def batches(x: torch.Tensor, size: int) -> Iterator[torch.Tensor]:
    """Consecutive slices of `x` along the batch axis, `size` items each (the last may be shorter)."""
    for i in range(0, x.shape[0], size):
        yield x[i:i + size]


def sense(lens: lenses.Lens, sharp: torch.Tensor, batch_size: int, seed: int, device: str) -> torch.Tensor:
    """Sensor images (N,3,H,W) in [0,1] of `sharp` through `lens`, noise drawn from a generator
    seeded with `seed`; computed on `device`, returned on the CPU."""
    gen = torch.Generator(device=device).manual_seed(seed)
    with torch.no_grad():
        return torch.cat([lens(b.to(device), generator=gen).cpu() for b in batches(sharp, batch_size)])


def train_pairs_factory(lens: lenses.Lens, cfg: RunConfig, seed: int
                        ) -> Callable[[], Iterator[tuple[torch.Tensor, torch.Tensor]]]:
    """A re-iterable source of (sensor, sharp) batches, each (B,3,h,w) in [0,1] with (h, w) the
    profile's training crop: one random crop of each TRAIN scene, for attackers that fit."""
    p = cfg.profile
    cached: list[torch.Tensor] = []

    def pairs() -> Iterator[tuple[torch.Tensor, torch.Tensor]]:
        if not cached:
            cached.append(to_tensor(load_scenes(cfg.scenes, "train", p.n_train, p.image_size, seed)))
        (crops,) = random_crops([cached[0]], p.train_crop, torch.Generator().manual_seed(seed + 1))
        gen = torch.Generator(device=cfg.device).manual_seed(seed + 1)
        for sharp in batches(crops, p.batch_size):
            sharp = sharp.to(cfg.device)
            with torch.no_grad():
                yield lens(sharp, generator=gen), sharp

    return pairs
