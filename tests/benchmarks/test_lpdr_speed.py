"""Plate-reader speed by stage (pytest-benchmark; run with `pytest tests/benchmarks --benchmark-only`).

Target on the 2-core CPU: <= 1 s per 512 x 1024 image for the whole pipeline, ground-truth vehicles.
``extra_info`` splits the time into the vehicle, plate-detection and OCR stages.
"""

import numpy as np
import pytest
import torch

import attacks
from benchmark.scenes import load_scenes


@pytest.mark.parametrize("detector", ["craft", "opencv"])
def test_lpdr_oracle_per_512x1024_image(benchmark, detector):
    scenes = load_scenes("synthetic", "val", 2, (512, 1024), 0)
    images = torch.from_numpy(np.stack([s.image for s in scenes])).permute(0, 3, 1, 2).float()
    hints = attacks.ReadHints(vehicle_boxes=[[v.box_xyxy for v in s.vehicles] for s in scenes])
    reader = attacks.load("lpdr-oracle", plate_detector=detector)
    reader.fit(attacks.FitContext())
    reader.read(images[:1], attacks.ReadHints(vehicle_boxes=hints.vehicle_boxes[:1]))  # warm-up
    reader.stage_seconds = dict.fromkeys(reader.stage_seconds, 0.0)
    reader.images_read = 0
    benchmark.pedantic(lambda: reader.read(images, hints), rounds=2, iterations=1)
    for stage, seconds in reader.stage_seconds.items():
        benchmark.extra_info[f"{stage}_s_per_image"] = seconds / reader.images_read
    benchmark.extra_info["s_per_image"] = benchmark.stats.stats.mean / len(scenes)
