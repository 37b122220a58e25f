"""What `run_restorers` keeps of each restorer's scenes when plates are read on windows: one scene
for the sample picture, in storage of its own. A slice of the batch would keep all 64 restored scenes
of every restorer alive (about 400 MB each on quick): a fresh quick run was killed for memory at
24 GB before this was a copy."""

from __future__ import annotations

import torch

import attacks
from benchmark.evaluation import Attacked, PlateSet, Target, run_restorers
from benchmark.profiles import get_profile
from benchmark.rows import RowBuilder
from benchmark.run_config import RunConfig
from benchmark.scenes import load_scenes
from benchmark.sensing import to_tensor


def test_the_kept_scene_does_not_hold_the_restored_batch():
    cfg = RunConfig(["fake"], None, "synthetic", get_profile("smoke"), [0])
    scenes = load_scenes("synthetic", "val", 3, (64, 128), 0)
    sensor = to_tensor(scenes)
    windows = [sensor[0, :, :32, :48].clone(), sensor[1, :, 8:40, 16:80].clone()]
    plates = PlateSet(scenes=scenes[:2], sharp=windows, sensor=windows, n_frames=2)
    target = Target("fake", scenes, sensor, sensor, attacks.FitContext(), None, None, plates=plates)
    out = Attacked()
    run_restorers(target, [attacks.load("raw")], {}, cfg,
                  RowBuilder(cfg, "fake", 0, {"lens": "fake"}, {"device": "cpu"}), out)
    kept = out.restored["raw"]
    assert kept.shape == (1, *sensor.shape[1:])
    assert kept.untyped_storage().nbytes() == kept.numel() * kept.element_size()
    assert [w.shape for w in out.restored_plates["raw"]] == [w.shape for w in windows]
