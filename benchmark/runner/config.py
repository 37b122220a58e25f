"""What a run is asked to do: lenses, attackers, scenes, profile, seeds, device, cache."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from benchmark.store.cache import cache_root
from benchmark.store.profiles import Profile
from benchmark.scenes import PLATE_FORMAT


@dataclass
class RunConfig:
    lenses: list[str]
    attacks: list[str] | None  # None: every registered attacker
    scenes: str
    profile: Profile
    seeds: list[int]
    device: str = "cpu"
    cache_dir: Path = field(default_factory=cache_root)
    plate_format: str = PLATE_FORMAT   # the plate strings the bound's entropy counts
    frames: int = 30                   # T of the video bound (T = 1 is always reported)
    budget_s: float | None = None      # wall-time budget of each expensive step (attacker stages, bound)


def training_scenes(scene_set: str) -> str:
    """Scenes that carry labels for training: Cityscapes when given, else the synthetic set."""
    return scene_set if scene_set.startswith("cityscapes:") else "synthetic"
