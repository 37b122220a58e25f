"""Run profiles: every size, count and step budget in one place, printed with the results."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from lenses.registry import suggest


@dataclass(frozen=True)
class Profile:
    name: str
    description: str
    image_size: tuple[int, int]   # (H, W) of evaluation scenes
    n_val: int                    # evaluation scenes per seed
    n_train: int                  # training scenes available to attackers that fit
    train_crop: tuple[int, int]   # (h, w) crops for training
    batch_size: int

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


PROFILES: dict[str, Profile] = {
    p.name: p
    for p in (
        Profile("smoke", "whole run under a minute on 2 CPU cores; for tests", (128, 256), 4, 8, (64, 64), 4),
        Profile("quick", "the CPU default: minutes on 2 cores", (512, 1024), 8, 64, (128, 128), 8),
        Profile("paper", "the paper's settings, for a GPU: full-size scenes, 512x512 crops, batch 16",
                (1024, 2048), 500, 2975, (512, 512), 16),
    )
}


def get_profile(name: str) -> Profile:
    """The profile called `name`; unknown names fail with the valid ones."""
    try:
        return PROFILES[name]
    except KeyError:
        raise ValueError(f"unknown profile {name!r}; valid: {', '.join(PROFILES)}.{suggest(name, PROFILES)}") from None
