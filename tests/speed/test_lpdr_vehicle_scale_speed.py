"""`lpdr`'s vehicle stage at full size (vehicle_scale=1) against its default (half size), as a ratio in one run.

Run with `pytest tests/speed/test_lpdr_vehicle_scale_speed.py --benchmark-only`: the target (the vehicle
stage at half size <= TARGET_RATIO x full size, fastest of ROUNDS interleaved rounds) is asserted then. Both
segment sharp quick plate windows with the shipped quick clean SegFormer-B0 through ONNX Runtime, as a run does.
`extra_info` holds both ways' seconds per window, the ratio, the reads each way and the load. Whether the half
size reads as many plates is measured on the full quick plate set, not here (attacks/readers/lpdr.py ``Lpdr``).
"""

from __future__ import annotations

import dataclasses
import os
import time

import numpy as np
import torch

import attacks
from attacks.readers.lpdr import Lpdr
from attacks.readers.plates.memo import forgetting
from benchmark.runner.evaluation import read_plates
from benchmark.results.plate_scoring import readable
from benchmark.store.profiles import get_profile
from benchmark.runner.config import RunConfig
from benchmark.scenes import load_scene
from benchmark.scenes.windows import plate_windows, window_scene
from benchmark.codesign.utility.clean import clean_utility_net
from benchmark.runner.utility_measure import segmenter
from benchmark.codesign.utility.scoring import window_for

TARGET_RATIO = 0.4
ROUNDS = 2
THREADS = 2
FRAMES = 8


def test_lpdr_vehicle_stage_full_vs_half_size(benchmark, request, tmp_path):
    run_cfg = RunConfig(["bench"], None, "synthetic", get_profile("quick"), [0])
    cfg = dataclasses.replace(run_cfg, cache_dir=tmp_path)
    frames = [load_scene("synthetic", "val", i, cfg.profile.image_size, 0) for i in range(FRAMES)]
    windows = plate_windows(frames, readable, window_for(cfg.profile.image_size, cfg.profile.train_crop)[0])
    scenes = sorted((window_scene(frames[w.frame], w) for w in windows), key=lambda s: s.image.shape)
    images = [torch.from_numpy(np.ascontiguousarray(s.image)).permute(2, 0, 1) for s in scenes]
    net = clean_utility_net(cfg.profile, 0, "cpu", run_cfg.cache_dir, progress=False)
    threads = torch.get_num_threads()
    torch.set_num_threads(THREADS)
    try:
        segment = segmenter(net, cfg)
        readers = {"full": Lpdr(vehicle_scale=1.0), "half": attacks.load("lpdr")}
        assert readers["half"].vehicle_scale == 0.5  # the registered default

        def timed(name):
            reader = readers[name]
            before = reader.stage_seconds["vehicles"]
            with forgetting():
                outcomes, _, _ = read_plates(reader, images, scenes, cfg.profile.batch_size, "cpu", segment)
            return reader.stage_seconds["vehicles"] - before, sum(o.correct for o in outcomes)

        reads = {name: timed(name)[1] for name in readers}  # warm-up
        seconds: dict[str, list[float]] = {"full": [], "half": []}
        for _ in range(ROUNDS):  # interleaved, so that a change of machine load hits both
            for name in readers:
                seconds[name].append(timed(name)[0])
        t0 = time.perf_counter()
        benchmark.pedantic(lambda: timed("half"), rounds=1, iterations=1)
        wall_half = time.perf_counter() - t0
    finally:
        torch.set_num_threads(threads)
    ratio = min(seconds["half"]) / min(seconds["full"])
    n = len(images)
    benchmark.extra_info.update({
        "windows": n, "ratio": ratio, "threads": THREADS, "load_average": list(os.getloadavg()),
        "full_vehicles_s_per_window": min(seconds["full"]) / n, "half_vehicles_s_per_window": min(seconds["half"]) / n,
        "half_chain_s_per_window": wall_half / n, "reads_full": reads["full"], "reads_half": reads["half"]})
    assert n >= 6
    if request.config.getoption("benchmark_only"):
        assert ratio <= TARGET_RATIO, benchmark.extra_info
