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
    # The attack chains to run (a restorer, a reader on the sensor image, or "restorer>reader"); None:
    # every reader on the sensor image and after every restorer (the full cross product).
    chains: tuple[str, ...] | None = None

    def wants(self, chain: str) -> bool:
        """Whether the run measures `chain` (always, in the full cross product)."""
        return self.chains is None or chain in self.chains


def training_scenes(scene_set: str) -> str:
    """Scenes that carry labels for training: Cityscapes when given, else the synthetic set."""
    return scene_set if scene_set.startswith("cityscapes:") else "synthetic"
