"""Utility model size study: SegFormer variants trained on the same budget, scored on the same scenes.

Each variant is pre-trained on sharp scenes exactly as a profile's clean utility net (same steps,
crops, learning rate, seed; cached like it) and scored on the profile's sharp val scenes: mIoU,
mean and overall accuracy, parameters, inference images/s and training seconds. It answers whether
the suite's utility model is larger than the embedded scenes need at that budget.
"""

from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path

import torch

from benchmark.cache import atomic_write_text, cache_root
from benchmark.profiles import Profile
from benchmark.provenance import provenance
from benchmark.run_config import RunConfig
from benchmark.sensing import to_tensor
from benchmark.utility.measure import utility_metrics
from benchmark.scenes import load_scenes
from benchmark.utility.clean import clean_utility_net

VARIANTS = ("tiny", "b0-narrow", "b0")


def measure(profile: Profile, variants: tuple[str, ...] = VARIANTS, seed: int = 0,
            cache_dir: Path | None = None) -> list[dict]:
    """One record per variant (see the module docstring); ``train_s`` is the wall time of getting the
    trained net: training it, or a second or so when it was cached by an earlier run."""
    cache_dir = Path(cache_dir or cache_root())
    scenes = load_scenes("synthetic", "val", profile.n_val, profile.image_size, seed)
    images = to_tensor(scenes)
    records = []
    for variant in variants:
        p = dataclasses.replace(profile, utility_model=variant)
        t0 = time.perf_counter()
        net = clean_utility_net(p, seed, "cpu", cache_dir, progress=False)
        train_s = time.perf_counter() - t0
        cfg = RunConfig(lenses=[], attacks=[], scenes="synthetic", profile=p, seeds=[seed], cache_dir=cache_dir)
        with torch.no_grad():
            m = utility_metrics(net, images, scenes, cfg)
        records.append({"variant": variant, "params": sum(q.numel() for q in net.parameters()),
                        "miou": m["miou"], "mean_acc": m["mean_acc"], "overall_acc": m["overall_acc"],
                        "images_per_s": m["images_per_s"], "train_s": train_s})
    return records


def run(path: Path, profile: Profile, seed: int = 0) -> Path:
    """Measure and write the study JSON (records, profile and provenance) to ``path``."""
    body = {"study": "utility_size", "profile": profile.to_dict(), "seed": seed,
            "threads": torch.get_num_threads(), "records": measure(profile, seed=seed), "provenance": provenance("cpu")}
    atomic_write_text(path, json.dumps(body, indent=1, sort_keys=True) + "\n")
    return path
