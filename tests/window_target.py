"""A small evaluation target with plate windows, for tests of `benchmark.runner.evaluation.run_restorers`.

Imported as ``from window_target import small_target`` (tests/ is on sys.path: the rootdir conftest lives there).
"""

from __future__ import annotations

import torch

import attacks
from benchmark.runner.config import RunConfig
from benchmark.runner.evaluation import PlateSet, Target
from benchmark.runner.rows import RowBuilder
from benchmark.runner.sensing import to_tensor
from benchmark.scenes import load_scenes
from benchmark.store.profiles import get_profile


def small_target(own_copies: bool = False) -> tuple[RunConfig, Target, RowBuilder, torch.Tensor, list[torch.Tensor]]:
    """A smoke run's config, a target of 3 synthetic val scenes at 64x128 with 2 plate windows cut from
    them, its row builder, the sensor batch and the windows. ``own_copies``: the target holds clones of
    the batch as its sensor and sharp images (so a test can count the tensors shaped like it)."""
    cfg = RunConfig(["fake"], None, "synthetic", get_profile("smoke"), [0])
    scenes = load_scenes("synthetic", "val", 3, (64, 128), 0)
    sensor = to_tensor(scenes)
    windows = [sensor[0, :, :32, :48].clone(), sensor[1, :, 8:40, 16:80].clone()]
    plates = PlateSet(scenes=scenes[:2], sharp=windows, sensor=windows, n_frames=2)
    images = (sensor.clone(), sensor.clone()) if own_copies else (sensor, sensor)
    target = Target("fake", scenes, *images, attacks.FitContext(), None, None, plates=plates)
    return cfg, target, RowBuilder(cfg, "fake", 0, {"lens": "fake"}, {"device": "cpu"}), sensor, windows
