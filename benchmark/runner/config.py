"""What a run is asked to do: lenses, attackers, scenes, profile, seeds, device, cache."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from benchmark.results.schema import chain_parts
from benchmark.store.cache import cache_root
from benchmark.store.profiles import Profile
from benchmark.scenes import PLATE_FORMAT


@dataclass(frozen=True)
class LensFile:
    """A lens the run reads from a spec file: where the file is, and a digest of what it says."""

    path: str    # the .toml spec, as the run was given it
    digest: str  # of the spec's content (`LensSpec.to_dict`, which holds the sha256 of every file it names)


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
    # Lenses given as spec files, by the name the run knows them by (the spec's `name`); a task of
    # such a lens is keyed by its digest too, so an edited spec is recomputed, not served from cache.
    lens_files: dict[str, LensFile] = field(default_factory=dict)
    # A sealed run's val scene seeds by run seed (`scene_seed`): drawn at random where the run began, never
    # handed to an attacker (whose fit context holds the run seed), written with the results after it.
    scene_seeds: dict[int, int] = field(default_factory=dict)

    def scene_seed(self, seed: int) -> int:
        """The seed of the val scenes (and their plate windows) of run seed `seed`: itself, unless sealed."""
        return self.scene_seeds.get(seed, seed)

    def lens_source(self, name: str) -> str:
        """What `lenses.load` takes for the run's lens `name`: its spec file, or the registered name."""
        return self.lens_files[name].path if name in self.lens_files else name

    def lens_tag(self, name: str) -> str:
        """The part of a task key that tells versions of the lens `name` apart ("" for a registered lens)."""
        return self.lens_files[name].digest[:12] if name in self.lens_files else ""

    def wants(self, chain: str) -> bool:
        """Whether the run measures `chain` (always, in the full cross product)."""
        return self.chains is None or chain in self.chains

    def reads_with(self, reader: str) -> bool:
        """Whether any chain of the run reads with `reader` (on the sensor image, after a restorer or in a
        cascade)."""
        return self.chains is None or any(chain_parts(c)[-1] == reader for c in self.chains)


def training_scenes(scene_set: str) -> str:
    """Scenes that carry labels for training: Cityscapes when given, else the synthetic set."""
    return scene_set if scene_set.startswith("cityscapes:") else "synthetic"
